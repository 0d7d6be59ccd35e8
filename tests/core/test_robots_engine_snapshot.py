"""World states of the robots-only engines (crowdnav.envs.engines.robots_state): both engines take the same state of the same
world, bit for bit, and a world's state loaded into a world of either engine (its own world again, another world of a
fresh engine reset with other seeds) plays on bit for bit: observations, rewards and terms, outcomes and contacts, the
time limit, partial steps, the next episodes. Snapshots fall where a robot ended at the last step and its world goes
on (out of the world in the state, still in the stored observation) and where the first robot has left. A single or
vector env's state, or another scenario's, is refused in one line; every attribute of the engines is in a state or
said not to be."""

from __future__ import annotations

import pickle
from typing import Any

import numpy as np
import pytest

from crowdnav.envs.engines.robots import SingleRobots, robots_engine
from crowdnav.envs.engines.stacked_robots import StackedRobots
from crowdnav.envs.engines.world_state import VectorWorldState, WorldState
from crowdnav.envs.engines.world_state_codec import to_arrays
from crowdnav.envs.reward import REWARD_TERMS
from crowdnav.envs.single import CrowdNavEnv

HALL = "robots_crossing_hall"
OPTIONS = {"scenario": HALL, "overrides": {"max_steps": 60, "world.boundary_walls": False}, "sensors": {"lidar": {"beams": 16}},
           "modalities": ["goal", "lidar", "velocity", "humans"]}
"""No walls: a robot may leave the world; ``humans`` sees no robots (a view of the humans alone)."""
WORLDS, K, J = 3, 1, 2
ENGINES = ("stacked", "single")


def _engine(kind: str, worlds: int = WORLDS) -> Any:
    engine = robots_engine(OPTIONS, worlds) if kind == "stacked" else SingleRobots(OPTIONS, worlds)
    assert isinstance(engine, StackedRobots if kind == "stacked" else SingleRobots)
    return engine


def _arrays(state: WorldState) -> dict[str, bytes]:
    """A state as its stored arrays and description (:mod:`crowdnav.envs.engines.world_state_codec`), each as bytes: equal states, equal bits."""
    return {key: values.tobytes() for key, values in to_arrays([VectorWorldState(state, False, False, False)]).items()}


def _actions(rng: np.random.Generator) -> np.ndarray:
    actions = rng.normal([0.9, 0.0], 0.5, (WORLDS, 3, 2))
    actions[:, 0] = rng.normal([1.0, 0.0], 0.1, (WORLDS, 2))  # the first robot ahead: it often ends first
    return actions


def _record(engine: Any, world: int, actions: np.ndarray, active: np.ndarray | None) -> tuple:
    """One step of ``engine`` and world ``world``'s part of it (then its episode's end resets it, its generator going on)."""
    seen = engine.observe()[world].tobytes()
    step = engine.step(actions, active)
    none = np.zeros(step.rewards.shape)  # (one engine lists no terms in a step no world's robot took)
    terms = {term: step.terms.get(term, none)[world].tobytes() for term in REWARD_TERMS}
    contacts = {robot: contact for (w, robot), contact in step.collisions.items() if w == world}
    record = (seen, step.stepped[world].tobytes(), step.rewards[world].tobytes(), terms, step.outcome[world].tolist(), contacts,
              bool(step.truncated[world]), bool(step.over[world]))
    over = np.flatnonzero(step.over)
    engine.reset(over, [None] * len(over))
    return record


def test_both_engines_take_the_same_state_of_the_same_world_bit_for_bit():
    stacked, single = _engine("stacked"), _engine("single")
    seeds = [40 + i for i in range(WORLDS)]
    stacked.reset(range(WORLDS), seeds)
    single.reset(range(WORLDS), seeds)
    rng = np.random.default_rng(4)
    leaving = first_left = 0
    for t in range(120):
        for world in range(WORLDS):
            assert _arrays(stacked.snapshot(world)) == _arrays(single.snapshot(world)), (t, world)
        actions, active = _actions(rng), None if t % 3 else rng.random(WORLDS) < 0.6
        step = stacked.step(actions, active)
        single.step(actions, active)
        assert stacked.observe().tobytes() == single.observe().tobytes()
        leaving += int((step.stepped & (step.outcome != None) & ~step.over[:, None]).sum())  # noqa: E711  (entry by entry)
        first_left += int((~stacked.team.active[:, 0]).sum())
        over = np.flatnonzero(step.over)
        for world in over:  # as the episode ended, before the reset
            assert _arrays(stacked.snapshot(world)) == _arrays(single.snapshot(world)) and not stacked.snapshot(world).env.running
        stacked.reset(over, [None] * len(over))
        single.reset(over, [None] * len(over))
    assert leaving > 0 and first_left > 0  # robots out of the world in the states, the first one too


