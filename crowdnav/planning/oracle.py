"""The ceiling of a scenario: a planner that knows the humans' whole future (``baseline:oracle``).

Privileged beyond every other baseline: it reads the simulator, clones it and plays the crowd
forward to the end of the episode, so it knows where every human will be at every step. Where
the humans do not react to the robot (``humans.see_robot: false``, one robot), their future does
not depend on what the robot does (tested bit for bit), and the earliest arrival that touches
nothing is found exactly on the space-time lattice of :mod:`crowdnav.planning.lattice`: the
robot's own moves at full speed, ``cells_per_step`` cells per step, checked against every human
and every wall at every step with the simulator's contact distance plus ``margin``.

One exception is exact only up to its events: a human who reaches its goal under ``on_goal:
respawn`` is moved to a spawn point drawn clear of the robot, so where (and with which random
draws) it reappears depends on where the robot is. The oracle therefore (a) blocks, on the step of
a respawn, the cells the human could have touched before it was moved (the simulator tests
contacts first: a disc of its reach plus one step at its max speed around where it was), and (b)
plans again whenever the crowd departs from the future it planned with.

Where the crowd would react to the robot (``see_robot: true``, several robots) the future is not
fixed and the oracle refuses the scenario in one line (:class:`PlannerUnavailable`): planning
through the simulator itself is a different search, which crowdnav does not ship. The same for a
unicycle robot, whose actions are not lattice moves.

Cost (room_furniture, 5-10 humans, 150 steps): about 0.1 s per episode on one core.
"""

from __future__ import annotations

import math

import numpy as np

from crowdnav.errors import CrowdNavError
from crowdnav.planning.lattice import Lattice, disc_cells, search
from crowdnav.planning.static_map import MapCache, StaticMap
from crowdnav.sim.robot_view import RobotWorld

STILL = np.zeros(2, dtype=np.float32)
MAX_CELLS = 50_000_000
"""Most lattice cells the oracle searches over an episode (remaining steps x cells over the world, about 4 bytes each):
the largest library scenario needs 3.3 million; a bigger world, a finer lattice or a longer episode is refused in one line
(:class:`PlannerUnavailable`) before the crowd is played forward or anything is allocated."""
MAX_EPISODES = 1024
"""Plans an oracle keeps at once (one per episode it drives; the oldest dropped)."""
EPSILON = 1e-9
"""Metres kept on the safe side of every contact and goal test: lattice sums and the simulator's may differ by rounding."""


class PlannerUnavailable(CrowdNavError, ValueError):
    """A planner cannot play this scenario (one line: which setting and why)."""


def check_plannable(sim: RobotWorld, who: str, needs_fixed_future: bool) -> None:
    """Refuse, in one line, a scenario a lattice planner cannot drive (unicycle robot; a crowd that reacts to it)."""
    scenario = sim.scenario
    if scenario.robot.kinematics != "holonomic":
        raise PlannerUnavailable(f"{who} plans lattice moves for a holonomic robot; this scenario's robot is {scenario.robot.kinematics}")
    if needs_fixed_future and scenario.robots is not None:
        raise PlannerUnavailable(f"{who} needs a future that does not depend on the robot; with several robots the others react to it")
    if needs_fixed_future and scenario.humans.see_robot:
        raise PlannerUnavailable(f"{who} needs a future that does not depend on the robot; this scenario's humans see it (humans.see_robot: true)")


def to_action(sim: RobotWorld, displacement: complex) -> np.ndarray:
    """The holonomic action that moves the robot by ``displacement`` (world frame, m) in one step."""
    robot = sim.scenario.robot
    local = displacement / (robot.max_speed * sim.dt) * complex(math.cos(sim.robot_heading), -math.sin(sim.robot_heading))
    if abs(local) > 1.0:  # rounding: a full-speed move may come out a hair over 1
        local /= abs(local)
    return np.array([local.real, local.imag], dtype=np.float32)


