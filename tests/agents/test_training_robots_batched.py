"""Batched training on a several-robot scenario (robots:): the native vector env's TeamWorlds under SB3, resumed exactly."""

from __future__ import annotations

import pandas as pd
import pytest
from crowdnav.agents import train
from crowdnav.agents.runs.folder import checkpoint_dir
from crowdnav.agents.runs.resume_state import ROLLOUT_ARRAYS

from tests.agents.test_training_batched import Stopped, _log, _weights, batched_config

ROBOTS = {"scenario": "robots_crossing_hall", "overrides": {"max_steps": 40, "humans.count": 3}}


@pytest.mark.slow  # ~6 s: two short PPO runs and a resume
def test_a_robots_run_stopped_after_a_checkpoint_resumes_bit_for_bit_like_the_uninterrupted_run(tmp_path):
    """The first robot learns with PPO in 4 worlds; the stopped run's worlds are rebuilt mid-episode (restore_worlds)."""
    fields = {**ROBOTS, "episodes": 1, "timesteps": 192, "checkpoint_every_steps": 64}
    whole = train(batched_config(tmp_path / "whole", "ppo", **fields))
    config = batched_config(tmp_path / "stopped", "ppo", **fields)

    def stop(episodes):
        raise Stopped

    with pytest.raises(Stopped):
        train(config, on_checkpoint=stop)
    assert (checkpoint_dir(tmp_path / "stopped") / ROLLOUT_ARRAYS).is_file()  # its worlds mid-episode, to replay
    resumed = train(config, resume=True)
    pd.testing.assert_frame_equal(_log(tmp_path / "stopped"), _log(tmp_path / "whole"))
    assert len(_log(tmp_path / "whole")) > 4  # episodes ended in every stretch: autoresets under SB3 too
    assert _weights(resumed) == _weights(whole)
