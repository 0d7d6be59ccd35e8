"""fixed_agents=True: every possible human is an agent every step, the absent and gone ones inactive.

That is what SuperSuit's ``pettingzoo_env_to_vec_env_v1`` and PettingZoo's API test need when
the crowd size varies; the chain to SB3's PPO is tested here too.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from gymnasium import spaces

from crowdnav.envs import SocialForcePolicy, parallel_env
from crowdnav.envs.multi_agent import exit_at_goal

with warnings.catch_warnings():
    # pettingzoo.test's __init__ imports PettingZoo's own example envs through their deprecated API
    warnings.filterwarnings("ignore", message="The old environment creation API", category=DeprecationWarning)
    from pettingzoo.test import parallel_api_test, parallel_seed_test

FAST = {"modalities": ["goal", "closest_obstacle"]}
RANGE = {"humans.count": [2, 5]}

CASES = {
    "crowd_range": ("room_furniture", {"overrides": RANGE}),
    "crowd_range_from_zero": ("room_furniture", {"overrides": {"humans.count": [0, 3]}}),
    "crowd_range_flat": ("room_furniture", {"overrides": RANGE, "flat_observations": True}),
    "standing_groups_and_range": ("station_hall", {}),  # one standing group's count is [3, 4]
    "exits_see_robot": ("open_space", {"human_exit": exit_at_goal, "overrides": {"humans.see_robot": True}}),
}


@pytest.mark.parametrize("case", CASES)
def test_parallel_api_test_passes_without_any_warning(case):
    scenario, options = CASES[case]
    env = parallel_env(scenario, **FAST, fixed_agents=True, **options)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parallel_api_test(env, num_cycles=400)


@pytest.mark.parametrize("case", ["crowd_range", "exits_see_robot"])
@pytest.mark.filterwarnings("error")
def test_parallel_seed_test_passes(case):
    scenario, options = CASES[case]
    parallel_seed_test(lambda: parallel_env(scenario, **FAST, fixed_agents=True, **options), num_cycles=50)


def _episode_sizes(env, seeds=range(12)) -> set[int]:
    sizes = set()
    for seed in seeds:
        env.reset(seed=seed)
        sizes.add(env.simulator.n_humans)
    return sizes


def test_every_possible_agent_acts_and_only_the_episodes_crowd_is_active():
    env = parallel_env("room_furniture", **FAST, overrides=RANGE, fixed_agents=True)
    assert _episode_sizes(env) == {2, 3, 4, 5}
    rng = np.random.default_rng(0)
    for seed in range(6):
        observations, infos = env.reset(seed=seed)
        n = env.simulator.n_humans
        while env.agents:
            assert env.agents == env.possible_agents
            for i in range(5):
                name, active = f"human_{i}", i < n
                assert observations[name]["active"][0] == float(active) and infos[name]["active"] is active
                assert env.observation_space(name).contains(observations[name])
                if not active:
                    assert not any(value.any() for value in observations[name].values())
                    assert infos[name]["group"] is None
            actions = {agent: rng.uniform(-1, 1, 2).astype(np.float32) for agent in env.agents}
            observations, rewards, terminations, truncations, infos = env.step(actions)
            ended = terminations["robot"] or truncations["robot"]
            assert set(rewards) == set(terminations) == set(truncations) == set(env.possible_agents)
            assert all(terminations[a] == terminations["robot"] and truncations[a] == truncations["robot"] for a in terminations)
            assert all(rewards[f"human_{i}"] == 0.0 for i in range(n, 5))
            assert (env.agents == []) == ended


def test_fixed_agents_replays_the_default_episode_and_ignores_inactive_actions():
    """Same seed, same actions for the episode's humans: the same episode bit for bit, whatever the inactive humans are told."""
    default = parallel_env("room_furniture", **FAST, overrides=RANGE)
    fixed = parallel_env("room_furniture", **FAST, overrides=RANGE, fixed_agents=True)
    crowd = SocialForcePolicy(default.scenario)
    rng = np.random.default_rng(1)
    for seed in (0, 3):
        observations, _ = default.reset(seed=seed)
        fixed_observations, _ = fixed.reset(seed=seed)
        while default.agents:
            actions = {**crowd(observations), "robot": rng.uniform(-1, 1, 2).astype(np.float32)}
            noise = {agent: rng.uniform(-1, 1, 2).astype(np.float32) for agent in fixed.agents if agent not in actions}
            for name in default.agents[1:]:
                for key, value in observations[name].items():
                    np.testing.assert_array_equal(fixed_observations[name][key], value)
            observations, rewards, *_ = default.step(actions)
            fixed_observations, fixed_rewards, *_ = fixed.step({**actions, **noise})
            np.testing.assert_array_equal(fixed.simulator.positions, default.simulator.positions)
            assert all(fixed_rewards[agent] == reward for agent, reward in rewards.items())
        assert not fixed.agents


def test_inactive_humans_still_need_a_valid_action():
    """Every agent in env.agents acts, as PettingZoo says; a NaN is a caller's bug wherever it goes."""
    env = parallel_env("room_furniture", **FAST, overrides=RANGE, fixed_agents=True)
    env.reset(seed=1)  # 3 humans: human_3 and human_4 are inactive
    actions = {agent: np.zeros(2, dtype=np.float32) for agent in env.agents}
    with pytest.raises(ValueError, match="human_4"):
        env.step({agent: action for agent, action in actions.items() if agent != "human_4"})
    with pytest.raises(ValueError, match="human_3"):
        env.step({**actions, "human_3": np.array([np.nan, 0.0])})
    env.step(actions)  # the failed calls changed nothing
    assert env.simulator.step_count == 1