@pytest.mark.parametrize("engine", ENGINES)
def test_a_loaded_world_plays_on_bit_for_bit_in_its_own_world_and_in_another_world_of_either_engine(engine):
    source = _engine(engine)
    source.reset(range(WORLDS), [7, 8, 9])
    rng = np.random.default_rng(1)
    for t in range(400):  # to a step where a robot of world K ended and its world goes on: the state's hardest moment
        step = source.step(_actions(rng), None)
        over = np.flatnonzero(step.over)
        source.reset(over, [None] * len(over))
        if t > 10 and not step.over[K] and (step.stepped[K] & (step.outcome[K] != None)).any():  # noqa: E711
            break
    else:
        pytest.fail("no robot of world K ended while its world went on")
    snapshot = pickle.loads(pickle.dumps(source.snapshot(K)))
    played = [(_actions(rng), None if t % 4 else rng.random(WORLDS) < 0.7) for t in range(70)]  # episodes end and restart
    expected = [_record(source, K, actions, active) for actions, active in played]
    targets = [("own world", source, K)] + [(f"fresh {kind}", _engine(kind), J) for kind in ENGINES]
    for name, target, world in targets:
        if target is not source:
            target.reset(range(WORLDS), [100, 101, 102])  # other episodes everywhere
        target.load(world, snapshot)
        assert _arrays(target.snapshot(world)) == _arrays(snapshot), name  # what it loaded, as it loaded it
        got = []
        for actions, active in played:
            moved = _actions(rng)
            moved[world] = actions[K]
            mask = None if active is None else np.where(np.arange(WORLDS) == world, active[K], rng.random(WORLDS) < 0.5)
            got.append(_record(target, world, moved, mask))
        for t, (mine, theirs) in enumerate(zip(got, expected, strict=True)):
            assert mine == theirs, (name, t)
    assert any(record[-1] for record in expected)  # the episode ended and the next one played on


@pytest.mark.parametrize("engine", ENGINES)
def test_a_state_that_is_not_a_robots_engines_is_refused_in_one_line(engine):
    target = _engine(engine)
    target.reset(range(WORLDS), [0, 1, 2])
    single = CrowdNavEnv(HALL, **{key: value for key, value in OPTIONS.items() if key != "scenario"})
    single.reset(seed=0)
    other = SingleRobots({**OPTIONS, "overrides": {"max_steps": 61, "world.boundary_walls": False}}, 1)
    other.reset([0], [0])
    for state, message in [(single.snapshot(), "without every robot's flat observation"), (other.snapshot(0), "other settings"),
                           ("a state", "expected a WorldState")]:
        with pytest.raises(ValueError, match=message) as error:
            target.load(0, state)
        assert "\n" not in str(error.value)


NOT_STATE = "not state"
ATTRIBUTES: dict[str, dict[str, str]] = {
    "StackedRobots": {"batch": "episode", "team": "episode.team", "_previous": "rewards", "_over": "env.running",
                      "_leaving": "episode (the robots that ended are out of the world in a state)",
                      "_loaded": "env.observation (observed until the world steps)", "_stored": "env.observation",
                      "_observed": "env.observation (made again by load)",
                      **dict.fromkeys(["num_worlds", "robot_names", "sensors", "observation_size", "_weights", "world_key"], NOT_STATE)},
    "SingleRobots": {"envs": "every part", "_observations": "env.observation",
                     **dict.fromkeys(["num_worlds", "robot_names", "observation_size"], NOT_STATE)},
    "CrowdNavParallelEnv": {"core": "every part (crowdnav.envs.core.EnvCore, tests/core/test_engine_snapshot.py)", "simulator": "episode",
                            "agents": "env.running", "_active_robots": "episode.team.active",
                            **dict.fromkeys(["_active_humans", "_group_of", "_humans"], NOT_STATE + " (no humans as agents)"),
                            **dict.fromkeys(["flat_observations", "fixed_agents", "humans_as_agents", "human_reward", "human_exit",
                                             "render_mode", "scenario", "metadata", "_human_names", "_robot_names", "_several",
                                             "possible_agents", "_dict_spaces", "observation_spaces", "state_space", "action_spaces"],
                                            NOT_STATE)},
}


def test_every_attribute_of_the_robots_engines_is_in_a_world_state_or_said_not_to_be():
    held = []
    for kind in ENGINES:
        engine = _engine(kind, 1)
        engine.reset([0], [0])
        engine.step(np.zeros((1, 3, 2)))
        engine.snapshot(0)
        held += [engine, *getattr(engine, "envs", [])]
    for thing in held:
        unknown = sorted(set(vars(thing)) - set(ATTRIBUTES[type(thing).__name__]))
        assert unknown == [], f"{type(thing).__name__}: say whether a world state holds {unknown} (tests/core/test_robots_engine_snapshot.py)"


def test_the_parallel_envs_loaded_robots_refuses_an_env_that_is_not_a_robots_engines():
    from crowdnav.envs.parallel import CrowdNavParallelEnv

    for env in (CrowdNavParallelEnv("open_space"), CrowdNavParallelEnv("robots_crossing_hall")):  # one robot; humans as agents
        with pytest.raises(ValueError, match="loaded_robots: a robots: scenario's env whose humans are not agents") as caught:
            env.loaded_robots(True)
        assert "\n" not in str(caught.value)
        env.close()
