"""The evaluation protocol: when a policy is tested during training, on which episodes, how often.

The paper's protocol (the defaults of :class:`Protocol`): every 50 training episodes the current
policy is evaluated on 20 test episodes, until 700 training episodes (14 evaluations, 280 test
episodes), 5 seeds per configuration. The test episodes are a fixed, held-out set of episode
seeds: the same at every evaluation and for every configuration, disjoint from the seeds of
the training episodes (:func:`crowdnav.agents.train_seed`), and never seen by the learner (they run on
their own environment with the deterministic policy, so no transition enters a replay buffer).

A protocol can instead state its budget in env steps (``train_steps``, evaluations every
``eval_every_steps``; env steps are counted over all the worlds a run collects from): its
:attr:`Protocol.unit` is then ``"steps"`` and its evaluation points are env-step counts. A
protocol without them (every result written before they existed) is in episodes.
"""

from __future__ import annotations

from typing import Annotated, Any

from crowdnav.agents.training.seeding import train_seed  # torch-free: the protocol stays cheap to import
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
MAX_STEPS = 10**12
MAX_SEED_BASE = 2**31
Count = Annotated[int, _at_least(1), Field(ge=1, le=MAX_COUNT)]
StepCount = Annotated[int, _at_least(1), Field(ge=1, le=MAX_STEPS)] | None
SeedBase = Annotated[int, _at_least(0), Field(ge=0, le=MAX_SEED_BASE)]

UNITS = ("episodes", "steps")
"""What a protocol's budget and evaluation points count (as ``crowdnav.agents.runs.folder.UNITS``)."""
POINT_COLUMNS = {"episodes": "training_episodes", "steps": "training_steps"}
"""The results column that holds an evaluation's point, per unit."""
AXIS_LABELS = {"episodes": "training episodes", "steps": "training env steps"}
UNIT_NAMES = {"episodes": "episodes", "steps": "env steps"}

