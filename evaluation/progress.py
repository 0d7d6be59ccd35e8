"""The benchmark's live progress: one bar over the episodes (training and test) of all runs.

With a protocol in env steps the number of training episodes is not known in advance: the bar
then counts the training env steps of all runs (test episodes are not counted; a run's share is
full once it is complete). The functions keep their names; their counts are in the protocol's
unit.

Where the counts come from depends on the executor: the local executors read the files the
runs write (:func:`episodes_on_disk`); the Ray executor receives them from its tasks, which
may write on other machines. The bar only asks ``count(job)`` once per interval.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from crowdnav.agents.runs.folder import last_logged_row, logged_episodes
from crowdnav.evaluation.protocol import Protocol
from crowdnav.evaluation.storage import EVALUATIONS_DIR, META_FILE, TRAIN_DIR


def run_episodes(protocol: Protocol) -> int:
    """Training plus test episodes of one complete run (a protocol in env steps: its training env steps)."""
    if protocol.unit == "steps":
        return protocol.budget  # train_steps
    return protocol.train_episodes + protocol.evaluations * protocol.test_episodes


def episodes_on_disk(folder: str | Path, protocol: Protocol) -> int:
    """Episodes a run has done so far, read from its folder (training log lines and evaluation files);
    a protocol in env steps: the env steps of its last logged training episode."""
    folder = Path(folder)
    if (folder / META_FILE).is_file():
        return run_episodes(protocol)
    if protocol.unit == "steps":
        return min(logged_steps(folder / TRAIN_DIR), protocol.budget)
    trained = logged_episodes(folder / TRAIN_DIR)
    evaluations = len(list((folder / EVALUATIONS_DIR).glob("evaluation_*.csv"))) if (folder / EVALUATIONS_DIR).is_dir() else 0
    return min(trained, protocol.train_episodes) + evaluations * protocol.test_episodes


def logged_steps(train_dir: str | Path) -> int:
    """The run's env steps when its last logged training episode ended (0 before the first); reads the log's tail only."""
    row = last_logged_row(train_dir)
    return int(row["timesteps"]) if row is not None and row.get("timesteps", "").isdigit() else 0


class ProgressBar:
    """A tqdm bar over all runs' episodes, refreshed every ``interval`` seconds from ``count(job)``, with lines above it."""

    def __init__(self, jobs: Sequence[Any], protocol: Protocol, count: Callable[[Any], int], *, title: str, enabled: bool,
                 interval: float = 1.0):
        self.jobs, self.count = list(jobs), count
        self.runs, self.done, self.failed = len(self.jobs), 0, 0
        self.bar = None
        self._stop = threading.Event()
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=self.runs * run_episodes(protocol), unit="ep" if protocol.unit == "episodes" else "step", desc=title,
                            dynamic_ncols=True, unit_scale=protocol.unit == "steps")
            self._refresh()
            self._thread = threading.Thread(target=self._poll, args=(interval,), daemon=True)
            self._thread.start()

    def _refresh(self) -> None:
        if self.bar is None:
            return
        self.bar.n = sum(self.count(job) for job in self.jobs)
        self.bar.set_postfix_str(f"runs {self.done}/{self.runs} done" + (f", {self.failed} failed" if self.failed else ""), refresh=False)
        self.bar.refresh()

    def _poll(self, interval: float) -> None:
        while not self._stop.wait(interval):
            try:
                self._refresh()
            except (OSError, ValueError):  # a file being replaced while read: next time
                pass

    def finished(self, outcome: dict[str, Any]) -> None:
        if outcome.get("status") == "failed":
            self.failed += 1
        else:
            self.done += 1
        self._refresh()

    def write(self, line: str, log: Callable[[str], None]) -> None:
        """A line above the progress bar (or to ``log`` without one)."""
        if self.bar is not None:
            self.bar.write(line)
        else:
            log(line)

    def close(self) -> None:
        self._stop.set()
        if self.bar is not None:
            self._thread.join()
            self._refresh()
            self.bar.close()
