"""Fixtures the command-line tests share."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from crowdnav.cli import main

HALL = "robots_crossing_hall"
"""The several-robots scenario the shared robot policy tests train in."""


@pytest.fixture(scope="module")
def robots_run(tmp_path_factory) -> Path:
    """The smallest run the CLI trains: one rollout of 2 worlds x 3 robots x 16 steps (96 robot steps, ~2 s)."""
    folder = tmp_path_factory.mktemp("robots")
    config = {"scenario": HALL, "algo": "ppo", "num_envs": 2, "timesteps": 96, "n_steps": 16, "batch_size": 48,
              "net_arch": [16], "seed": 0, "out": str(folder / "run"), "progress": False, "overrides": {"max_steps": 20},
              "sensors": {"lidar": {"beams": 16}}}
    path = folder / "robots.yaml"
    path.write_text(yaml.safe_dump(config), encoding="utf-8")
    assert main(["train", "--config", str(path), "--agents", "robots"]) == 0
    return folder / "run"
