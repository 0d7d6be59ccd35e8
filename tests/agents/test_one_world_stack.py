"""``num_envs`` is a size: one world trains through the native vector env as the published ``num_envs: 1`` runs did.

Those runs collected from one wrapped ``gymnasium.Env`` (``make_env``; on-policy in a ``DummyVecEnv`` behind an
``ActionLog``). ``TrainingSession`` now collects from the vector env for every world count; :class:`PublishedStack`
rebuilds the old stack here as the reference: the same episodes and final weights, fresh and resumed after a
checkpoint, and the checkpoints that stack wrote (one world stored as kind "single", its actions replayed) still resume
bit for bit.
"""

from __future__ import annotations

import json
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from crowdnav.agents.runs.folder import checkpoint_dir
from crowdnav.agents.runs.result import TrainResult
from crowdnav.agents.runs.resume_state import ROLLOUT_ARRAYS, ActionLog
from crowdnav.agents.sb3.factory import make_env, observation_normalization
from crowdnav.agents.sb3.session import TrainingSession
from crowdnav.agents.training.checks import scenario_max_steps
from crowdnav.agents.training.config import config_from_mapping
from stable_baselines3.common.vec_env import DummyVecEnv

from tests.agents.agents_tiny import tiny_config
from tests.agents.format1 import RecordingSession


class Stopped(Exception):
    """Stands for a kill right after a checkpoint."""


class PublishedStack(TrainingSession):
    """The collection stack of ``num_envs: 1`` runs before the vector env took every world count (the reference).

    Its checkpoints keep no worlds (its old rollout writer is gone): it is only run uninterrupted.
    """

    def _build_env(self, leog: Any) -> None:
        single = make_env(self.config, leog, self.first_episode)
        self.env = self.collecting = single  # type: ignore[assignment]
        if not self.off_policy:
            self.collecting = ActionLog(DummyVecEnv([partial(_same, single)]))
        self.max_steps = scenario_max_steps(single)
        self.scales = observation_normalization(single)

    def build(self) -> None:
        super().build()
        self.resume_point.rollout_state = lambda: None  # type: ignore[method-assign]


def _same(env: Any) -> Any:
    return env


def _run(config: dict, *, published: bool = False, resume: bool = False, stop_at: int | None = None,
         session_class: type[TrainingSession] | None = None) -> TrainResult:
    def stop(episodes: int) -> None:
        if episodes == stop_at:
            raise Stopped

    session_class = session_class or (PublishedStack if published else TrainingSession)
    return session_class(config_from_mapping(config), resume, stop if stop_at is not None else None).run()


def _episodes(result: TrainResult) -> list[tuple]:
    return [(r.seed, r.outcome, r.reward, r.length, r.timesteps) for r in result.records]


def _weights(result: TrainResult) -> list[bytes]:
    return [p.detach().numpy().tobytes() for p in result.model.policy.parameters()]


def test_every_world_count_collects_from_the_vector_env(tmp_path):
    session = TrainingSession(config_from_mapping(tiny_config(tmp_path / "run", algo="sac", episodes=1)), False)
    session.restore()
    session.build()
    assert type(session.collecting).__name__ == "CrowdNavSB3VecEnv"  # nothing records its steps: checkpoints store states
    assert session.collecting.num_envs == 1


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_one_world_trains_bit_for_bit_like_the_published_single_env_stack(tmp_path, algo):
    published = _run(tiny_config(tmp_path / "published", algo=algo, episodes=4), published=True)
    now = _run(tiny_config(tmp_path / "now", algo=algo, episodes=4))
    assert _episodes(now) == _episodes(published)
    assert _weights(now) == _weights(published)


@pytest.mark.slow
@pytest.mark.parametrize(("algo", "algo_kwargs"), [
    ("sac", {"train_freq": 4, "gradient_steps": -1}),  # rewound to the episode end, as the single env's checkpoints were
    ("ppo", {"n_steps": 32, "n_epochs": 1}),  # the world mid-episode, replayed through CrowdNavVectorEnv.restore_worlds
])
def test_one_world_resumes_to_the_published_stacks_uninterrupted_run(tmp_path, algo, algo_kwargs):
    whole = _run(tiny_config(tmp_path / "whole", algo=algo, episodes=6, algo_kwargs=algo_kwargs), published=True)
    config = tiny_config(tmp_path / "stopped", algo=algo, episodes=6, algo_kwargs=algo_kwargs)
    with pytest.raises(Stopped):
        _run(config, stop_at=2)
    resumed = _run(config, resume=True)
    assert _episodes(resumed) == _episodes(whole)[2:]
    assert _weights(resumed) == _weights(whole)


def _as_single_stack_checkpoint(path: Path) -> None:
    """Rewrite a one-world format-1 ``rollout_state.npz`` (kind "vector": its actions recorded) as the single-env stack
    wrote it: kind "single", no returns or lengths."""
    with np.load(path, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    meta = json.loads(str(arrays.pop("meta.json")))
    worlds = meta["worlds"]
    meta["worlds"] = {"kind": "single", "run_seed": worlds["run_seed"], "episode": worlds["episode_of"][0]}
    del arrays["worlds/returns"], arrays["worlds/episode_lengths"]
    np.savez(path, **arrays, **{"meta.json": np.array(json.dumps(meta))})


@pytest.mark.slow
def test_a_single_env_stack_checkpoint_mid_episode_resumes_bit_for_bit(tmp_path):
    algo_kwargs = {"n_steps": 32, "n_epochs": 1}
    whole = _run(tiny_config(tmp_path / "whole", algo="ppo", episodes=6, algo_kwargs=algo_kwargs))
    config = tiny_config(tmp_path / "stopped", algo="ppo", episodes=6, algo_kwargs=algo_kwargs)
    with pytest.raises(Stopped):
        _run(config, stop_at=2, session_class=RecordingSession)
    rollout = checkpoint_dir(tmp_path / "stopped") / ROLLOUT_ARRAYS
    assert rollout.is_file()  # the world mid-episode: what the old stack stored as kind "single"
    _as_single_stack_checkpoint(rollout)
    resumed = _run(config, resume=True)
    assert _episodes(resumed) == _episodes(whole)[2:]  # the episode's return so far counted again by the replay
    assert _weights(resumed) == _weights(whole)
