"""benchmarks/probe_training.py: variant files and the side-by-side runs cut at a wall-time limit."""

from __future__ import annotations

import json
import re

import pytest

from benchmarks import probe_training


def test_variants_extend_the_base_entry_and_get_their_own_out_folder(tmp_path):
    path = tmp_path / "variants.json"
    path.write_text(json.dumps({"base": {"algo": "ppo", "seed": 0, "timesteps": 10}, "a": {}, "b": {"seed": 1, "algo": "sac"}}))
    variants = probe_training.load_variants(str(path), "/runs")
    assert variants == {
        "a": {"progress": False, "algo": "ppo", "seed": 0, "timesteps": 10, "out": "/runs/a"},
        "b": {"progress": False, "algo": "sac", "seed": 1, "timesteps": 10, "out": "/runs/b"},
    }


@pytest.mark.slow
def test_a_run_still_training_at_the_limit_is_killed_and_judged_by_its_saved_snapshots(tmp_path, capsys):
    path = tmp_path / "variants.json"
    base = {"algo": "ppo", "scenario": "open_space", "modalities": ["closest_obstacle", "goal"], "num_envs": 4,
            "n_steps": 16, "checkpoint_every_steps": 64}
    path.write_text(json.dumps({"base": base, "short": {"timesteps": 128}, "endless": {"timesteps": 10**9}}))
    probe_training.main(["--variants", str(path), "--out", str(tmp_path / "runs"), "--workers", "2",
                         "--train-seconds", "45", "--last", "1", "--tests", "2"])
    out = capsys.readouterr().out
    assert "endless: still training at 45 s, killed" in out
    assert "short        128 env steps: success" in out
    assert re.search(r"endless +[\d,]+ env steps: success", out)  # judged by a snapshot it saved before the kill
