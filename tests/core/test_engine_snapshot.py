"""World states (crowdnav.envs.engines.world_state): a world's snapshot, loaded into any world of either engine, plays on bit for bit.

For each engine and every library scenario (several robots too: stacked, crowdnav.envs.engines.stacked_team, and as
single envs; plus the tracker profiles, ORCA and reacting recorded crowds, several robots driven by ORCA, the residual
plan with the shield), a vector env plays seeded random actions, world K is
snapshot, and the env plays on, episode ends and autoresets included, recording everything observable of world K
(observation, reward, flags, infos, frame). The snapshot is then loaded into world K again, and (pickled) into world
J of fresh envs of each engine reset with other seeds, and the same actions replayed: every record must be equal bit
for bit, and a snapshot right after a load must be the state loaded. A part of a world left out of the state (a
generator, the reward's memory, a crowd model's state, the tracker's window, a Gymnasium flag) makes the loaded
worlds drift. Other tests: a snapshot as the episode ends in each autoreset mode, an env never reset taking every
world from snapshots, other robots that finished, the single env, the refusals. The last test lists every attribute
of the objects that hold a world: one added without saying whether a world state holds it fails there.
"""

from __future__ import annotations

import dataclasses
import pickle
from typing import Any

import numpy as np
import pytest

import crowdnav.envs.vector.env as vector_module
from crowdnav.envs.engines.world_state import VectorWorldState, WorldState
from crowdnav.envs.single import CrowdNavEnv
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from crowdnav.scenario.library import library_names
from tests.core.test_replay import _replay, _write

K, J, WORLDS = 1, 2, 3
WARM, AFTER = 20, 50
"""Steps before the snapshot and after it (max_steps 40: every world's episode ends after the snapshot, and the next starts)."""
MAX_STEPS = {"max_steps": 40}


ENGINES = ("stacked", "team")
STACKED = {"StackedWorlds", "StackedTeamWorlds"}
"""The stacked engine's classes: one robot per world, several (``robots:``)."""


def _cases() -> list[Any]:
    cases = []
    for name in library_names():
        cases += [pytest.param(name, {}, engine, id=f"{name}-{engine}") for engine in ENGINES]
    tracked = {"modalities": ["goal", "humans", "lidar"]}
    for profile in ("lidar_tracker", "camera_front"):
        cases += [pytest.param("room_furniture", {**tracked, "sensors": {"tracker": profile}}, engine, id=f"{profile}-{engine}")
                  for engine in ("stacked", "team")]
    cases += [pytest.param("open_space", {"overrides": {"humans.model": "orca"}}, engine, id=f"orca_crowd-{engine}")
              for engine in ("stacked", "team")]
    cases += [pytest.param("open_space", {"replay": True}, engine, id=f"replay_react-{engine}") for engine in ("stacked", "team")]
    cases.append(pytest.param("robots_crossing_hall", {"other_robots": "orca"}, "team", id="robots_orca-team"))
    planned = {"modalities": ["goal", "plan"], "residual": True, "shield": True, "overrides": {"humans.count": 4}}
    for profile in ("perfect", "camera_front"):  # the plan observed at load steers the next step (and reads the tracker's columns)
        # 10-16 s each: one (the tracker's columns, the stacked engine) stays in the default suite, the others run with -m slow
        cases += [pytest.param("room_furniture", {**planned, "sensors": {"tracker": profile}}, engine, id=f"residual_shield_{profile}-{engine}",
                               marks=() if (profile, engine) == ("camera_front", "stacked") else pytest.mark.slow)
                  for engine in ("stacked", "team")]
    return cases


def _options(options: dict[str, Any], tmp_path: Any) -> dict[str, Any]:
    options = dict(options)
    overrides = {**MAX_STEPS, **options.pop("overrides", {})}
    if overrides.get("humans.model") == "orca" or options.get("other_robots") == "orca":
        pytest.importorskip("pyrvo")
    if options.pop("replay", False):
        path = tmp_path / "walk.txt"
        _write(path)
        overrides.update(_replay(path, react_within=4.0))
    return {**options, "overrides": overrides}


