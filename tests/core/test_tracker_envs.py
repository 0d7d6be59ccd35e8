"""The people tracker in the envs: the default leaves every episode and observation as it was (digests), every profile
plays the same in the single and the native vector env bit for bit, the crowd never notices the tracker, and every
reader of one robot's tracker (observation, plan, shield, ``baseline:onboard``) sees the same tracks."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from crowdnav import Simulator
from crowdnav.envs import CrowdNavEnv
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.planning.onboard import OnboardPlanner
from crowdnav.sensors.tracked import sensed_people
from tests.core.test_vector_env import _compare_with_sync

PROFILES = ["perfect", "lidar_tracker", "camera_front"]
READERS = ["humans", "goal", "velocity", "plan"]


def single_digest(scenario: str, overrides: dict, modalities: list[str], seed: int, steps: int = 60, shield: bool = False) -> str:
    """A hash of one env's observations, positions and rewards over ``steps`` random actions (resetting without a seed)."""
    env = CrowdNavEnv(scenario, modalities=modalities, overrides=overrides, shield=shield)
    observation, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed + 7)
    digest = hashlib.sha256()
    for _ in range(steps):
        for key in sorted(observation):
            digest.update(observation[key].tobytes())
        digest.update(env.simulator.positions.tobytes())
        observation, reward, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
        digest.update(np.float64(reward).tobytes())
        if terminated or truncated:
            observation, _ = env.reset()
    return digest.hexdigest()[:16]


def vector_digest(scenario: str, overrides: dict, modalities: list[str], seed: int, steps: int = 40) -> str:
    env = CrowdNavVectorEnv(scenario, num_envs=6, modalities=modalities, overrides=overrides)
    observation, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed + 7)
    digest = hashlib.sha256()
    for _ in range(steps):
        for key in sorted(observation):
            digest.update(observation[key].tobytes())
        observation, rewards, *_ = env.step(rng.uniform(-1, 1, (6, 2)).astype(np.float32))
        digest.update(rewards.tobytes())
    return digest.hexdigest()[:16]


# (scenario, overrides, seed, single env, single env with the shield (closest_obstacle goal plan), vector env): recorded at
# the commit before the tracker (e20ece6) with these functions
DIGESTS_BEFORE_THE_TRACKER = [
    ("room_furniture", {"humans.count": 10}, 3, "25ab06f49157cf5a", "d24b77ea1a9f9cce", "fdbaf1fea3bd9374"),
    ("circle_crossing", {}, 11, "5a046204858c86d3", "be8edebc7d82e0a4", "819e865c9caefb1a"),
]


@pytest.mark.parametrize(("scenario", "overrides", "seed", "single", "shielded", "vector"), DIGESTS_BEFORE_THE_TRACKER)
def test_the_default_perfect_profile_leaves_every_episode_and_observation_bit_for_bit(scenario, overrides, seed, single, shielded, vector):
    modalities = READERS if scenario == "room_furniture" else ["humans", "goal", "velocity"]
    for given in (overrides, {**overrides, "sensors.tracker": "perfect"}):
        assert single_digest(scenario, given, modalities, seed) == single
        assert single_digest(scenario, given, ["closest_obstacle", "goal", "plan"], seed, shield=True) == shielded
        assert vector_digest(scenario, given, modalities, seed) == vector


@pytest.mark.parametrize(("profile", "mode"), [
    *[(profile, AutoresetMode.NEXT_STEP) for profile in PROFILES],
    (PROFILES[1], AutoresetMode.SAME_STEP),  # the other profiles' same-step cases: 2-3 s each, marked slow
    *[pytest.param(profile, AutoresetMode.SAME_STEP, marks=pytest.mark.slow) for profile in (PROFILES[0], PROFILES[2])],
])
def test_single_and_native_vector_envs_are_equal_bit_for_bit_with_each_profile(profile, mode):
    overrides = {"humans.count": 8, "sensors.tracker": profile}
    ends = _compare_with_sync("RoomFurniture", mode, 60, num_envs=5, seed=3, modalities=READERS + ["lidar"], overrides=overrides)
    assert ends > 0  # autoresets (seedless episodes) were played