class OraclePlanner:
    """Earliest collision-free arrival with the humans' true future (see the module docstring).

    ``cells_per_step``: lattice resolution (2: 0.1 m cells at 1 m/s and 0.2 s); ``margin``: extra
    clearance (m) kept from humans and obstacles beyond contact. Called with a
    :class:`crowdnav.Simulator` (it clones it); plans once per episode, and again only if the
    robot is ever off its plan.
    """

    label = "oracle: knows the humans' future (privileged)"

    def __init__(self, cells_per_step: int = 2, margin: float = 0.0):
        if not isinstance(cells_per_step, int) or cells_per_step < 1:
            raise ValueError(f"cells_per_step must be a positive integer, got {cells_per_step!r}")
        if not (math.isfinite(margin) and margin >= 0.0):
            raise ValueError(f"margin must be a finite number >= 0, got {margin!r}")
        self.cells_per_step, self.margin = cells_per_step, float(margin)
        self._plans: dict[int, tuple[object, dict[int, complex], dict[int, np.ndarray]]] = {}
        """id(episode state) -> (that state, step -> where the robot should be after it, step -> where the humans should be):
        one oracle may drive many envs."""
        self.maps = MapCache(self.margin)

    def __call__(self, sim: RobotWorld) -> np.ndarray:
        check_plannable(sim, "the oracle", needs_fixed_future=True)  # the reason a scenario is refused comes first
        state = getattr(sim, "state", None)
        if state is None or not hasattr(sim, "clone"):
            raise PlannerUnavailable("the oracle reads a crowdnav.Simulator (it plays the crowd forward on a clone)")
        step = state.step_count
        found = self._plans.get(id(state))
        if found is None or found[0] is not state or abs(found[1].get(step, math.inf) - sim.robot_position) > 1e-6 \
                or not _crowd_as_planned(found[2].get(step), sim.positions[1:]):
            if found is None and len(self._plans) >= MAX_EPISODES:
                self._plans.pop(next(iter(self._plans)))
            found = self._plans[id(state)] = (state, *self._plan_and_crowd(sim))
        target = found[1].get(step + 1)
        return STILL.copy() if target is None else to_action(sim, target - sim.robot_position)

    def static_map(self, sim: RobotWorld) -> StaticMap:
        """The map of ``sim``'s world for this robot (one per scenario)."""
        return self.maps.map(sim.world)

    def future(self, sim: RobotWorld) -> np.ndarray:
        """(T, n) complex: the humans' positions after each of the episode's remaining steps (the robot standing still)."""
        return self._future(sim)[0]

    def _future(self, sim: RobotWorld) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The humans' positions after each remaining step, and where the respawned ones were before they moved:
        ((T, n) positions, (T, n) complex last positions before the respawn, (T, n) bool respawned on that step)."""
        check_plannable(sim, "the oracle", needs_fixed_future=True)
        twin = sim.clone()  # type: ignore[attr-defined]  # checked in __call__
        remaining = sim.scenario.max_steps - twin.state.step_count
        out = np.empty((remaining, sim.n_humans), dtype=complex)
        before = np.empty_like(out)
        respawned = np.zeros(out.shape, dtype=bool)
        for t in range(remaining):
            count = twin.state.human_respawns.copy()
            before[t] = twin.state.positions[1:]
            twin.step(STILL)
            out[t] = twin.state.positions[1:]
            respawned[t] = twin.state.human_respawns != count
        return out, before, respawned

    def plan(self, sim: RobotWorld) -> dict[int, complex]:
        """Step -> planned robot position, from the current step to the goal (empty: no collision-free arrival exists)."""
        return self._plan_and_crowd(sim)[0]

    def _plan_and_crowd(self, sim: RobotWorld) -> tuple[dict[int, complex], dict[int, np.ndarray]]:
        """The plan, and step -> the humans' positions it assumed after that step."""
        check_plannable(sim, "the oracle", needs_fixed_future=True)
        robot, step0 = sim.scenario.robot, sim.state.step_count  # type: ignore[attr-defined]
        lattice = Lattice(self.cells_per_step, robot.max_speed * sim.dt / self.cells_per_step)
        x0, y0, x1, y1 = self.static_map(sim).bounds
        here, h = sim.robot_position, lattice.spacing
        remaining = max(1, sim.scenario.max_steps - step0)
        if remaining * ((x1 - x0) / h + 3) * ((y1 - y0) / h + 3) > MAX_CELLS:
            raise PlannerUnavailable(f"the oracle: {remaining} steps on a {x1 - x0:g} m x {y1 - y0:g} m world at {h:g} m cells "
                                     f"(cells_per_step {self.cells_per_step}) exceed its limit of {MAX_CELLS:,} lattice cells")
        future, before, respawned = self._future(sim)
        crowd = {step0 + t + 1: row for t, row in enumerate(future)}
        lo_i, lo_j = math.floor((x0 - here.real) / h), math.floor((y0 - here.imag) / h)
        w, hh = math.ceil((x1 - here.real) / h) - lo_i + 1, math.ceil((y1 - here.imag) / h) - lo_j + 1
        origin = here + complex(lo_i, lo_j) * h
        ii, jj = np.meshgrid(np.arange(w), np.arange(hh), indexing="ij")
        cells = origin + (ii + 1j * jj) * h
        static_free = self.static_map(sim).free(cells)
        reach = np.broadcast_to(robot.radius + sim.radii[1:] + self.margin + EPSILON, future.shape)
        # contacts are tested before a respawn moves a human: block all it could have touched on its way to the goal
        ghost_reach = np.where(respawned, reach + sim.state.human_max_speed * sim.dt, -1.0)  # type: ignore[attr-defined]
        blocked = disc_cells(np.concatenate([future, before], 1), np.concatenate([reach, ghost_reach], 1), np.full(len(future), origin),
                             h, (w, hh)).reshape(len(future), 1, w, hh)
        free = static_free[None, None] & ~blocked
        start = np.zeros((1, w, hh), dtype=bool)
        start[0, -lo_i, -lo_j] = True
        goal = (np.abs(cells - sim.robot_goal) <= robot.goal_radius - EPSILON)[None]
        layers = search(start, free, lattice.moves, stop=goal)
        for t, now in enumerate(layers.reached[1:], start=1):
            hits = np.argwhere(now[0] & goal[0])
            if len(hits):
                best = hits[np.argmin(np.abs(cells[hits[:, 0], hits[:, 1]] - sim.robot_goal))]
                moves = layers.path(0, t, (int(best[0]), int(best[1])), lattice.moves)
                positions = here + np.cumsum(lattice.displacements[moves])
                return {step0: here, **{step0 + k + 1: complex(p) for k, p in enumerate(positions)}}, crowd
        # no arrival: survive as long as possible, ending nearest the goal (then plan again from there)
        t = len(layers.reached) - 1
        while t > 0 and not layers.reached[t].any():
            t -= 1
        if t == 0:
            return {}, crowd
        hits = np.argwhere(layers.reached[t][0])
        best = hits[np.argmin(np.abs(cells[hits[:, 0], hits[:, 1]] - sim.robot_goal))]
        moves = layers.path(0, t, (int(best[0]), int(best[1])), lattice.moves)
        positions = here + np.cumsum(lattice.displacements[moves])
        return {step0: here, **{step0 + k + 1: complex(p) for k, p in enumerate(positions)}}, crowd


def _crowd_as_planned(planned: np.ndarray | None, now: np.ndarray) -> bool:
    """Whether the humans stand where the plan assumed (no entry: the plan's first step, nothing to compare)."""
    return planned is None or (planned.shape == now.shape and bool(np.array_equal(planned, now)))
