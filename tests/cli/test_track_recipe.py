"""docs/architecture.md's recipe "Adding a track", followed end to end from the command line on a track file of its own:
``crowdnav track check`` gives its fingerprint, ``crowdnav track reference`` plays its baselines and adds a reference agent
(a finished ``crowdnav benchmark`` of the toy algorithm, tests/agents/toy_algorithm.py, on the track's setting),
``crowdnav evaluate --track`` plays a policy on it, and ``crowdnav leaderboard --track`` ranks them all."""

from __future__ import annotations

import csv
import json
import re

import pytest
import yaml

from crowdnav.cli import main
from crowdnav.registry import register_algorithm, unregister_algorithm
from tests.agents.toy_algorithm import SPEC

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

TRACK = {"name": "tiny_open", "version": 1, "description": "open_space with 3 humans, 30 steps, 4 episodes (a test track)",
         "scenario": "open_space", "overrides": {"humans.count": 3}, "time_limit_steps": 30, "test_episodes": 4, "test_seed_base": 0,
         "observations": ["goal", "velocity"], "fingerprint": "0000000000000000"}
"""A track of the test's own: its fingerprint is not known until `crowdnav track check` plays it."""
CLEAN = "0123456789abcdef0123456789abcdef01234567"
"""The commit the reference agent's runs record: reference agents are published only from a clean checkout."""


@pytest.fixture
def random_search():
    register_algorithm("random_search", SPEC)
    yield "random_search"
    unregister_algorithm("random_search")


def experiment(track):
    """A benchmark of the toy on the track's setting (scenario, overrides, time limit, test set, observations), 3 seeds."""
    protocol = {"train_episodes": 4, "eval_every": 2, "test_episodes": track["test_episodes"], "test_seed_base": track["test_seed_base"],
                "seeds": 3, "final_evaluations": 1}
    defaults = {"algo": "random_search", "scenario": track["scenario"], "modalities": track["observations"],
                "overrides": {**track["overrides"], "max_steps": track["time_limit_steps"]}, "num_envs": 1}
    return {"name": "toy", "description": "the toy algorithm on the tiny track", "protocol": protocol, "defaults": defaults,
            "configurations": [{"name": "rs", "label": "random search, goal + velocity", "train": {}}]}


def test_a_new_track_is_fingerprinted_given_reference_results_and_ranks_a_policy(tmp_path, monkeypatch, capsys, random_search):
    monkeypatch.chdir(tmp_path)
    track = tmp_path / "tiny_open.yaml"
    track.write_text(yaml.safe_dump(TRACK, sort_keys=False), encoding="utf-8")

    # 1. the fingerprint: `track check` plays the episodes and prints it; stored, the file loads and checks
    assert main(["track", "check", str(track)]) == 1
    printed = re.search(r"fingerprint ([0-9a-f]{16}), stored 0000000000000000", capsys.readouterr().out)
    assert printed is not None
    track.write_text(track.read_text(encoding="utf-8").replace("0000000000000000", printed.group(1)), encoding="utf-8")
    assert main(["track", "check", str(track)]) == 0
    assert main(["track", "show", str(track)]) == 0
    shown = capsys.readouterr().out
    assert "unchanged" in shown and "4 episodes, seeds 0-3" in shown and "observations: goal, velocity" in shown

    # 2. its reference results: cheap baselines only
    argv = ["track", "reference", str(track), "--out", "ref", "--allow-dirty", "--baseline", "straight", "--baseline", "social_force"]
    assert main(argv) == 0
    reference = tmp_path / "ref" / "tiny_open"
    assert sorted(path.name for path in reference.glob("*.csv")) == ["baseline_social_force.csv", "baseline_straight.csv"]

    # 3. a reference agent: a finished benchmark of the track's setting, its runs recorded as from a clean commit
    (tmp_path / "toy.yaml").write_text(yaml.safe_dump(experiment(TRACK)), encoding="utf-8")
    monkeypatch.setattr("crowdnav.evaluation.runner.git_commit", lambda: CLEAN)
    assert main(["benchmark", "toy.yaml", "--out", "results", "--executor", "serial", "--workers", "1", "--no-video", "--no-progress"]) == 0
    assert main(["track", "reference", str(track), "--agents", "results/toy/rs", "--out", "ref", "--allow-dirty"]) == 0
    index = json.loads((reference / "reference.json").read_text(encoding="utf-8"))
    assert [entry["name"] for entry in index["entries"]] == ["baseline_straight", "baseline_social_force",
                                                             *(f"agent_toy_rs_seed{seed}" for seed in range(3))]
    assert all(entry["episodes_checked"].startswith("straight-to-goal as the track's") for entry in index["entries"][2:])
    with open(reference / "agent_toy_rs_seed0.csv", encoding="utf-8") as file:
        agent = [(int(row["test_seed"]), row["outcome"], int(row["steps"])) for row in csv.DictReader(file)]
    assert [seed for seed, _, _ in agent] == [0, 1, 2, 3]  # its final evaluation, on the track's test set

    # 4. a policy evaluated on the track (seed 0's run of the toy), then ranked with the reference results
    capsys.readouterr()
    assert main(["evaluate", "results/toy/rs/seed_0", "--track", str(track), "--name", "mine", "--out", "res", "--no-progress"]) == 0
    played = next((tmp_path / "res").rglob("test_episodes.csv"))
    meta = json.loads((played.parent / "meta.json").read_text(encoding="utf-8"))
    assert meta["track"] == {"name": "tiny_open", "version": 1, "fingerprint": printed.group(1)}
    with open(played, encoding="utf-8") as file:  # the run's final policy on the same episodes: what its final evaluation played
        assert [(int(row["test_seed"]), row["outcome"], int(row["steps"])) for row in csv.DictReader(file)] == agent
    assert main(["leaderboard", "--track", str(track), "--reference", str(reference), "res"]) == 0
    board = capsys.readouterr().out
    rows = [line.split(" | ")[1] for line in board.splitlines() if re.match(r"\| \d+ \| ", line)]
    assert "## Track tiny_open v1" in board and sorted(rows) == sorted([
        "mine *", "social force, privileged (scripted)", "straight to goal (scripted)",
        *(f"random search, goal + velocity (4 training episodes, seed {seed})" for seed in range(3))])
