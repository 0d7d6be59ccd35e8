"""The native vector env and its batched simulator: world i is the single env seeded s + i, bit for bit."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import crowdnav  # noqa: F401  (registers the ids)
from crowdnav import Simulator
from crowdnav.batch.scalar_math import TWO_PI, cmul, remainder
from crowdnav.batch.simulator import BatchSimulator
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.worlds.compiled import load_world

ALL = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]


def _same(a, b) -> bool:
    """Deep equality of observations/infos, arrays compared bit for bit."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.dtype == object or b.dtype == object:
            return a.shape == b.shape and all(_same(x, y) for x, y in zip(a.ravel(), b.ravel(), strict=True))
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    return type(a) is type(b) and a == b


def test_scalar_math_reproduces_python_remainder_cos_sin_and_complex_products():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-12, 12, 20_000), [math.pi, -math.pi, TWO_PI, 3 * math.pi, 0.0, -0.0]])
    assert np.array_equal(remainder(x, TWO_PI).view(np.int64), np.array([math.remainder(v, TWO_PI) for v in x]).view(np.int64))
    assert np.array_equal(np.cos(x), [math.cos(v) for v in x]) and np.array_equal(np.sin(x), [math.sin(v) for v in x])
    a, b = rng.normal(size=(2, 2000)) + 1j * rng.normal(size=(2, 2000))
    re, im = cmul(a.real, a.imag, b.real, b.imag)
    assert all(complex(p) * complex(q) == complex(r, i) for p, q, r, i in zip(a, b, re, im, strict=True))
    assert all(abs(complex(p)) == h for p, h in zip(a, np.hypot(a.real, a.imag), strict=True))


@pytest.mark.parametrize(("scenario", "overrides"), [
    ("room_furniture", None),
    ("station_hall", None),  # groups: standing circles, respawns
    ("cafe", {"robot.kinematics": "unicycle", "robot.max_angular_speed": 1.5}),
    ("open_space", {"humans.count": [0, 6]}),  # crowd sizes differ across worlds, including none
    ("doorway", {"humans.stall.time": 2.0}),  # stalls (mirror rule): humans pinned at the wall beside the door turn back
    ("station_hall", {"humans.stall.time": 1.0}),  # stalls with groups: sample, respawn and stop rules, standing circles
    # a group that walks together (Moussaid et al.'s group terms, shared goals by the group's centre) among the pillars,
    # its size drawn per episode so worlds of one crowd size hold it at different sizes, stalls giving the whole group a goal
    ("station_hall", {"humans.groups.1.walk_together": True, "humans.groups.1.count": [2, 5], "humans.stall.time": 1.0}),
])
def test_batched_simulator_worlds_equal_single_simulators_bit_for_bit(scenario, overrides):
    stalls = check_batch_equals_singles(load_world(scenario, overrides), worlds=5, first_seed=20, steps=120, rng_seed=1, scale=1.2)
    assert stalls > 0 if overrides and "humans.stall.time" in overrides else stalls == 0  # the default window (60 s) never ends inside


def check_batch_equals_singles(world, worlds: int, first_seed: int, steps: int, rng_seed: int, scale: float) -> int:
    """Step a BatchSimulator and one Simulator per world with the same random actions: every world's state and
    events equal its single simulator's, bit for bit, across episode ends (also used by tests/core/test_orca.py).
    Returns how many stalls the episodes had."""
    stalls = 0
    batch, singles = BatchSimulator(world, worlds), [Simulator(world) for _ in range(worlds)]
    batch.reset(range(worlds), [first_seed + i for i in range(worlds)])
    for i, sim in enumerate(singles):
        sim.reset(seed=first_seed + i)
    rng = np.random.default_rng(rng_seed)
    for _ in range(steps):
        actions = rng.uniform(-scale, scale, (worlds, 2))
        result = batch.step(actions)
        for i, sim in enumerate(singles):
            events = sim.step(actions[i])
            bucket, row = batch.locate(i)
            assert bucket.state.positions[row].tobytes() == sim.positions.tobytes()
            assert bucket.state.velocities[row].tobytes() == sim.velocities.tobytes()
            assert bucket.repulsion[row].tobytes() == sim.geometry.repulsion.tobytes()
            assert bucket.state.robot_heading[row] == sim.robot_heading
            assert bucket.state.human_goals[row].tobytes() == sim.human_goals.tobytes()
            assert bucket.state.human_stall_mark[row].tobytes() == sim.state.human_stall_mark.tobytes()
            assert bucket.state.human_stalls[row].tobytes() == sim.human_stalls.tobytes()
            assert result.collisions.get(i) == events.collision and result.goal_reached[i] == events.goal_reached
            assert result.left_world[i] == events.left_world and result.truncated[i] == events.truncated
            if events.terminated or events.truncated:
                stalls += int(sim.human_stalls.sum())
                batch.reset([i], [None])
                sim.reset()
    return stalls + sum(int(sim.human_stalls.sum()) for sim in singles)


