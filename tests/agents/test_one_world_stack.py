"""One world through the native vector env trains as one ``gymnasium.Env`` does, bit for bit.

``num_envs: 1`` runs (the published results) collect from one wrapped env; the vector stack with one
world must give the same episodes and final weights, fresh and resumed after a checkpoint, so that
the stack can become a matter of size alone (``TrainingSession.vector``; docs/architecture.md says what
still keeps one world on the single env).
"""

from __future__ import annotations

import pytest
from crowdnav.agents.config import config_from_mapping
from crowdnav.agents.train_result import TrainResult
from crowdnav.agents.training_session import TrainingSession

from tests.agents.agents_tiny import tiny_config


class Stopped(Exception):
    """Stands for a kill right after a checkpoint."""


def _run(config: dict, *, vector: bool, resume: bool = False, stop_at: int | None = None) -> TrainResult:
    def stop(episodes: int) -> None:
        if episodes == stop_at:
            raise Stopped

    session = TrainingSession(config_from_mapping(config), resume, stop if stop_at is not None else None)
    session.vector = vector
    return session.run()


def _episodes(result: TrainResult) -> list[tuple]:
    return [(r.seed, r.outcome, r.reward, r.length, r.timesteps) for r in result.records]


def _weights(result: TrainResult) -> list[bytes]:
    return [p.detach().numpy().tobytes() for p in result.model.policy.parameters()]


@pytest.mark.parametrize("algo", ["sac", "ppo"])
def test_one_world_through_the_vector_env_trains_bit_for_bit_like_the_single_env(tmp_path, algo):
    single = _run(tiny_config(tmp_path / "single", algo=algo, episodes=4), vector=False)
    vector = _run(tiny_config(tmp_path / "vector", algo=algo, episodes=4), vector=True)
    assert _episodes(vector) == _episodes(single)
    assert _weights(vector) == _weights(single)


@pytest.mark.slow
@pytest.mark.parametrize(("algo", "algo_kwargs"), [
    ("sac", {"train_freq": 4, "gradient_steps": -1}),  # rewound to the episode end, as the single env's checkpoints are
    ("ppo", {"n_steps": 32, "n_epochs": 1}),  # the world mid-episode, replayed through CrowdNavVectorEnv.restore_worlds
])
def test_one_world_through_the_vector_env_resumes_to_the_single_envs_uninterrupted_run(tmp_path, algo, algo_kwargs):
    whole = _run(tiny_config(tmp_path / "whole", algo=algo, episodes=6, algo_kwargs=algo_kwargs), vector=False)
    config = tiny_config(tmp_path / "stopped", algo=algo, episodes=6, algo_kwargs=algo_kwargs)
    with pytest.raises(Stopped):
        _run(config, vector=True, stop_at=2)
    resumed = _run(config, vector=True, resume=True)
    assert _episodes(resumed) == _episodes(whole)[2:]
    assert _weights(resumed) == _weights(whole)