def _env(name: str, options: dict[str, Any], engine: str, monkeypatch: pytest.MonkeyPatch, **extra: Any) -> CrowdNavVectorEnv:
    with monkeypatch.context() as patch:
        if engine == "team":  # one single env per world (the stacked engine's scenarios too)
            patch.setattr(vector_module, "stacks", lambda *args: False)
        env = CrowdNavVectorEnv(name, num_envs=WORLDS, **options, **extra)
    assert type(env.engine).__name__ in {"stacked": STACKED, "team": {"TeamWorlds"}}[engine]
    return env


def _world_infos(infos: dict[str, Any], world: int) -> dict[str, Any]:
    """The entries of vector ``infos`` that world ``world`` has (Gymnasium's ``_key`` masks), recursively."""
    out = {}
    for key, value in infos.items():
        mask = infos.get(f"_{key}")
        if key.startswith("_") or (mask is not None and not mask[world]):
            continue
        out[key] = _world_infos(value, world) if isinstance(value, dict) else value[world]
    return out


def _play(env: CrowdNavVectorEnv, world: int, actions: np.ndarray, resets: frozenset[int] = frozenset(), source: int = K) -> list[Any]:
    """Step ``env`` with ``actions`` (steps, worlds, 2), world ``world`` taking row ``source``'s; everything observable of ``world`` per step.

    ``resets``: steps before which ``world`` is reset by a reset mask, its generator continued (``DISABLED``).
    """
    records = []
    for step, rows in enumerate(actions):
        if step in resets:
            mask = np.zeros(WORLDS, dtype=bool)
            mask[world] = True
            obs, _ = env.reset(options={"reset_mask": mask})
            records.append(({key: values[world] for key, values in obs.items()}, env.engine.frame(world)))
        rows = rows.copy()
        rows[world] = actions[step, source]
        obs, rewards, terminated, truncated, infos = env.step(rows)
        records.append(({key: values[world] for key, values in obs.items()}, rewards[world], terminated[world], truncated[world],
                        _world_infos(infos, world), env.engine.frame(world)))
    return records


def _same(a: Any, b: Any) -> bool:
    """Equal bit for bit (NaN equal to NaN where it marks a robot that left), of the same types, recursively."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[key], b[key]) for key in a)
    if isinstance(a, (tuple, list)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        if not isinstance(b, np.ndarray) or a.dtype != b.dtype or a.shape != b.shape:
            return False
        if a.dtype == object:
            return all(_same(x, y) for x, y in zip(a.ravel(), b.ravel(), strict=True))
        return bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, (float, np.floating)) and np.isnan(a):
        return isinstance(b, (float, np.floating)) and bool(np.isnan(b))
    return type(a) is type(b) and bool(a == b)


def _assert_same(expected: list[Any], got: list[Any], what: str) -> None:
    assert len(expected) == len(got)
    for step, (a, b) in enumerate(zip(expected, got, strict=True)):
        assert _same(a, b), f"{what}: step {step} after the snapshot differs"


def _assert_round_trip(loaded: VectorWorldState, state: VectorWorldState) -> None:
    """A world's snapshot right after it loaded ``state`` is ``state`` (but the single env's part, which the stacked engine has not)."""
    a, b = dataclasses.asdict(loaded), dataclasses.asdict(state)
    if state.world.env is None or loaded.world.env is None:
        a["world"]["env"] = b["world"]["env"] = None
    assert _same(a, b), "a world snapshot right after it loaded a state differs from that state"


def _actions(seed: int, steps: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1.0, 1.0, size=(steps, WORLDS, 2))


@pytest.mark.parametrize(("name", "options", "engine"), _cases())
def test_a_loaded_world_plays_on_bit_for_bit_in_its_own_world_and_in_another_world_of_either_engine(name, options, engine, monkeypatch,
                                                                                                     tmp_path):
    options = _options(options, tmp_path)
    env = _env(name, options, engine, monkeypatch)
    env.reset(seed=7)
    _play(env, K, _actions(1, WARM))
    state = env.snapshot(K)
    frozen = pickle.dumps(state)
    actions = _actions(2, AFTER)
    played = _play(env, K, actions)
    ends = sum(bool(record[2] or record[3]) for record in played if len(record) == 6)
    assert ends >= 1, "the episode must end (and the next start) after the snapshot"
    assert pickle.dumps(state) == frozen, "a snapshot is a copy: stepping the world leaves it as it was"
    env.load(K, state)
    _assert_same(played, _play(env, K, actions), "loaded into its own world")
    # several robots driven by ORCA are single envs either way (no batched ORCA robot)
    engines = ("team",) if options.get("other_robots") == "orca" else ENGINES
    for target in engines:  # a fresh env of either engine, its worlds reset with other seeds; the pickled state into world J
        other = _env(name, options, target, monkeypatch)
        other.reset(seed=500)
        _play(other, J, _actions(3, 3))
        other.load(J, pickle.loads(frozen))
        _assert_round_trip(other.snapshot(J), state)
        _assert_same(played, _play(other, J, actions), f"loaded into world {J} of a fresh {target} env")
    assert pickle.dumps(state) == frozen, "loading copies: the worlds that loaded it leave it as it was"


def _until_ended(env: CrowdNavVectorEnv, seed: int) -> None:
    """Step ``env`` until world K's episode ends (its next step or a reset mask restarts it)."""
    rng = np.random.default_rng(seed)
    for _ in range(200):
        _, _, terminated, truncated, infos = env.step(rng.uniform(-1.0, 1.0, size=(WORLDS, 2)))
        ended = terminated[K] or truncated[K] or ("final_obs" in infos and infos["_final_obs"][K])
        if ended:
            return
    raise AssertionError("world K's episode did not end")


