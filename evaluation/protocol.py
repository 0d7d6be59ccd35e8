"""The evaluation protocol: when a policy is tested during training, on which episodes, how often.

The paper's protocol (the defaults of :class:`Protocol`): every 50 training episodes the current
policy is evaluated on 20 test episodes, until 700 training episodes (14 evaluations, 280 test
episodes), 5 seeds per configuration. The test episodes are a fixed, held-out set of episode
seeds: the same at every evaluation and for every configuration, disjoint from the seeds of
the training episodes (:func:`agents.train_seed`), and never seen by the learner (they run on
their own environment with the deterministic policy, so no transition enters a replay buffer).
"""

from __future__ import annotations

from typing import Annotated, Any

from crowdnav.agents.seeding import train_seed  # torch-free: the protocol stays cheap to import
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, model_validator

from crowdnav.config_errors import FieldProblems, validation_issues


def _at_least(minimum: int) -> BeforeValidator:
    """A whole number >= ``minimum`` (not a bool, not 2.0), with the one message every protocol field gives."""
    def check(value: Any) -> Any:
        if not _is_int(value) or value < minimum:
            raise ValueError(f"expected an integer >= {minimum}, got {value!r}")
        return value

    return BeforeValidator(check)


# Upper bounds: far beyond any real protocol, and below what numpy seeds and ranges can hold
# (2**63 test episodes would overflow instead of failing with the field's name).
MAX_COUNT = 1_000_000
MAX_SEED_BASE = 2**31
Count = Annotated[int, _at_least(1), Field(ge=1, le=MAX_COUNT)]
SeedBase = Annotated[int, _at_least(0), Field(ge=0, le=MAX_SEED_BASE)]


def _option(default: Any, doc: str) -> Any:
    return Field(default, description=doc)


class Protocol(BaseModel):
    """How every (configuration, seed) run is trained and tested. Defaults: the paper's protocol.

    The ``protocol`` section of an experiment file; built directly, a bad value raises ValueError
    ``field: expectation``.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    train_episodes: Count = _option(700, "Training length in episodes.")
    eval_every: Count = _option(50, "Evaluate the current policy after every this many training episodes.")
    test_episodes: Count = _option(20, "Test episodes per evaluation (the same seeds at every evaluation).")
    seeds: Count = _option(5, "Runs per configuration, with training seeds 0, 1, ..., seeds - 1.")
    test_seed_base: SeedBase = _option(0, "The test episodes use seeds test_seed_base, test_seed_base + 1, ...")
    window: Count = _option(10, "Curves: sliding window, in test episodes, of the outcome rates (success, collision, out_of_bounds, truncated).")
    final_evaluations: Count = _option(3, "Leaderboard: the 'final' rates pool the test episodes of this many last evaluations.")

    def __init__(self, **fields: Any) -> None:
        # One ValueError naming the fields. Pydantic calls a custom __init__ for the protocol section of an
        # experiment file too; there the shared formatter unpacks FieldProblems onto protocol.<field>.
        try:
            super().__init__(**fields)
        except ValidationError as error:
            raise FieldProblems([(issue.path, issue.message) for issue in validation_issues(error, fields, Protocol)]) from None

    @model_validator(mode="after")
    def _evaluates_at_least_once(self) -> Protocol:
        if self.eval_every > self.train_episodes:
            raise FieldProblems([("eval_every", f"{self.eval_every} is more than train_episodes ({self.train_episodes}): "
                                                "no evaluation would run")])
        return self

    @property
    def evaluation_points(self) -> list[int]:
        """Training episodes after which the policy is evaluated: eval_every, 2 eval_every, ... <= train_episodes."""
        return list(range(self.eval_every, self.train_episodes + 1, self.eval_every))

    @property
    def evaluations(self) -> int:
        return len(self.evaluation_points)

    @property
    def test_seeds(self) -> list[int]:
        """The held-out episode seeds, identical at every evaluation and for every configuration."""
        return list(range(self.test_seed_base, self.test_seed_base + self.test_episodes))

    @property
    def run_seeds(self) -> list[int]:
        return list(range(self.seeds))

    def training_seeds(self, run_seed: int) -> range | list[int]:
        """Seeds of the training episodes of run ``run_seed`` (as :func:`agents.train_seed` assigns them)."""
        first, last = train_seed(run_seed, 0), train_seed(run_seed, self.train_episodes - 1)
        if last - first == self.train_episodes - 1:  # consecutive: a range, so membership tests are O(1)
            return range(first, last + 1)
        return [train_seed(run_seed, episode) for episode in range(self.train_episodes)]

    def check_disjoint(self) -> None:
        """ValueError if a test seed is also the seed of a training episode of any run."""
        test = set(self.test_seeds)
        for run_seed in self.run_seeds:
            shared = sorted(seed for seed in test if seed in self.training_seeds(run_seed))
            if shared:
                raise ValueError(f"test_seed_base: test seeds {shared[:5]} are also training seeds of run seed {run_seed}; "
                                 "choose a test_seed_base below the training seeds (agents.train_seed)")

    def to_dict(self) -> dict[str, int]:
        return self.model_dump()


QUICK = {"train_episodes": 20, "eval_every": 10, "test_episodes": 5, "seeds": 1, "window": 5, "final_evaluations": 1}
"""The ``--quick`` preset: a smoke run of the whole pipeline (about a minute per run)."""


def quick(protocol: Protocol) -> Protocol:
    """``protocol`` shrunk to the :data:`QUICK` preset (the test-seed base is kept)."""
    return Protocol(**{**protocol.to_dict(), **QUICK})


def protocol_fields() -> dict[str, str]:
    """Field name -> one-line doc, for error messages and documentation."""
    return {name: info.description or "" for name, info in Protocol.model_fields.items()}


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)
