"""Shared robot training (agents: robots) resumes exactly: stopped after any checkpoint, or SIGKILLed anywhere, a resumed
run logs the episodes and ends with the weights of the run that never stopped."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from crowdnav.agents import train
from crowdnav.agents.marl.resume import STATE_FILE
from crowdnav.agents.runs.resume_state import ResumeStateError

from tests.agents.test_marl import robots_config


class Stopped(Exception):
    """Stands for a kill right after a checkpoint (the state a SIGKILL there leaves on disk)."""


def _episodes(result) -> list[tuple]:
    return [(r.episode, r.seed, r.outcome, r.reward, r.length, r.timesteps) for r in result.records]


def _weights(result) -> list[bytes]:
    return [p.detach().numpy().tobytes() for p in result.model.policy.parameters()]


def _stop_at(checkpoints: int):
    calls = []

    def stop(episodes: int) -> None:
        calls.append(episodes)
        if len(calls) == checkpoints:
            raise Stopped
    return stop


# 2 worlds x 3 robots, rollouts of 16 world steps (96 robot steps), episodes of at most 20 steps: every checkpoint but
# the final one falls with the worlds mid-episode, and some robots have ended while their world goes on
@pytest.mark.parametrize(("fields", "stop_after"), [
    ({"timesteps": 480, "checkpoint_every_steps": 96}, 1),
    ({"timesteps": 480, "checkpoint_every_steps": 96}, 3),
    # an episode budget: checkpoints follow episode counts
    ({"timesteps": None, "checkpoint_every_steps": None, "episodes": 24, "checkpoint_every": 6}, 2),
], ids=["steps-first", "steps-third", "episodes"])
def test_a_robots_run_stopped_after_a_checkpoint_resumes_bit_for_bit(tmp_path, fields, stop_after):
    whole = train(robots_config(tmp_path / "whole", **fields))
    config = robots_config(tmp_path / "stopped", **fields)
    with pytest.raises(Stopped):
        train(config, on_checkpoint=_stop_at(stop_after))
    assert (tmp_path / "stopped" / "checkpoint" / STATE_FILE).is_file()
    resumed = train(config, resume=True)
    done = len(_episodes(whole)) - len(_episodes(resumed))
    assert 0 <= done < len(_episodes(whole)) and _episodes(resumed) == _episodes(whole)[done:]
    assert _weights(resumed) == _weights(whole)
    assert resumed.model._n_updates == whole.model._n_updates and resumed.timesteps == whole.timesteps
    assert _log(tmp_path / "stopped") == _log(tmp_path / "whole")


def test_a_checkpoint_whose_worlds_load_differently_is_refused_in_one_line(tmp_path):
    config = robots_config(tmp_path / "run", timesteps=480, checkpoint_every_steps=96)
    with pytest.raises(Stopped):
        train(config, on_checkpoint=_stop_at(1))
    path = tmp_path / "run" / "checkpoint" / STATE_FILE
    with np.load(path) as archive:
        arrays = dict(archive)
    for key in [key for key in arrays if key.startswith("worlds/0/world/env/observation/")]:  # (format 1: tests/agents/test_marl_resume_states.py)
        arrays[key] = arrays[key] * 0.5  # another observation in the world's state than the stored last observation
    np.savez(path, **arrays)
    with pytest.raises(ResumeStateError, match="world 0 loaded to another observation") as error:
        train(config, resume=True)
    assert "\n" not in str(error.value)


def _log(run: Path) -> list[tuple]:
    """episodes.csv without its wall-clock column."""
    with open(run / "episodes.csv", encoding="utf-8") as file:
        return [tuple(value for key, value in row.items() if key != "seconds") for row in csv.DictReader(file)]


def _train_process(config: Path, resume: bool) -> subprocess.Popen:
    argv = [sys.executable, "-m", "crowdnav", "train", "--config", str(config), "--agents", "robots", *(["--resume"] if resume else [])]
    return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def _parameters(run: Path) -> dict[str, bytes]:
    from crowdnav.agents.sb3.model_zip import read_model_zip

    policy = read_model_zip(run / "checkpoint" / "model.zip", "cpu").parameters["policy"]
    return {name: tensor.numpy().tobytes() for name, tensor in policy.items()}


def _checkpoint_steps(run: Path, recover: bool = True) -> int:
    """The robot steps of the run's checkpoint (0: none yet or mid-swap); ``recover``: first pick one a kill cut mid-swap."""
    import json

    from crowdnav.agents.runs.folder import recover_checkpoint

    if recover:
        recover_checkpoint(run)
    try:
        return int(json.loads((run / "checkpoint" / "policy.json").read_text(encoding="utf-8"))["timesteps"])
    except (OSError, ValueError):
        return 0


@pytest.mark.slow
def test_crowdnav_train_agents_robots_sigkilled_at_random_moments_ends_as_the_run_never_killed(tmp_path):
    """Seven SIGKILLs, each followed by --resume: one before any checkpoint, six at random moments after the run got past
    its last one (mid-rollout, mid-update, mid-checkpoint); the log and the final weights are those of the run that was
    never killed (about a minute)."""
    rng = np.random.default_rng(7)
    configs = {}
    for name in ("whole", "killed"):
        fields = robots_config(tmp_path / name, timesteps=2880, checkpoint_every_steps=96)
        del fields["agents"]
        configs[name] = tmp_path / f"{name}.yaml"
        configs[name].write_text(yaml.safe_dump(fields), encoding="utf-8")
    whole = _train_process(configs["whole"], resume=False)
    assert whole.wait(timeout=600) == 0, whole.communicate()[1]
    progress = [0]
    for kill in range(7):
        process = _train_process(configs["killed"], resume=kill > 0)
        deadline = time.monotonic() + 300
        while kill > 0 and _checkpoint_steps(tmp_path / "killed", recover=False) <= progress[-1]:  # past its checkpoint
            assert process.poll() is None, process.communicate()[1]
            assert time.monotonic() < deadline
            time.sleep(0.005)
        time.sleep(float(rng.uniform(0.0, 0.3)))
        assert process.poll() is None, "the run finished before it was killed; lengthen its budget"
        os.kill(process.pid, signal.SIGKILL)
        process.wait(timeout=60)
        progress.append(_checkpoint_steps(tmp_path / "killed"))
    assert len(set(progress)) >= 5 and progress[-1] < 2880, progress  # the kills landed all along the run
    process = _train_process(configs["killed"], resume=True)
    assert process.wait(timeout=600) == 0, process.communicate()[1]
    assert _log(tmp_path / "killed") == _log(tmp_path / "whole")
    assert _parameters(tmp_path / "killed") == _parameters(tmp_path / "whole")
