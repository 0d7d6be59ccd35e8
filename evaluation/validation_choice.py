"""Early stopping on validation episodes: each run's snapshot chosen by held-out *validation* seeds, never the test's.

The protocol's final evaluation reads a run where its fixed budget leaves it; a learner that still moves (the SARL
runs of docs/agents.md lose or gain a point or two over their last 500 episodes) can be read instead at the snapshot
that did best on episodes of its own, disjoint from the test episodes. :func:`choose_on_validation` does that for a
finished experiment folder (``crowdnav benchmark``'s output):

* every evaluation point of every run (the ``training_episodes`` of its ``test_episodes.csv``) has a snapshot
  ``train/snapshots/episode_NNNNN``; each plays ``episodes`` validation episodes, seeds ``seed_base`` on
  (default 500,000-500,299: below every run's training seeds, 1,000,000 on, and refused where they meet the test
  seeds);
* the snapshot with the most validation successes is kept (ties: the later one) and its *test* evaluation, already
  stored by the protocol, is the run's result.

The validation outcomes are stored next to the run (``validation_<seed_base>_<episodes>.csv``, one row per snapshot)
and reused: a second call plays nothing it has played before, and never rewrites a stored row.
"""

from __future__ import annotations

import csv
import json
from collections import Counter
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from crowdnav.agents.runs.folder import snapshot_dir
from crowdnav.agents.training.seeding import check_test_seeds

from crowdnav.files import hold_lock, open_text_for_append, refuse_link

VALIDATION_SEED_BASE = 500_000
"""First validation seed: above any protocol's test seeds in the shipped experiments, below every training seed."""
VALIDATION_EPISODES = 300
"""Validation episodes per snapshot of the declared rule (docs/evaluation.md#early-stopping-on-validation-episodes)."""
OUTCOMES = ("success", "collision", "out_of_bounds", "truncated")
FIELDS = ("training_episodes", "episodes", *OUTCOMES)


@dataclass(frozen=True)
class Choice:
    """One run's snapshot chosen on validation episodes, and that snapshot's test evaluation."""

    configuration: str
    seed: int
    validation: dict[int, int]
    """Validation successes per evaluation point (training episodes)."""
    chosen: int
    """Training episodes of the kept snapshot."""
    test_successes: int
    test_episodes: int

    @property
    def test_success(self) -> float:
        return self.test_successes / self.test_episodes


def choose_on_validation(experiment: str | Path, *, episodes: int = VALIDATION_EPISODES, seed_base: int = VALIDATION_SEED_BASE,
                         configurations: Sequence[str] | None = None, log: Callable[[str], None] = print) -> list[Choice]:
    """The snapshot each run of ``experiment`` keeps on validation episodes (module docstring), configuration by seed."""
    folder = Path(experiment)
    check_test_seeds(seed_base, episodes)
    runs = sorted(folder.glob("*/seed_*/spec.json"))
    if not runs:
        raise ValueError(f"{folder} holds no run (no <configuration>/seed_<n>/spec.json): give an experiment's results folder")
    choices = []
    for spec_file in runs:
        spec = json.loads(spec_file.read_text(encoding="utf-8"))
        if configurations is not None and spec["configuration"] not in configurations:
            continue
        choices.append(_choose(spec_file.parent, spec, episodes, seed_base, log))
    return choices


def _choose(run: Path, spec: dict[str, Any], episodes: int, seed_base: int, log: Callable[[str], None]) -> Choice:
    protocol = spec["protocol"]
    test_first, test_count = int(protocol.get("test_seed_base", 0)), int(protocol["test_episodes"])
    if seed_base < test_first + test_count and test_first < seed_base + episodes:
        raise ValueError(f"validation seeds {seed_base:,}-{seed_base + episodes - 1:,} meet {run}'s test seeds "
                         f"{test_first:,}-{test_first + test_count - 1:,}; choose --seed-base outside them")
    tests = _test_successes(run / "test_episodes.csv")
    table = run / f"validation_{seed_base}_{episodes}.csv"
    with _table_lock(table):  # one writer per table: two would play the same snapshots and interleave rows
        stored = _read(table)
        for point in sorted(set(tests) - set(stored)):
            stored[point] = _validate(run, point, episodes, seed_base)
            _append(table, point, episodes, stored[point])
            log(f"{run.parent.name}/{run.name}: snapshot after {point:,} episodes, {stored[point]['success']} of {episodes} validation successes")
    validation = {point: stored[point]["success"] for point in sorted(tests)}
    chosen = kept(validation)
    successes, played = tests[chosen]
    return Choice(spec["configuration"], int(spec["seed"]), validation, chosen, successes, played)