@pytest.mark.parametrize("engine", ["stacked", "team"])
@pytest.mark.parametrize("mode", ["NextStep", "SameStep", "Disabled"])
def test_a_world_snapshot_as_its_episode_ends_keeps_gymnasiums_flags_and_restarts_alike(mode, engine, monkeypatch):
    options = {"overrides": MAX_STEPS, "autoreset_mode": mode}
    env = _env("room_furniture", options, engine, monkeypatch)
    env.reset(seed=11)
    _until_ended(env, 4)
    state = env.snapshot(K)
    assert state.ended == (mode != "SameStep")  # SAME_STEP restarted it in the step that ended it
    actions = _actions(5, 30)
    resets = frozenset({6}) if mode == "Disabled" else frozenset()  # DISABLED: the world waits (flags repeated) until a reset mask
    played = _play(env, K, actions, resets)
    other = _env("room_furniture", options, engine, monkeypatch)
    other.reset(seed=99)
    other.load(J, state)
    _assert_same(played, _play(other, J, actions, resets), f"{mode}: loaded into world {J}")


@pytest.mark.parametrize("engine", ["stacked", "team"])
def test_an_env_never_reset_takes_every_world_from_snapshots_and_plays_on_as_the_env_they_came_from(engine, monkeypatch):
    options = {"overrides": MAX_STEPS, "sensors": {"tracker": "lidar_tracker"}, "modalities": ["goal", "humans"]}
    env = _env("hotel_lobby", options, engine, monkeypatch)
    env.reset(seed=21)
    _play(env, K, _actions(9, WARM))
    states = [pickle.loads(pickle.dumps(env.snapshot(world))) for world in range(WORLDS)]
    actions = _actions(10, 30)
    fresh = _env("hotel_lobby", options, engine, monkeypatch)
    for world, state in enumerate(states):
        fresh.load(world, state)
    for rows in actions:  # every world, every step (as a resumed training run continues)
        expected, got = env.step(rows), fresh.step(rows)
        assert _same(expected, got)