@pytest.mark.parametrize("profile", PROFILES[1:])
def test_the_shielded_and_residual_envs_and_one_world_are_equal_bit_for_bit_with_a_tracker(profile):
    overrides = {"humans.count": [4, 8], "sensors.tracker": profile}  # crowd sizes vary: several buckets
    _compare_with_sync("RoomFurniture", AutoresetMode.NEXT_STEP, 40, num_envs=4, seed=5, modalities=READERS,
                       overrides=overrides, shield=True, residual=True)
    _compare_with_sync("CircleCrossing", AutoresetMode.NEXT_STEP, 30, num_envs=1, seed=5, modalities=READERS,
                       overrides={"sensors.tracker": profile})  # one world: held as a single env (TeamWorlds)


def test_the_tracker_never_changes_the_crowds_episode():
    def positions(profile: str) -> bytes:
        env = CrowdNavEnv("room_furniture", modalities=["humans"], overrides={"humans.count": 10, "sensors.tracker": profile})
        env.reset(seed=4)
        rng, out = np.random.default_rng(0), []
        for _ in range(50):
            _, _, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 2))
            out.append(env.simulator.positions.tobytes())
            if terminated or truncated:
                env.reset()
        return b"".join(out)

    assert positions("lidar_tracker") == positions("perfect") == positions("camera_front")


def test_the_tracker_reports_what_it_sees_not_the_truth():
    def humans(profile: str) -> np.ndarray:
        env = CrowdNavEnv("room_furniture", modalities=["humans"], overrides={"humans.count": 10, "sensors.tracker": profile})
        observations = [env.reset(seed=2)[0]["humans"]]
        for _ in range(10):
            observations.append(env.step(np.zeros(2))[0]["humans"])
        return np.array(observations)

    perfect, camera = humans("perfect"), humans("camera_front")
    assert camera[..., 5].sum() < perfect[..., 5].sum()  # a 69-degree camera sees fewer people
    assert not np.array_equal(humans("lidar_tracker"), perfect)


def test_onboard_planner_reads_the_envs_tracks_in_the_single_and_the_vector_env():
    options = {"modalities": ["plan", "humans"], "overrides": {"humans.count": 8, "sensors.tracker": "lidar_tracker"}}
    env, planner = CrowdNavEnv("room_furniture", **options), OnboardPlanner()
    observation, _ = env.reset(seed=1)
    for _ in range(8):
        np.testing.assert_array_equal(planner(env.simulator), observation["plan"])
        observation, *_ = env.step(observation["plan"])
    vector = CrowdNavVectorEnv("room_furniture", num_envs=3, **options)
    observations, _ = vector.reset(seed=1)
    for _ in range(4):
        for i in range(3):
            np.testing.assert_array_equal(planner(vector.simulator(i)), observations["plan"][i])
        observations, *_ = vector.step(observations["plan"])


def test_a_bare_simulator_with_a_tracker_profile_is_refused_in_one_line():
    sim = Simulator("room_furniture", {"sensors.tracker": "lidar_tracker"})
    sim.reset(seed=0)
    with pytest.raises(ValueError, match="people tracker's state lives in the env"):
        sensed_people(sim)
    plain = Simulator("room_furniture")
    plain.reset(seed=0)
    assert sensed_people(plain) is plain


def test_rendering_shows_the_tracks_and_the_field_of_view_beside_the_true_crowd_only_with_a_tracker():
    def frame(profile: str, **options) -> np.ndarray:
        env = CrowdNavEnv("room_furniture", modalities=["humans"], overrides={"humans.count": 10, "sensors.tracker": profile},
                          render_mode="rgb_array", render_options=options or None)
        env.reset(seed=3)
        for _ in range(3):
            env.step(np.array([0.5, 0.0]))
        out = env.render()
        assert out is not None
        return out

    plain = frame("perfect")
    np.testing.assert_array_equal(frame("camera_front", tracks=False), plain)  # the overlay is the only difference
    assert (frame("camera_front") != plain).any()
