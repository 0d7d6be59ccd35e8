"""A receding-horizon planner over constant-velocity predictions (``baseline:predictive``).

At every step it predicts each human to keep its current velocity for ``horizon`` seconds,
searches the space-time lattice of :mod:`crowdnav.planning.lattice` around the robot (the moves
it can make, ``cells_per_step`` cells per step), keeps the cells that touch no predicted human
(contact distance plus ``human_margin``) and no wall or furniture (plus ``static_margin``), and
takes the first move of the best plan: the earliest that reaches the goal if one does within the
horizon, otherwise the one that survives longest and ends nearest the goal by the geodesic
distance around the furniture (the map). If every move touches a prediction at the next step,
it takes the move that keeps the most room.

What it reads is a :class:`CrowdEstimate`: from the simulator (:meth:`CrowdEstimate.from_sim`:
the true current state of every human; the baseline is privileged that far) or from a robot's
own observation (:meth:`CrowdEstimate.from_tracker`: the humans its tracker reports; the ``plan``
modality and ``baseline:onboard``). It never reads the future. Worlds are batched: one call plans K worlds of one map with the same arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from crowdnav.crowd.replay import empty_places
from crowdnav.planning.lattice import Lattice, SearchLayers, disc_cells, search, shifted
from crowdnav.planning.oracle import EPSILON, check_plannable, to_action
from crowdnav.planning.static_map import RASTER, MapCache, StaticMap, grid_shape
from crowdnav.sim.robot_view import RobotWorld
from crowdnav.worlds.compiled import CompiledWorld


@dataclass
class CrowdEstimate:
    """What a planner knows of K worlds now (world frame, m and m/s); absent humans have ``present`` False."""

    robot: np.ndarray
    """(K,) complex robot positions."""
    goal: np.ndarray
    """(K,) complex robot goals."""
    humans: np.ndarray
    """(K, n) complex human positions."""
    velocities: np.ndarray
    """(K, n) complex human velocities."""
    radii: np.ndarray
    """(K, n) human body radii."""
    present: np.ndarray
    """(K, n) bool: which rows are humans (a tracker reports fewer than n)."""

    @classmethod
    def from_tracker(cls, robot: np.ndarray, heading: np.ndarray, velocity: np.ndarray, goal: np.ndarray,
                     rows: np.ndarray) -> CrowdEstimate:
        """K robots' poses, own velocities (world frame) and goals, and their trackers' rows (K, count, 6) of
        :class:`crowdnav.sensors.humans.HumansModality` (robot-frame position and relative velocity, radius, presence)."""
        rotation = np.exp(1j * np.asarray(heading, dtype=float))[:, None]
        return cls(np.asarray(robot, dtype=complex), np.asarray(goal, dtype=complex),
                   robot[:, None] + rotation * (rows[..., 0] + 1j * rows[..., 1]),
                   velocity[:, None] + rotation * (rows[..., 2] + 1j * rows[..., 3]),
                   rows[..., 4].astype(float), rows[..., 5] > 0.5)

    @classmethod
    def from_sim(cls, sim: RobotWorld) -> CrowdEstimate:
        """The true current state of one world (every human present, and other robots as moving discs)."""
        positions, velocities, radii = sim.positions[1:], sim.velocities[1:], sim.radii[1:]
        return cls(np.array([sim.robot_position]), np.array([sim.robot_goal]), positions[None].astype(complex),
                   velocities[None].astype(complex), radii[None].astype(float), ~empty_places(positions)[None])


MAX_WINDOW_CELLS = 4_000_000
"""Most cells of one world's local lattice over the horizon (steps x side x side, side = 2 * steps * cells_per_step + 1):
e.g. a 10 s horizon at 2 cells per step and dt 0.2 s; bigger settings are refused in one line before any allocation."""

PREDICTIONS = ("constant_velocity", "frozen")
"""How a planner may predict the humans (:attr:`PlannerSettings.prediction`)."""


@dataclass(frozen=True)
class PlannerSettings:
    """The predictive planner's parameters (docs/agents.md#the-predictive-planner)."""

    horizon: float = 2.0
    """Seconds of constant-velocity prediction searched at every step."""
    cells_per_step: int = 2
    """Lattice cells per full-speed step (2: 0.1 m cells at 1 m/s and 0.2 s, 13 moves)."""
    prediction: str = "constant_velocity"
    """How the humans move over the horizon: ``constant_velocity``, or ``frozen`` (where they stand now; an ablation)."""
    human_margin: float = 0.1
    """Metres kept from each predicted human beyond contact (prediction error room)."""
    static_margin: float = 0.02
    """Metres kept from walls and furniture beyond contact."""
    map_spacing: float = 0.1
    """Grid spacing (m) of the geodesic distance to the goal."""

    def __post_init__(self) -> None:
        for name in ("horizon", "human_margin", "static_margin", "map_spacing"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if self.map_spacing <= 0 or self.horizon <= 0:
            raise ValueError(f"horizon and map_spacing must be > 0, got {self.horizon!r} and {self.map_spacing!r}")
        if self.prediction not in PREDICTIONS:
            raise ValueError(f"prediction must be one of {PREDICTIONS}, got {self.prediction!r}")
        if isinstance(self.cells_per_step, bool) or not isinstance(self.cells_per_step, int) or not 1 <= self.cells_per_step <= 8:
            raise ValueError(f"cells_per_step must be an integer in [1, 8], got {self.cells_per_step!r}")

    def window(self, dt: float) -> tuple[int, int]:
        """``(steps, centre)`` of the local lattice at time step ``dt``; a one-line ValueError over :data:`MAX_WINDOW_CELLS`."""
        steps = max(1, int(round(min(self.horizon / dt, 1e12))))
        side = 2 * steps * self.cells_per_step + 1
        if steps * side * side > MAX_WINDOW_CELLS:
            raise ValueError(f"planner settings: horizon {self.horizon:g} s at cells_per_step {self.cells_per_step} and time step {dt:g} s "
                             f"is a {steps}-step lattice of {side} x {side} cells per step, over the limit of {MAX_WINDOW_CELLS:,} "
                             "cells (a shorter horizon or fewer cells per step)")
        return steps, steps * self.cells_per_step


class PredictivePlanner:
    """Constant-velocity prediction + lattice search, replanned every step (see the module docstring).

    As a scripted policy (``policy(sim) -> action``) it reads the true current state; a learned
    agent calls :meth:`plan` with what it observed. ``settings``: :class:`PlannerSettings`.
    """

    label = "predictive planner: current state + map, constant-velocity prediction (privileged)"

    def __init__(self, settings: PlannerSettings | None = None, **overrides: float):
        self.settings = settings or PlannerSettings(**overrides)  # type: ignore[arg-type]
        self.maps = MapCache(self.settings.static_margin, self.settings.map_spacing)

    def __call__(self, sim: RobotWorld) -> np.ndarray:
        check_plannable(sim, "the predictive planner", needs_fixed_future=False)
        self.check(sim.world, sim.dt)
        move = self.plan(sim.world, sim.dt, CrowdEstimate.from_sim(sim))[0]
        return to_action(sim, complex(move))

    def static_map(self, world: CompiledWorld) -> StaticMap:
        """The map of ``world`` for its robot (one per scenario)."""
        return self.maps.map(world)

    def check(self, world: CompiledWorld, dt: float) -> None:
        """Refuse in one line, before anything is allocated, settings or a world too large to plan in (the lattice, the maps)."""
        self.settings.window(dt)
        box = world.scenario.world
        bounds = (float(box.min[0]), float(box.min[1]), float(box.max[0]), float(box.max[1]))
        grid_shape(bounds, RASTER, "the planners' clearance raster")
        grid_shape(bounds, self.settings.map_spacing, "the goal-distance grid (map_spacing)")

    def layers(self, world: CompiledWorld, dt: float, crowd: CrowdEstimate) -> Layers:
        """The local lattice of K worlds around their robots and its free cells at each predicted step.

        The last result is kept for every planner of the process (read-only arrays): with the ``plan``
        modality and the shield on, both ask for the same state's layers once per step (after the step
        to observe, before the next to check), and this is two thirds of their cost.
        """
        key = _layers_key(self.settings, dt, crowd)
        if _LAST_LAYERS and _LAST_LAYERS[0][0] is world and _LAST_LAYERS[0][1] == key:
            return _LAST_LAYERS[0][2]
        layers = self._layers(world, dt, crowd)
        for array in (layers.cells, layers.static_free, layers.free, layers.goal, layers.predicted, layers.reach):
            array.flags.writeable = False
        _LAST_LAYERS[:] = [(world, key, layers)]  # the world is held, so its id cannot be reused while cached
        return layers

    def _layers(self, world: CompiledWorld, dt: float, crowd: CrowdEstimate) -> Layers:
        s, robot = self.settings, world.scenario.robot
        lattice = Lattice(s.cells_per_step, robot.max_speed * dt / s.cells_per_step)
        steps, centre = s.window(dt)
        side = 2 * centre + 1
        k = len(crowd.robot)
        span = np.arange(-centre, centre + 1) * lattice.spacing
        cells = crowd.robot[:, None, None] + (span[:, None] + 1j * span[None, :])  # (K, side, side)
        static_free = self.static_map(world).free(cells, exact=False)
        ahead = np.arange(1, steps + 1)[:, None, None] * dt
        moving = crowd.velocities if s.prediction == "constant_velocity" else np.zeros_like(crowd.velocities)
        predicted = crowd.humans[None] + moving[None] * ahead  # (T, K, n)
        reach = np.where(crowd.present, robot.radius + crowd.radii + s.human_margin + EPSILON, -1.0)
        blocked = disc_cells(predicted, np.broadcast_to(reach, predicted.shape), np.broadcast_to(cells[:, 0, 0], (steps, k)),
                             lattice.spacing, (side, side)).reshape(steps, k, side, side)
        goal = np.abs(cells - crowd.goal[:, None, None]) <= robot.goal_radius - EPSILON
        return Layers(lattice, centre, cells, static_free, static_free[None] & ~blocked, goal, predicted, reach)

    def plan(self, world: CompiledWorld, dt: float, crowd: CrowdEstimate) -> np.ndarray:
        """(K,) complex: the displacement (m, world frame) each world's robot should make this step."""
        grid = self.layers(world, dt, crowd)
        start = np.zeros(grid.goal.shape, dtype=bool)
        start[:, grid.centre, grid.centre] = True
        found = search(start, grid.free, grid.lattice.moves, stop=grid.goal)
        flat_cells = grid.cells.reshape(len(grid.cells), -1)

        def cost(rows: np.ndarray, mask: np.ndarray) -> np.ndarray:  # only where a plan may end
            out = np.full(mask.shape, np.inf)
            owner, cell = np.nonzero(mask)
            out[owner, cell] = self.maps.cost(world, crowd.goal[rows], flat_cells[rows[owner], cell], owner)
            return out

        first = _first_moves(found, grid.lattice.moves, grid.goal, cost)
        stuck = first < 0
        if stuck.any():  # every move touches a prediction next step: keep the most room
            first[stuck] = grid.roomiest()[stuck]
        displacement: np.ndarray = grid.lattice.displacements[first]
        return displacement


_LAST_LAYERS: list[tuple[CompiledWorld, tuple[object, ...], Layers]] = []
"""The last (world, key, layers) any planner computed (:meth:`PredictivePlanner.layers`)."""


def _layers_key(settings: PlannerSettings, dt: float, crowd: CrowdEstimate) -> tuple[object, ...]:
    """Everything :meth:`PredictivePlanner.layers` reads but the world: the settings, the step and the estimate's bytes."""
    arrays = (crowd.robot, crowd.goal, crowd.humans, crowd.velocities, crowd.radii, crowd.present)
    return (settings, float(dt), *((a.dtype.str, a.shape, a.tobytes()) for a in map(np.asarray, arrays)))


def moves_to_actions(moves: np.ndarray, heading: np.ndarray, step: float) -> np.ndarray:
    """(K, 2) float32 holonomic actions (robot frame) that make each world's ``moves`` (K,) complex, world frame, m)
    in one step; ``step``: the robot's full-speed displacement per step (``max_speed * dt``)."""
    local = moves / step * np.exp(-1j * np.asarray(heading, dtype=float))
    local /= np.maximum(np.abs(local), 1.0)  # rounding: a full-speed move may come out a hair over 1
    actions: np.ndarray = np.stack([local.real, local.imag], -1).astype(np.float32)
    return actions


@dataclass
class Layers:
    """K worlds' local lattices (centred on their robots) and where the robot may be at each predicted step."""

    lattice: Lattice
    centre: int
    """Index of the robot's cell on both axes."""
    cells: np.ndarray
    """(K, side, side) complex cell positions."""
    static_free: np.ndarray
    """(K, side, side) bool: clear of walls and furniture."""
    free: np.ndarray
    """(T, K, side, side) bool: clear of everything at predicted step t + 1."""
    goal: np.ndarray
    """(K, side, side) bool: within the goal radius."""
    predicted: np.ndarray
    """(T, K, n) complex predicted human positions."""
    reach: np.ndarray
    """(K, n) contact distance plus margin to each human (-1: absent)."""

    def safe_moves(self) -> np.ndarray:
        """(K, M) bool: the moves after which the robot can stay clear of every prediction to the horizon (or reach the goal).

        One backward pass: a cell is safe at step t if it is free then and one move leads to a safe
        cell at t + 1 (every cell free at the horizon is safe; a free goal cell is safe at any t).
        """
        moves = self.lattice.moves
        safe = self.free[-1].copy()
        for t in range(len(self.free) - 2, -1, -1):
            onward = np.zeros_like(safe)
            for di, dj in moves.tolist():
                onward |= shifted(safe, -di, -dj)
            safe = self.free[t] & (onward | self.goal)
        c = self.centre
        out: np.ndarray = safe[:, c + moves[:, 0], c + moves[:, 1]]
        return out

    def roomiest(self) -> np.ndarray:
        """(K,) the statically free move that keeps the most room from every human predicted one step ahead."""
        moves, c = self.lattice.moves, self.centre
        targets = self.cells[:, c + moves[:, 0], c + moves[:, 1]]  # (K, M)
        room = (np.abs(targets[:, :, None] - self.predicted[0][:, None, :]) - self.reach[:, None, :]).min(2, initial=np.inf)
        ok = self.static_free[:, c + moves[:, 0], c + moves[:, 1]]
        out: np.ndarray = np.argmax(np.where(ok, room, -np.inf), 1)
        return out


def _first_moves(layers: SearchLayers, moves: np.ndarray, goal: np.ndarray,
                 cost: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """(K,) the first move of each world's best plan (-1 where the robot cannot survive one step).

    ``cost(rows, mask)``: the distance to the goal of worlds ``rows`` at their cells ``mask`` (inf elsewhere).
    """
    k = len(goal)
    depth = len(layers.reached) - 1
    chosen_t = np.zeros(k, dtype=np.int64)
    chosen = np.full(k, -1, dtype=np.int64)  # flat cell index
    done = np.zeros(k, dtype=bool)
    for t in range(1, depth + 1):  # the earliest arrival at the goal
        hit = (layers.reached[t] & goal).reshape(k, -1)
        new = hit.any(1) & ~done
        if new.any():
            chosen[new] = np.argmax(hit[new], 1)
            chosen_t[new] = t
            done |= new
    for t in range(depth, 0, -1):  # otherwise: the deepest layer, nearest the goal around obstacles
        now = layers.reached[t].reshape(k, -1)
        new = now.any(1) & ~done
        if new.any():
            chosen[new] = np.argmin(cost(np.flatnonzero(new), now[new]), 1)
            chosen_t[new] = t
            done |= new
    side = goal.shape[-1]
    i, j = chosen // side, chosen % side
    first = np.full(k, -1, dtype=np.int64)
    for t in range(depth, 0, -1):  # walk back to the first move, all worlds at once
        on = (chosen_t >= t) & done
        if not on.any():
            continue
        move = layers.parent[t - 1][np.flatnonzero(on), i[on], j[on]].astype(np.int64)
        first[on] = move
        i[on] -= moves[move, 0]
        j[on] -= moves[move, 1]
    return first
