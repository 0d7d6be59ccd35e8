"""`crowdnav evaluate` plays its test episodes in bounded batches: memory does not grow with --episodes (it held ~110 KB
per episode, all played side by side), and the batches write the rows one batch of every episode writes."""

from __future__ import annotations

import subprocess
import sys

import pytest
from crowdnav.evaluation import evaluate

TINY = {"max_steps": 3, "humans.count": 1}
MEASURE = """
import resource, sys, tempfile
from crowdnav.evaluation import evaluate
evaluate.BATCH_EPISODES = 100
with tempfile.TemporaryDirectory() as out:
    evaluate.evaluate_policy("baseline:straight", "open_space", out, episodes=int(sys.argv[1]), overrides={TINY})
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""
PER_EPISODE_KB = 20
"""Bound on the peak memory one more episode may add (KiB); playing every episode side by side added ~110 KiB."""


def _peak_kb(episodes: int) -> int:
    """Peak resident memory (KiB) of a fresh process evaluating baseline:straight on ``episodes`` one-human, 3-step episodes."""
    done = subprocess.run([sys.executable, "-c", MEASURE.replace("{TINY}", repr(TINY)), str(episodes)],
                          capture_output=True, text=True, timeout=300, check=True)
    return int(done.stdout.split()[-1])


@pytest.mark.slow  # a 10 s soak
def test_peak_memory_of_an_evaluation_does_not_grow_with_its_episodes():
    few, many = _peak_kb(300), _peak_kb(1300)
    assert many - few < PER_EPISODE_KB * 1000, f"{few} KiB for 300 episodes, {many} KiB for 1300"


def test_episodes_played_in_batches_write_the_rows_of_one_batch(tmp_path, monkeypatch):
    one = evaluate.evaluate_policy("baseline:straight", "open_space", tmp_path / "one", episodes=7, overrides=TINY)
    monkeypatch.setattr(evaluate, "BATCH_EPISODES", 3)  # batches of 3, 3 and 1
    batched = evaluate.evaluate_policy("baseline:straight", "open_space", tmp_path / "batched", episodes=7, overrides=TINY)
    table = (batched / "test_episodes.csv").read_text()
    assert table == (one / "test_episodes.csv").read_text()
    assert [line.split(",")[6] for line in table.splitlines()[1:]] == [str(i) for i in range(7)]  # numbered over the test set