def test_flat_vector_starts_with_the_active_flag_and_matches_the_dict():
    flat = parallel_env("room_furniture", **FAST, overrides=RANGE, fixed_agents=True, flat_observations=True)
    nested = parallel_env("room_furniture", **FAST, overrides=RANGE, fixed_agents=True)
    flat_obs, _ = flat.reset(seed=1)
    dict_obs, _ = nested.reset(seed=1)
    n = flat.simulator.n_humans
    assert n == 3
    for name in flat.possible_agents:
        np.testing.assert_array_equal(flat_obs[name], spaces.flatten(nested.observation_space(name), dict_obs[name]))
        if name != "robot":
            assert flat_obs[name][0] == float(int(name.split("_")[1]) < n)
    assert not flat_obs["human_4"].any()


def test_a_human_that_exits_stays_an_agent_inactive_and_still():
    env = parallel_env("open_space", **FAST, human_exit=exit_at_goal, overrides={"max_steps": 400}, fixed_agents=True)
    crowd = SocialForcePolicy(env.scenario)
    observations, infos = env.reset(seed=0)
    sim, exited = env.simulator, set()
    while env.agents:
        assert env.agents == env.possible_agents
        actions = {**crowd(observations), "robot": np.zeros(2, dtype=np.float32)}
        observations, rewards, terminations, truncations, infos = env.step(actions)
        for name in exited:  # gone on an earlier step: zero observation, reward 0, not moving
            assert not infos[name]["active"] and rewards[name] == 0.0
            assert not any(value.any() for value in observations[name].values())
            assert sim.velocities[1 + int(name.split("_")[1])] == 0
        if env.agents:
            assert not any(terminations.values()) and not any(truncations.values())
        exited |= {name for name in env.possible_agents[1:] if infos[name]["goal_reached"]}
    assert exited, "no human reached its goal"


def test_the_documented_loop_runs_under_fixed_agents():
    env = parallel_env("station_hall", **FAST, fixed_agents=True)
    crowd = SocialForcePolicy(env.scenario)
    for seed in range(4):
        observations, _ = env.reset(seed=seed)
        while env.agents:
            actions = crowd(observations)
            assert all(np.isfinite(action).all() for action in actions.values())
            inactive = [f"human_{i}" for i in range(env.simulator.n_humans, env.scenario.humans.max_count)]
            assert all(not actions[name].any() for name in inactive)
            actions["robot"] = np.zeros(2, dtype=np.float32)
            observations, *_ = env.step(actions)


SB3_CASES = {"crowd_range": ("room_furniture", RANGE), "station_hall": ("station_hall", {})}


@pytest.mark.parametrize("case", SB3_CASES)
def test_supersuit_chain_trains_sb3_ppo_with_a_varying_crowd(case):
    """pad -> vec env -> concat -> SB3 PPO (one policy shared by every agent): it learns, then runs
    episodes of different crowd sizes back to back with the absent humans' rows all zero."""
    ss = pytest.importorskip("supersuit")
    sb3 = pytest.importorskip("stable_baselines3")
    torch = pytest.importorskip("torch")
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tiny networks: more threads only add contention
    try:
        _train_and_run(ss, sb3, *SB3_CASES[case])
    finally:
        torch.set_num_threads(threads)


def _train_and_run(ss, sb3, scenario: str, overrides: dict) -> None:
    short = {**overrides, "max_steps": 40}  # several episodes, and crowd sizes, per world below
    env = parallel_env(scenario, **FAST, overrides=short, flat_observations=True, fixed_agents=True)
    humans = env.scenario.humans.max_count
    env = ss.pad_observations_v0(ss.pad_action_space_v0(env))
    vec = ss.pettingzoo_env_to_vec_env_v1(env)
    vec = ss.concat_vec_envs_v1(vec, 2, num_cpus=0, base_class="stable_baselines3")
    assert vec.num_envs == 2 * (1 + humans)
    # SuperSuit's ConcatVecEnv has no seed(), so PPO(seed=...) fails: seed the worlds through
    # its reset (copy i gets seed + i) and torch through SB3; learn's unseeded reset continues them
    vec.venv.reset(seed=0)
    sb3.common.utils.set_random_seed(0)
    model = sb3.PPO("MlpPolicy", vec, n_steps=8, batch_size=32, n_epochs=1, device="cpu")
    model.learn(total_timesteps=300)  # agent transitions: rollouts of 8 steps x num_envs rows
    assert model.num_timesteps >= 300

    observations, sizes, ends = vec.reset(), set(), 0
    for _ in range(120):
        actions, _ = model.predict(observations, deterministic=True)
        assert actions.shape == (vec.num_envs, 2) and np.isfinite(actions).all()
        observations, rewards, dones, infos = vec.step(actions)
        assert np.isfinite(observations).all() and np.isfinite(rewards).all()
        rows = observations.reshape(2, 1 + humans, -1)[:, 1:]  # per world: the humans' rows
        active = rows[..., 0]  # the flat vector's first value is the active flag
        assert set(np.unique(active)) <= {0.0, 1.0} and not rows[active == 0].any()
        sizes |= set(active.sum(axis=1).astype(int).tolist())
        ends += int(dones.reshape(2, 1 + humans).all(axis=1).sum())
    assert ends >= 4 and len(sizes) > 1, (ends, sizes)