MAX_WORLDS = 4096
"""The most worlds a run collects from (``TrainConfig.num_envs``'s upper bound): bounds the episodes of a step budget."""


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
    train_steps: StepCount = _option(None, "A training budget in env steps (counted over all worlds) instead of train_episodes; "
                                           "set together with eval_every_steps.")
    eval_every_steps: StepCount = _option(None, "With train_steps: evaluate the current policy after every this many env steps.")

    def __init__(self, **fields: Any) -> None:
        # One ValueError naming the fields. Pydantic calls a custom __init__ for the protocol section of an
        # experiment file too; there the shared formatter unpacks FieldProblems onto protocol.<field>.
        try:
            super().__init__(**fields)
        except ValidationError as error:
            raise FieldProblems([(issue.path, issue.message) for issue in validation_issues(error, fields, Protocol)]) from None

    @model_validator(mode="after")
    def _one_budget_evaluated_at_least_once(self) -> Protocol:
        steps = {"train_steps": self.train_steps, "eval_every_steps": self.eval_every_steps}
        given = [name for name, value in steps.items() if value is not None]
        if len(given) == 1:
            missing, other = ("eval_every_steps", "train_steps") if given == ["train_steps"] else ("train_steps", "eval_every_steps")
            raise FieldProblems([(missing, f"a budget in env steps needs both train_steps and eval_every_steps; {other} is set, "
                                           f"{missing} is not")])
        if self.train_steps is not None and self.eval_every_steps is not None:  # both given (one alone was refused above)
            # one budget: an episode field next to a step budget would be ignored, so it is refused
            mixed = [name for name in ("train_episodes", "eval_every") if name in self.model_fields_set]
            if mixed:
                raise FieldProblems([(name, "the budget is in env steps (train_steps, eval_every_steps); remove this episode field")
                                     for name in mixed])
            if self.eval_every_steps > self.train_steps:
                raise FieldProblems([("eval_every_steps", f"{self.eval_every_steps} is more than train_steps ({self.train_steps}): "
                                                          "no evaluation would run")])
        elif self.eval_every > self.train_episodes:
            raise FieldProblems([("eval_every", f"{self.eval_every} is more than train_episodes ({self.train_episodes}): "
                                                "no evaluation would run")])
        return self

    @property
    def unit(self) -> str:
        """``"episodes"`` (train_episodes, eval_every: the paper's protocol) or ``"steps"`` (train_steps, eval_every_steps)."""
        return "episodes" if self.train_steps is None else "steps"

    @property
    def budget(self) -> int:
        """The training length in :attr:`unit`."""
        return self.train_episodes if self.train_steps is None else self.train_steps

    @property
    def interval(self) -> int:
        """The evaluation interval in :attr:`unit`."""
        return self.eval_every if self.eval_every_steps is None else self.eval_every_steps

    @property
    def point_column(self) -> str:
        """The results column of the evaluation points: ``training_episodes`` or ``training_steps``."""
        return POINT_COLUMNS[self.unit]

    @property
    def evaluation_points(self) -> list[int]:
        """Training episodes (or env steps) after which the policy is evaluated: interval, 2 interval, ... <= budget."""
        return list(range(self.interval, self.budget + 1, self.interval))

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
        """Seeds of the training episodes of run ``run_seed`` (as :func:`crowdnav.agents.train_seed` assigns them).

        With a step budget the number of episodes is not known in advance: this is a superset,
        every seed the run can use. Episodes are numbered as they start; the first reset starts
        one per world (at most :data:`MAX_WORLDS`), every later one follows an episode that ended
        and took at least one env step, and the last step overshoots the budget by fewer than
        the worlds: at most ``train_steps + 2 MAX_WORLDS`` episodes.
        """
        episodes = self.train_episodes if self.train_steps is None else self.train_steps + 2 * MAX_WORLDS
        first, last = train_seed(run_seed, 0), train_seed(run_seed, episodes - 1)
        if last - first == episodes - 1:  # consecutive: a range, so membership tests are O(1)
            return range(first, last + 1)
        return [train_seed(run_seed, episode) for episode in range(episodes)]

    def check_disjoint(self) -> None:
        """ValueError if a test seed is also the seed of a training episode of any run."""
        test = set(self.test_seeds)
        for run_seed in self.run_seeds:
            shared = sorted(seed for seed in test if seed in self.training_seeds(run_seed))
            if shared:
                raise ValueError(f"test_seed_base: test seeds {shared[:5]} are also training seeds of run seed {run_seed}; "
                                 "choose a test_seed_base below the training seeds (crowdnav.agents.train_seed)")

    def describe_budget(self) -> str:
        """``700 episodes`` or ``2,000,000 env steps``."""
        return describe_budget(self.to_dict())

    def to_dict(self) -> dict[str, int]:
        # Only the fields of its unit: an episode protocol's dict is the one written before step budgets existed,
        # so older results (spec.json, experiment.yaml) still match it and are not trained again.
        if self.unit == "steps":
            return self.model_dump(exclude={"train_episodes", "eval_every"})
        return self.model_dump(exclude={"train_steps", "eval_every_steps"})


QUICK = {"train_episodes": 20, "eval_every": 10, "test_episodes": 5, "seeds": 1, "window": 5, "final_evaluations": 1}
"""The ``--quick`` preset: a smoke run of the whole pipeline (about a minute per run)."""
QUICK_STEPS = {"train_steps": 4_000, "eval_every_steps": 2_000}
"""The ``--quick`` budget of a protocol in env steps (the rest as :data:`QUICK`)."""


def quick(protocol: Protocol) -> Protocol:
    """``protocol`` shrunk to the :data:`QUICK` preset in its own unit (the test-seed base is kept)."""
    shrunk = {**protocol.to_dict(), **QUICK}
    if protocol.unit == "steps":
        shrunk = {**{key: value for key, value in shrunk.items() if key not in ("train_episodes", "eval_every")}, **QUICK_STEPS}
    return Protocol(**shrunk)


def protocol_unit(protocol: Any) -> str:
    """The unit of a protocol's dict as a results folder stores it (no ``train_steps``, as older crowdnav wrote: episodes)."""
    return "steps" if protocol.get("train_steps") is not None else "episodes"


def describe_budget(protocol: Any) -> str:
    """A stored protocol's training budget, ``700 episodes`` or ``2,000,000 env steps`` (``-`` if it names none)."""
    if protocol_unit(protocol) == "steps":
        return f"{protocol['train_steps']:,} env steps"
    return f"{protocol['train_episodes']:,} episodes" if "train_episodes" in protocol else "-"


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)