def _compare_with_sync(scenario, mode, steps, num_envs=4, seed=7, **options):
    native = gym.make_vec(f"crowdnav/{scenario}-v0", num_envs=num_envs, vectorization_mode="vector_entry_point",
                          autoreset_mode=mode, **options)
    sync = gym.make_vec(f"crowdnav/{scenario}-v0", num_envs=num_envs, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": mode}, **options)
    assert isinstance(native.unwrapped, CrowdNavVectorEnv)
    assert native.single_observation_space == sync.single_observation_space and native.observation_space == sync.observation_space
    first, second = native.reset(seed=seed), sync.reset(seed=seed)
    assert _same(first[0], second[0])
    rng, ends = np.random.default_rng(seed), 0
    for _ in range(steps):
        actions = rng.uniform(-1, 1, (num_envs, 2)).astype(np.float32)
        mine, theirs = native.step(actions), sync.step(actions)
        for a, b in zip(mine, theirs, strict=True):
            assert _same(a, b)
        ends += int((mine[2] | mine[3]).sum())
    return ends


def test_native_vector_env_equals_sync_vector_env_next_step_all_modalities():
    assert _compare_with_sync("RoomFurniture", AutoresetMode.NEXT_STEP, 150, modalities=ALL) > 0


def test_native_vector_env_equals_sync_vector_env_same_step_with_final_observations():
    assert _compare_with_sync("OpenSpace", AutoresetMode.SAME_STEP, 150, modalities=ALL, sensors={"goal": {"frame": "cartesian"}}) > 0


def test_native_vector_env_equals_sync_with_groups_and_partial_lidar():
    _compare_with_sync("StationHall", AutoresetMode.NEXT_STEP, 60, num_envs=3, modalities=["lidar", "closest_obstacle"],
                       sensors={"lidar": {"fov_deg": 180, "beams": 90}, "closest_obstacle": {"frame": "cartesian"}})


def test_disabled_autoreset_holds_ended_worlds_until_reset_mask():
    env = CrowdNavVectorEnv("open_space", 3, autoreset_mode="Disabled", modalities=["goal"])
    env.reset(seed=0)
    actions = np.tile([1.0, 0.0], (3, 1))
    for _ in range(400):
        observation, reward, terminated, truncated, _ = env.step(actions)
        if (terminated | truncated).any():
            break
    done = terminated | truncated
    held = observation["goal"].copy()
    observation, reward, terminated2, truncated2, _ = env.step(actions)
    assert np.array_equal(observation["goal"][done], held[done]) and (reward[done] == 0.0).all()
    assert np.array_equal(terminated2[done], terminated[done]) and np.array_equal(truncated2[done], truncated[done])
    env.reset(options={"reset_mask": done})
    _, _, terminated3, truncated3, _ = env.step(actions)
    assert not (terminated3 | truncated3)[done].any()


def test_vector_env_rejects_bad_actions_seeds_and_masks():
    env = CrowdNavVectorEnv("open_space", 2, modalities=["goal"])
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros((2, 2)))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        env.step(np.zeros(2))
    with pytest.raises(ValueError, match="world 1 must be finite"):
        env.step(np.array([[0.0, 0.0], [np.nan, 0.0]]))
    with pytest.raises(ValueError, match="one per world"):
        env.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="an int or a list of one per world, got True"):
        env.reset(seed=True)
    with pytest.raises(ValueError, match="reset_mask"):
        env.reset(options={"reset_mask": np.zeros(2, dtype=bool)})
    with pytest.raises(ValueError, match="autoreset_mode"):
        CrowdNavVectorEnv("open_space", 2, autoreset_mode="sometimes")


def test_held_out_episodes_batched_equal_one_env_per_seed_with_recorded_frames():
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    def policy(batch):  # deterministic, reads the observations: towards the goal, away from the nearest obstacle
        goal, obstacle = batch["goal"], batch["closest_obstacle"]
        return np.stack([goal[:, 2] - 0.3 * obstacle[:, 2] / (obstacle[:, 0] + 0.5), goal[:, 1] - 0.3 * obstacle[:, 1]], axis=1)

    episodes = HeldOutEpisodes({"scenario": "room_furniture", "modalities": ["goal", "closest_obstacle", "lidar"]}, seeds=range(100, 112))
    batched, single = episodes.run(policy, record=True), episodes.run(policy, record=True, batched=False)
    assert len({e["outcome"] for e in single}) > 1  # the check sees more than one kind of ending
    for a, b in zip(batched, single, strict=True):
        frames_a, frames_b = a.pop("frames"), b.pop("frames")
        assert a.keys() == b.keys() and all(a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]) for k in a)  # NaN: no time to goal
        assert frames_a["groups"] == frames_b["groups"]
        assert all(np.array_equal(frames_a[k], frames_b[k]) for k in ("positions", "velocities", "goals"))


def test_worlds_stepped_in_small_chunks_still_equal_sync(monkeypatch):
    import crowdnav.batch.simulator as batch_simulator

    monkeypatch.setattr(batch_simulator, "CHUNK_ELEMENTS", 200)  # two worlds per chunk in room_furniture with 5 humans
    env = CrowdNavVectorEnv("room_furniture", 5, modalities=["goal"], overrides={"humans.count": 5})
    assert env.engine.batch.chunk_size(5) == 2
    assert _compare_with_sync("RoomFurniture", AutoresetMode.NEXT_STEP, 80, num_envs=5, modalities=ALL, overrides={"humans.count": 5}) > 0