@pytest.mark.parametrize("target", ENGINES)
@pytest.mark.parametrize("engine", ENGINES)
def test_a_world_whose_other_robot_has_finished_keeps_its_outcome_and_stays_out_alike_in_either_engine(engine, target, monkeypatch):
    env = _env("robots_crossing_hall", {}, engine, monkeypatch)
    env.reset(seed=7)
    still = np.zeros((WORLDS, 2))
    for _ in range(150):  # the robots' own policies drive them; the first robot waits
        _, _, terminated, truncated, infos = env.step(still)
        outcomes = infos.get("other_robots", {})
        finished = [w for w in range(WORLDS) if not (terminated[w] or truncated[w])
                    and any(values[w] is not None for key, values in outcomes.items() if not key.startswith("_"))]
        if finished:
            break
    else:
        raise AssertionError("no other robot finished while its world ran on")
    world = finished[0]
    state = env.snapshot(world)
    actions = _actions(8, 40)
    played = _play(env, world, actions, source=world)
    other = _env("robots_crossing_hall", {}, target, monkeypatch)
    other.reset(seed=1)
    target = (world + 1) % WORLDS
    other.load(target, state)
    _assert_same(played, _play(other, target, actions, source=world), "a world of several robots")


def test_the_single_env_snapshots_and_loads_its_world_and_a_vector_env_world_loads_it():
    env = CrowdNavEnv("cafe", overrides=MAX_STEPS)
    env.reset(seed=3)
    for action in _actions(6, 10)[:, 0]:
        env.step(action)
    state = env.snapshot()
    actions = _actions(7, 30)[:, 0]

    def play(env: CrowdNavEnv) -> list[Any]:
        out = []
        for action in actions:
            out.append(env.step(action))
            if out[-1][2] or out[-1][3]:
                out.append(env.reset())
        return out

    played = play(env)
    assert _same(env.load(state), state.env.observation)
    assert _same(play(env), played)
    vector = CrowdNavVectorEnv("cafe", num_envs=WORLDS, overrides=MAX_STEPS)
    vector.reset(seed=0)
    vector.load(J, VectorWorldState(state, ended=False, terminated=False, truncated=False))
    rows = np.zeros((1, WORLDS, 2))
    rows[0, J] = actions[0]
    obs, reward, *_ = vector.step(rows[0])
    assert reward[J] == played[0][1] and all(np.array_equal(obs[key][J], played[0][0][key]) for key in obs)
    while True:  # to the episode's end: an ended episode refuses a step, loaded too
        _, _, terminated, truncated, _ = env.step(actions[0])
        if terminated or truncated:
            break
    ended = env.snapshot()
    fresh = CrowdNavEnv("cafe", overrides=MAX_STEPS)
    fresh.load(ended)
    with pytest.raises(RuntimeError, match="the episode is over"):
        fresh.step(actions[0])


@pytest.fixture
def state() -> WorldState:
    env = CrowdNavVectorEnv("room_furniture", num_envs=WORLDS)
    env.reset(seed=1)
    env.step(np.zeros((WORLDS, 2)))
    return env.snapshot(K).world


def _refusal(env: CrowdNavVectorEnv, state: Any) -> str:
    with pytest.raises(ValueError) as error:
        env.engine.load(J, state)
    message = str(error.value)
    assert "\n" not in message
    return message


def test_a_state_loads_only_where_scenario_settings_robots_and_version_match_and_the_refusal_names_what_differs(state):
    open_space = CrowdNavVectorEnv("open_space", num_envs=WORLDS)
    assert _refusal(open_space, state) == "a world state of scenario 'room_furniture' cannot load into a world of scenario 'open_space'"
    crowd = CrowdNavVectorEnv("room_furniture", num_envs=WORLDS, overrides={"humans.count": 3}, sensors={"lidar": {"beams": 90}})
    assert _refusal(crowd, state) == "a world state of scenario 'room_furniture' with other settings cannot load: humans, sensors differ"
    robots = CrowdNavVectorEnv("robots_crossing_hall", num_envs=WORLDS)
    assert _refusal(robots, state).startswith("a world state of 1 robot(s) cannot load into a world of 3 (scenario 'robots_crossing_hall')")
    same = CrowdNavVectorEnv("room_furniture", num_envs=WORLDS)
    assert _refusal(same, dataclasses.replace(state, version=0)) == ("a world state of version 0 cannot load: this crowdnav's world "
                                                                     "states are version 1")
    assert "expected a WorldState" in _refusal(same, {"episode": None})
    with pytest.raises(ValueError, match=r"^expected a VectorWorldState \(CrowdNavVectorEnv.snapshot\), got WorldState$"):
        same.load(J, state)
    with pytest.raises(ValueError, match=r"^world must be an integer in \[0, 3\), got 3$"):
        same.load(3, VectorWorldState(state, False, False, False))
    with pytest.raises(RuntimeError, match="has not been reset"):
        same.snapshot(0)
    single = CrowdNavEnv("open_space")
    with pytest.raises(ValueError, match="^a world state of scenario 'room_furniture' cannot load"):
        single.load(state)


