"""docs/architecture.md's recipe "Adding a backend", followed: a backend of its own, given to the vector env through its
``engine`` option, plays the worlds the default engine plays, bit for bit, and loads their states, both ways.

The backend is thin on purpose: it keeps world ``i`` in world ``K - 1 - i`` of another engine and maps every world
index and per-world row of the protocol. A method the vector env reads besides the protocol (it has no other), or one
that mapped a world wrongly, shows as a difference from the default engine.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pytest

import tests.core.test_engine_protocol as protocol_tests
from crowdnav.batch.robot_policies import social_force_robots
from crowdnav.batch.simulator import StepResult
from crowdnav.envs.engines.per_world import TeamWorlds
from crowdnav.envs.engines.protocol import Judged, WorldEngine
from crowdnav.envs.engines.stacked import StackedWorlds
from crowdnav.envs.engines.stacked_team import StackedTeamWorlds, first_robot_modalities
from crowdnav.envs.engines.world_state import WorldState
from crowdnav.envs.vector.env import CrowdNavVectorEnv
from tests.core.test_engine_snapshot import _same

WORLDS = 3


class ReversedWorlds:
    """A :class:`crowdnav.envs.engines.protocol.WorldEngine`: world ``i`` is world ``K - 1 - i`` of ``inner``."""

    def __init__(self, inner: WorldEngine):
        self.inner, self.num_worlds, self.modalities = inner, inner.num_worlds, inner.modalities

    def _slot(self, world: int) -> int:
        return self.num_worlds - 1 - int(world)

    @staticmethod
    def _flip(rows: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(rows[::-1])

    def _result(self, result: StepResult) -> StepResult:
        """A step's result seen from the other side (its own inverse); collisions in world order."""
        return StepResult(self._flip(result.goal_reached), self._flip(result.left_world), self._flip(result.truncated),
                          {self._slot(world): contact for world, contact in sorted(result.collisions.items(), reverse=True)})

    def reset(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None] | np.ndarray) -> None:
        slots = np.array([self._slot(world) for world in worlds], dtype=np.int64)
        order = np.argsort(slots)  # the inner engine's worlds in ascending order, each with its own seed
        self.inner.reset(slots[order], [seeds[k] for k in order])

    def step(self, actions: np.ndarray, active: np.ndarray | None = None) -> StepResult:
        return self._result(self.inner.step(self._flip(actions), None if active is None else self._flip(active)))

    def judged(self, result: StepResult, stepping: np.ndarray, every: bool) -> Judged:
        outcome, rewards, terms = self.inner.judged(self._result(result), self._flip(stepping), every)
        # a term holds the stepping worlds' values in world order: the inner engine's order reversed
        return self._flip(outcome), self._flip(rewards), {term: self._flip(values) for term, values in terms.items()}

    def settle(self) -> None:
        self.inner.settle()

    def observe(self, out: Mapping[str, np.ndarray]) -> None:
        inner = {key: np.empty_like(values) for key, values in out.items()}
        self.inner.observe(inner)
        for key, values in out.items():
            values[...] = inner[key][::-1]

    def shielded(self, shield: Any, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out, replaced = self.inner.shielded(shield, self._flip(actions))
        return self._flip(out), self._flip(replaced)

    def stalls(self) -> np.ndarray:
        return self._flip(self.inner.stalls())

    def other_robots(self, stepping: np.ndarray) -> dict[int, dict[str, str | None]]:
        robots = self.inner.other_robots(self._flip(stepping))
        return {self._slot(world): robots[world] for world in sorted(robots, reverse=True)}

    def social_force(self) -> np.ndarray:
        return self._flip(self.inner.social_force())

    def row(self, name: str, world: int) -> np.ndarray:
        return self.inner.row(name, self._slot(world))

    def robot_goal(self, world: int) -> complex:
        return self.inner.robot_goal(self._slot(world))

    def frame(self, world: int) -> dict[str, np.ndarray]:
        return self.inner.frame(self._slot(world))

    def simulator(self, world: int) -> Any:
        return self.inner.simulator(self._slot(world))

    def simulators(self) -> list[Any]:
        return self.inner.simulators()[::-1]

    def snapshot(self, world: int) -> WorldState:
        return self.inner.snapshot(self._slot(world))

    def load(self, world: int, state: WorldState) -> None:
        self.inner.load(self._slot(world), state)


INNER = {
    "stacked": lambda world, count, modalities: StackedWorlds(world, count, modalities),
    "team": lambda world, count, modalities: TeamWorlds(world, count),
    "stacked_team": lambda world, count, modalities: StackedTeamWorlds(world, count, first_robot_modalities(world), social_force_robots),
}
CASES = [  # (scenario, options, inner engine, an info the case reaches): the shield and the same-step autoreset; single
    # envs inside, collisions; several robots
    pytest.param("room_furniture", {"shield": True, "autoreset_mode": "SameStep"}, "stacked", "shielded", id="stacked-shield-same_step"),
    pytest.param("room_furniture", {}, "team", "collision_kind", id="team"),
    pytest.param("robots_crossing_hall", {}, "stacked_team", "other_robots", id="robots-stacked_team"),
]
MODALITIES = {"room_furniture": ["goal", "lidar", "humans", "velocity", "closest_obstacle"],
              "robots_crossing_hall": ["goal", "lidar", "velocity", "closest_obstacle"]}


def make(scenario: str, options: dict[str, Any], inner: str | None) -> CrowdNavVectorEnv:
    """The vector env with the default engine (``inner`` None) or with the backend over the ``inner`` engine."""
    engine = None if inner is None else (lambda world, count, modalities: ReversedWorlds(INNER[inner](world, count, modalities)))
    return CrowdNavVectorEnv(scenario, num_envs=WORLDS, modalities=MODALITIES[scenario], overrides={"humans.count": 4, "max_steps": 20},
                             engine=engine, **options)


def played(env: CrowdNavVectorEnv, steps: int, rng: np.random.Generator) -> list[Any]:
    """Everything observable, step by step, under seeded random actions (the same ``rng`` state gives the same actions)."""
    records = []
    for _ in range(steps):
        observation, rewards, terminated, truncated, infos = env.step(rng.uniform(-1, 1, size=(WORLDS, 2)))
        records.append((observation, rewards, terminated, truncated, infos, [env.engine.frame(world) for world in range(WORLDS)],
                        [env.simulator(world).positions for world in range(WORLDS)]))
    return records


def assert_same(expected: list[Any], got: list[Any]) -> None:
    assert len(expected) == len(got)
    for step, (a, b) in enumerate(zip(expected, got, strict=True)):
        assert _same(a, b), f"step {step} differs"


def test_the_backend_has_every_method_of_the_protocol_with_its_parameters() -> None:
    protocol_tests.test_each_engine_has_every_method_of_the_protocol_with_its_parameters(ReversedWorlds)


@pytest.mark.parametrize(("scenario", "options", "inner", "info"), CASES)
def test_a_backend_given_to_the_vector_env_plays_its_worlds_as_the_default_engine_bit_for_bit(scenario, options, inner, info) -> None:
    default, ours = make(scenario, options, None), make(scenario, options, inner)
    assert isinstance(ours.engine, ReversedWorlds) and not isinstance(default.engine, ReversedWorlds)
    first = [env.reset(seed=[7, 8, 9]) for env in (default, ours)]
    assert _same(first[0], first[1])
    expected, got = played(default, 60, np.random.default_rng(0)), played(ours, 60, np.random.default_rng(0))
    assert np.all(np.any([record[2] | record[3] for record in expected], axis=0))  # every world ended an episode and went on
    assert any(info in record[4] for record in expected)  # the protocol's methods behind that info were called
    assert_same(expected, got)


@pytest.mark.parametrize(("scenario", "options", "inner", "info"), CASES)
def test_world_states_load_between_the_backend_and_the_default_engine_both_ways(scenario, options, inner, info) -> None:
    default, ours = make(scenario, options, None), make(scenario, options, inner)
    now = {}
    for env in (default, ours):
        env.reset(seed=[7, 8, 9])
        now[id(env)] = played(env, 12, np.random.default_rng(1))[-1][0]  # mid-episode: the last observation
    for source, target in ((default, make(scenario, options, inner)), (ours, make(scenario, options, None))):
        target.reset(seed=[1, 2, 3])  # other episodes, then every world loaded from the source
        assert _same(target.load_worlds([source.snapshot(world) for world in range(WORLDS)]), now[id(source)])
        assert_same(played(source, 30, np.random.default_rng(2)), played(target, 30, np.random.default_rng(2)))
