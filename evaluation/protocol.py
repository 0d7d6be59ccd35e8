"""The evaluation protocol: when a policy is tested during training, on which episodes, how often.

The paper's protocol (the defaults of :class:`Protocol`): every 50 training episodes the current
policy is evaluated on 20 test episodes, until 700 training episodes (14 evaluations, 280 test
episodes), 5 seeds per configuration. The test episodes are a fixed, held-out set of episode
seeds: the same at every evaluation and for every configuration, disjoint from the seeds of
the training episodes (:func:`agents.train_seed`), and never seen by the learner (they run on
their own environment with the deterministic policy, so no transition enters a replay buffer).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

from crowdnav.agents.seeding import train_seed  # torch-free: the protocol stays cheap to import


def _option(default: Any, doc: str) -> Any:
    return field(default=default, metadata={"doc": doc})


@dataclass(frozen=True)
class Protocol:
    """How every (configuration, seed) run is trained and tested. Defaults: the paper's protocol."""

    train_episodes: int = _option(700, "Training length in episodes.")
    eval_every: int = _option(50, "Evaluate the current policy after every this many training episodes.")
    test_episodes: int = _option(20, "Test episodes per evaluation (the same seeds at every evaluation).")
    seeds: int = _option(5, "Runs per configuration, with training seeds 0, 1, ..., seeds - 1.")
    test_seed_base: int = _option(0, "The test episodes use seeds test_seed_base, test_seed_base + 1, ...")
    window: int = _option(10, "Curves: sliding window, in test episodes, of the outcome rates (success, collision, out_of_bounds, truncated).")
    final_evaluations: int = _option(3, "Leaderboard: the 'final' rates pool the test episodes of this many last evaluations.")

    def __post_init__(self) -> None:
        problems = [f"{name}: expected an integer >= 1, got {getattr(self, name)!r}"
                    for name in ("train_episodes", "eval_every", "test_episodes", "seeds", "window", "final_evaluations")
                    if not _is_int(getattr(self, name)) or getattr(self, name) < 1]
        if not _is_int(self.test_seed_base) or self.test_seed_base < 0:
            problems.append(f"test_seed_base: expected an integer >= 0, got {self.test_seed_base!r}")
        if not problems and self.eval_every > self.train_episodes:
            problems.append(f"eval_every: {self.eval_every} is more than train_episodes ({self.train_episodes}): no evaluation would run")
        if problems:
            raise ValueError("; ".join(problems))

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
        return asdict(self)


QUICK = {"train_episodes": 20, "eval_every": 10, "test_episodes": 5, "seeds": 1, "window": 5, "final_evaluations": 1}
"""The ``--quick`` preset: a smoke run of the whole pipeline (about a minute per run)."""


def quick(protocol: Protocol) -> Protocol:
    """``protocol`` shrunk to the :data:`QUICK` preset (the test-seed base is kept)."""
    return replace(protocol, **QUICK)


def protocol_fields() -> dict[str, str]:
    """Field name -> one-line doc, for error messages and documentation."""
    return {item.name: item.metadata["doc"] for item in fields(Protocol)}


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)
