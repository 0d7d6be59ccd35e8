"""SB3 collecting from the native vector env: the adapter equals SB3's DummyVecEnv of single envs, and SB3 trains on it."""

from __future__ import annotations

import numpy as np
from crowdnav.agents.sb3.vec_env import CrowdNavSB3VecEnv
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from crowdnav.envs import CrowdNavEnv

OPTIONS = {"modalities": ["goal", "lidar", "velocity"], "overrides": {"humans.count": 5}}


def _same_info(mine: dict, theirs: dict) -> bool:
    keys = set(theirs) - {"episode", "terminal_observation"}
    if {k for k in mine if k not in ("episode", "terminal_observation")} != keys or any(mine[k] != theirs[k] for k in keys):
        return False
    if "episode" in theirs and (mine["episode"]["r"], mine["episode"]["l"]) != (theirs["episode"]["r"], theirs["episode"]["l"]):
        return False
    if "terminal_observation" in theirs:
        return all(np.array_equal(mine["terminal_observation"][k], theirs["terminal_observation"][k]) for k in theirs["terminal_observation"])
    return True


def test_sb3_adapter_equals_dummy_vec_env_of_monitored_single_envs_bit_for_bit():
    mine = CrowdNavSB3VecEnv.make("open_space", 4, **OPTIONS)
    theirs = DummyVecEnv([lambda: Monitor(CrowdNavEnv("open_space", **OPTIONS)) for _ in range(4)])
    mine.seed(3)
    theirs.seed(3)
    first, second = mine.reset(), theirs.reset()
    assert all(np.array_equal(first[k], second[k]) for k in second)
    rng, ends = np.random.default_rng(0), 0
    for _ in range(200):
        actions = rng.uniform(-1, 1, (4, 2)).astype(np.float32)
        mine.step_async(actions)
        theirs.step_async(actions)
        (obs_a, rew_a, done_a, info_a), (obs_b, rew_b, done_b, info_b) = mine.step_wait(), theirs.step_wait()
        assert all(obs_a[k].tobytes() == obs_b[k].tobytes() for k in obs_b)
        assert rew_a.tobytes() == rew_b.tobytes() and np.array_equal(done_a, done_b)
        assert all(_same_info(a, b) for a, b in zip(info_a, info_b, strict=True))
        ends += int(done_a.sum())
    assert ends > 0


def test_sb3_sac_and_ppo_train_on_the_native_vector_env_with_normalised_observations():
    probe = CrowdNavEnv("open_space", **OPTIONS)
    scales = {key: modality.normalization() for key, modality in probe.core.modalities.items()}
    env = CrowdNavSB3VecEnv.make("open_space", 4, seed=0, scales=scales, **OPTIONS)
    assert env.observation_space["goal"].high[0] <= 2.0  # the normalised Box, not metres
    SAC("MultiInputPolicy", env, learning_starts=50, batch_size=32, policy_kwargs={"net_arch": [16]}, seed=0).learn(120)
    PPO("MultiInputPolicy", env, n_steps=16, batch_size=32, n_epochs=1, policy_kwargs={"net_arch": [16]}, seed=0).learn(64)


def test_calls_aimed_at_some_worlds_or_at_the_autoreset_mode_are_refused_and_whole_calls_run_once():
    import pytest

    env = CrowdNavSB3VecEnv.make("open_space", 3, **OPTIONS)
    env.reset()
    calls = []
    env.env.probe = lambda: calls.append(1) or "done"
    with pytest.raises(ValueError, match=r"indices=\[1\]\): the 3 worlds are one batched env"):
        env.env_method("reset", indices=[1])
    with pytest.raises(ValueError, match="same-step autoreset"):
        env.set_attr("autoreset_mode", "bogus")
    with pytest.raises(ValueError, match="no such attribute"):
        env.set_attr("autoreset_mod", 1)
    assert env.env_method("probe") == ["done"] * 3 and calls == [1]  # one call acts on every world
    assert env.get_attr("num_envs", indices=[0, 2]) == [3, 3]
    env.close()


def test_resume_rebuilds_worlds_through_public_methods_and_touches_no_private_member_of_the_vector_env():
    import ast

    from tests.paths import REPO

    tree = ast.parse((REPO / "agents" / "runs" / "resume_worlds.py").read_text(encoding="utf-8"))
    names = {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)}
    private = {name for name in names if name.startswith("_") and not name.startswith("__")}
    # only the DummyVecEnv internals of the one-env path and a recurrent model's LSTM state (not the env's), which
    # agents/sb3/internals.py checks against SB3 and sb3-contrib
    assert private <= {"_save_obs", "_obs_from_buf", "_reset_seeds", "_last_lstm_states"}, private
    assert hasattr(CrowdNavSB3VecEnv, "restore_worlds") and hasattr(CrowdNavSB3VecEnv, "world_counts")