def test_a_world_state_pickles_and_holds_plain_data(state):
    again = pickle.loads(pickle.dumps(state))
    assert isinstance(again, WorldState) and _same(vars(again.episode.state), vars(state.episode.state))
    assert again.episode.rng == state.episode.rng and again.rewards == state.rewards
    with pytest.raises(dataclasses.FrozenInstanceError):
        state.rewards = ()  # type: ignore[misc]


NOT_STATE = "not state"
"""An attribute a world state need not hold: a setting of the scenario or env, a constant, or what a step makes anew before anyone reads it."""
ATTRIBUTES: dict[str, dict[str, str]] = {
    "StackedWorlds": {"_previous_distance": "rewards", "tracker": "tracker", "batch": "episode",
                      **dict.fromkeys(["_tracked", "_weights", "modalities", "num_worlds", "world_key"], NOT_STATE)},
    "BatchSimulator": {"buckets": "episode.state (a row; the geometry is measured again)", "slots": "episode (generator, crowd models)",
                       "_where": "episode.state's crowd size (load moves the row)",
                       "team": "episode.team (a world's row)",
                       **dict.fromkeys(["_bounds", "_crowd", "_crowds", "_labels", "_polygons", "_static_count", "_substep_dt", "_substeps",
                                        "_surface", "dt", "num_worlds", "scenario", "world"], NOT_STATE)},
    "StackedTeamWorlds": {"_previous_distance": "rewards", "_other_distance": "rewards", "tracker": "tracker", "batch": "episode",
                          "team": "episode.team", "_outcomes": "env.other_outcomes", "_loaded": "env.observation",
                          "_leaving": "episode.team (the robots that ended are out of the world in a snapshot)",
                          **dict.fromkeys(["_policy", "_sees_robots", "_tracked", "_weights", "modalities", "num_worlds", "world_key"], NOT_STATE)},
    "TeamStack": {**dict.fromkeys(["positions", "velocities", "goals", "headings", "active", "left_at"], "episode.team"),
                  **dict.fromkeys(["social", "static_offset", "static_distance", "pair_distance", "_agent_distance"],
                                  "measured again from the positions"),
                  **dict.fromkeys(["ended", "outcome", "collisions"], "made by each step before anyone reads them"),
                  **dict.fromkeys(["_bounds", "_labels", "_surface", "force", "names", "specs", "static_count", "surface_radius", "team", "team_dt"],
                                  NOT_STATE)},
    "Simulator": {"_state": "episode.state", "_rng": "episode.rng", "team": "episode.team", "crowd": "episode.crowd",
                  "geometry": "measured again from the positions", "radii": "the crowd size's constants",
                  "robot_events": "made by each step before anyone reads them", "_ready": "set by load",
                  **dict.fromkeys(["_constants", "_force", "_robot_scenarios", "bounds", "dt", "groups", "max_humans", "obstacles", "placement",
                                   "relaxation", "router", "rules_every_step", "rules_when_stopped", "scenario", "stall_window", "substep_dt",
                                   "substeps", "together", "world"], NOT_STATE)},
    "PeopleTracker": {**dict.fromkeys(["_alive", "_columns", "_confirmed", "_entropy", "_episode", "_fresh", "_hits", "_key", "_last_seen",
                                       "_latest", "_measured", "_measured_at", "_moments", "_position", "_robot", "_step", "_sums",
                                       "_velocity"], "tracker"),
                      **dict.fromkeys(["_all", "dt", "full_circle", "half_fov", "num_worlds", "sight", "values"], NOT_STATE)},
    "TeamWorlds": {"envs": "every part", "observations": "env.observation",
                   **dict.fromkeys(["_other_robots", "outcomes", "rewards", "terms"], "made by each step before anyone reads them"),
                   **dict.fromkeys(["modalities", "num_worlds", "plain", "team"], NOT_STATE)},
    "CrowdNavEnv": {"core": "every part", "simulator": "episode", "_other_outcomes": "env.other_outcomes", "_np_random": "episode.rng",
                    **dict.fromkeys(["_np_random_seed", "_other_names", "_other_policies", "action_space", "metadata", "observation_space",
                                     "render_mode", "scenario"], NOT_STATE)},
    "EnvCore": {"simulator": "episode", "reward": "rewards", "robot_rewards": "rewards", "tracker": "tracker", "_running": "env.running",
                "_observation": "env.observation", "shielded": "made by each step before anyone reads it",
                "view": NOT_STATE + " (rendering draws the world, never changes it)",
                **dict.fromkeys(["_reads_tracker", "_robot_sensors", "_sensors", "action_space", "modalities", "observation_space", "plain",
                                 "render_mode", "residual", "robot_names", "robot_spaces", "scenario", "shield", "world_key"], NOT_STATE)},
    "Reward": {"_previous_distance": "rewards", "_weights": NOT_STATE, "weights": NOT_STATE},
    "ReplayModel": {"start": "episode.crowd", "reacting": "episode.crowd", "_moving": "episode.crowd",
                    **dict.fromkeys(["_positions", "_velocities", "_targets", "_holder"], "laid out again from the window's start"),
                    **dict.fromkeys(["_ahead", "_clearance", "_grid", "_group", "_offset", "_reaction", "_steps", "_track_first", "_track_length",
                                     "_track_points", "_track_start", "count", "dt", "react_within", "world"], NOT_STATE)},
    "CrowdNavVectorEnv": {"engine": "world", "_ended": "ended", "_last_flags": "terminated, truncated", "_started": "set by load",
                          **dict.fromkeys(["_all_started", "_none_ended", "_observations"], "made again by load"),
                          **dict.fromkeys(["_np_random", "_np_random_seed", "_single_worlds", "action_space", "autoreset_mode", "episode_seeds",
                                           "metadata", "modalities", "num_envs", "observation_space", "residual", "scenario", "shield",
                                           "single_action_space", "single_observation_space"], NOT_STATE + " of a world")},
}