def kept(validation: dict[int, int]) -> int:
    """The rule: the evaluation point whose snapshot won the most validation episodes, ties to the later one."""
    return max(validation, key=lambda point: (validation[point], point))


def stored_choice(run: Path, *, episodes: int = VALIDATION_EPISODES, seed_base: int = VALIDATION_SEED_BASE) -> tuple[int, dict[int, int]]:
    """The kept evaluation point of a finished run and its validation successes per point, from the stored table only.

    Plays nothing (publishing reads what :func:`choose_on_validation` stored); refused, naming the command that fills
    the table, where a point of the run's test evaluations has no stored validation row.
    """
    from crowdnav.evaluation.storage import experiment_of

    tests = _test_successes(run / "test_episodes.csv")
    table = run / f"validation_{seed_base}_{episodes}.csv"
    stored = _read(table)
    missing = sorted(set(tests) - set(stored))
    if missing:
        raise ValueError(f"{table} has no validation row for the snapshot after {missing[0]:,} episodes: run `python "
                         f"benchmarks/validation_choice.py {experiment_of(run)} --episodes {episodes} --seed-base {seed_base}` first")
    validation = {point: stored[point]["success"] for point in sorted(tests)}
    return kept(validation), validation


def _test_successes(path: Path) -> dict[int, tuple[int, int]]:
    """(successes, episodes) of the protocol's test evaluation at each evaluation point."""
    if not path.is_file():
        raise ValueError(f"{path} is missing: the run has no test evaluation yet (finish it with crowdnav benchmark)")
    counts: dict[int, Counter[str]] = {}
    with path.open(encoding="utf-8", newline="") as file:
        for row in csv.DictReader(file):
            counts.setdefault(int(row["training_episodes"]), Counter())[row["outcome"]] += 1
    return {point: (count["success"], sum(count.values())) for point, count in counts.items()}


def _validate(run: Path, point: int, episodes: int, seed_base: int) -> Counter[str]:
    from crowdnav.agents import load_policy
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    snapshot = snapshot_dir(run / "train", point)
    if not snapshot.is_dir():
        raise ValueError(f"{snapshot} is missing: choosing on validation needs the snapshot of every evaluation point")
    policy = load_policy(snapshot)
    rows = HeldOutEpisodes(policy.env_options, list(range(seed_base, seed_base + episodes))).run(policy)
    return Counter(str(row["outcome"]) for row in rows)


def _table_lock(table: Path) -> AbstractContextManager[None]:
    """The table's writer lock, ``.<table>.lock`` beside it: a second writer is refused at once, naming the first's PID."""
    return hold_lock(table.with_name(f".{table.name}.lock"), lambda holder: f"{table} is being written by another process "
                     f"(PID {holder}); one writer at a time: wait for it to finish", remove=True)


def _read(path: Path) -> dict[int, Counter[str]]:
    refuse_link(path)  # rows read from elsewhere would stand for this run's
    if not path.is_file():
        return {}
    with path.open(encoding="utf-8", newline="") as file:
        return {int(row["training_episodes"]): Counter({key: int(row[key]) for key in OUTCOMES}) for row in csv.DictReader(file)}


def _append(path: Path, point: int, episodes: int, outcomes: Counter[str]) -> None:
    """One stored row more (the header first on a new file); rows already there are never rewritten."""
    with open_text_for_append(path) as file:  # appended to, never through a link
        writer = csv.DictWriter(file, fieldnames=FIELDS)
        if file.tell() == 0:
            writer.writeheader()
        writer.writerow({"training_episodes": point, "episodes": episodes, **{key: outcomes.get(key, 0) for key in OUTCOMES}})


def summary(choices: Sequence[Choice]) -> str:
    """A Markdown table: per run the validation successes per snapshot, the kept one and its test success."""
    lines = ["| configuration | seed | validation successes per snapshot | kept | test success |", "|---|---|---|---|---|"]
    for choice in choices:
        per_point = " / ".join(f"{successes} ({point:,})" for point, successes in choice.validation.items())
        lines.append(f"| {choice.configuration} | {choice.seed} | {per_point} | {choice.chosen:,} | "
                     f"{choice.test_successes} of {choice.test_episodes} ({100 * choice.test_success:.1f}%) |")
    by_configuration: dict[str, list[Choice]] = {}
    for choice in choices:
        by_configuration.setdefault(choice.configuration, []).append(choice)
    for name, runs in by_configuration.items():
        won, played = sum(c.test_successes for c in runs), sum(c.test_episodes for c in runs)
        lines.append(f"\n{name}: {won} of {played} test episodes ({100 * won / played:.1f}%) over {len(runs)} seeds at the kept snapshots")
    return "\n".join(lines)