def test_every_attribute_of_what_holds_a_world_is_in_a_world_state_or_said_not_to_be(monkeypatch, tmp_path):
    options = _options({"replay": True, "sensors": {"tracker": "lidar_tracker"}, "modalities": ["goal", "humans"]}, tmp_path)
    held: list[Any] = []
    for engine in ("stacked", "team"):
        env = _env("open_space", options, engine, monkeypatch)
        env.reset(seed=0)
        env.step(np.zeros((WORLDS, 2)))
        env.snapshot(K)
        held.append(env)
        if engine == "stacked":
            held += [env.engine, env.engine.batch, env.engine.batch.slots[K], env.engine.tracker]
            held.append(env.engine.batch.slots[K].crowd.models["replay"])
        else:
            single = env.engine.envs[K]
            held += [env.engine, single, single.core, single.core.reward, single.simulator]
    robots = _env("robots_crossing_hall", {"overrides": MAX_STEPS}, "stacked", monkeypatch)
    robots.reset(seed=0)
    robots.step(np.zeros((WORLDS, 2)))
    robots.snapshot(K)
    held += [robots.engine, robots.engine.batch, robots.engine.team, robots.engine.batch.slots[K]]
    for thing in held:
        declared = ATTRIBUTES[type(thing).__name__]
        unknown = sorted(set(vars(thing)) - set(declared))
        assert unknown == [], f"{type(thing).__name__}: say whether a world state holds {unknown} (tests/core/test_engine_snapshot.py)"
