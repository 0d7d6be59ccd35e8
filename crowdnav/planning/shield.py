"""An action-time safety shield from the robot's own sensing (the env option ``shield``).

Before the simulator moves the robot, the shield checks the action a policy chose: it predicts
the humans the robot's tracker reports (the ``humans`` modality's k nearest within range, with
the scenario's sensor settings and its ``sensors.tracker``, which the env hands it: the shield never
sees anyone the robot's sensors would not)
at constant velocity for ``horizon`` seconds and asks the predictive planner's lattice
(:class:`crowdnav.planning.predictive.Layers`) which moves keep the robot clear of every
prediction and of the walls and furniture of the map to the horizon. An action whose move is
safe is executed unchanged; any other is replaced by the safe lattice move closest to it; with
no safe move, by the move that keeps the most room. The robot's pose in the map and its own
velocity are its localisation and odometry.

So a shielded agent acts from its observation and the map, never from the true state of people
it cannot sense, nor from their future. Results of a shielded policy are reported apart from the
same policy unshielded (``info["shielded"]``: whether the shield replaced this step's action).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from crowdnav.planning.predictive import CrowdEstimate, PlannerSettings, PredictivePlanner, moves_to_actions
from crowdnav.sensors.humans import HumansModality
from crowdnav.worlds.compiled import CompiledWorld


def shield_settings(option: Any) -> PlannerSettings | None:
    """The env option ``shield``: None / False (off), True (the defaults) or a mapping of :class:`PlannerSettings` fields."""
    if option is None or option is False:
        return None
    if option is True:
        return PlannerSettings()
    if isinstance(option, PlannerSettings):
        return option
    if not isinstance(option, dict):
        raise ValueError(f"shield must be true, false or a mapping of {sorted(PlannerSettings.__dataclass_fields__)}, got {option!r}")
    unknown = sorted(set(option) - set(PlannerSettings.__dataclass_fields__))
    if unknown:
        raise ValueError(f"shield: unknown setting(s) {unknown}; expected some of {sorted(PlannerSettings.__dataclass_fields__)}")
    try:
        return PlannerSettings(**option)
    except ValueError as error:  # say which option the bad value came from
        raise ValueError(f"shield: {error}") from None


class Shield:
    """The shield of one env's robot in ``world`` (see the module docstring)."""

    def __init__(self, world: CompiledWorld, settings: PlannerSettings):
        self.world, self.planner = world, PredictivePlanner(settings)
        self.tracker = HumansModality(world, world.scenario.sensors.humans)
        self.dt = float(world.scenario.time_step)

    def single(self, sim: Any, action: np.ndarray) -> tuple[np.ndarray, bool]:
        """One world's (action to execute, whether it was replaced)."""
        rows = self.tracker.observe(sim)[None]
        actions, replaced = self.filter(np.array([sim.robot_position]), np.array([sim.robot_heading]),
                                        np.array([complex(sim.velocities[0])]), np.array([sim.robot_goal]), rows, action[None])
        return actions[0], bool(replaced[0])

    def batch(self, state: Any, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """K worlds' (actions, replaced) from a :class:`crowdnav.batch.state.BatchState`."""
        rows = self.tracker.observe_batch(state)
        return self.filter(state.positions[:, 0], state.robot_heading, state.velocities[:, 0], state.robot_goal, rows, actions)

    def filter(self, robot: np.ndarray, heading: np.ndarray, velocity: np.ndarray, goal: np.ndarray,
               rows: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The kernel: K robots' poses, velocities, goals, tracker rows (K, count, 6) and actions (K, 2)."""
        crowd = CrowdEstimate.from_tracker(robot, heading, velocity, goal, rows)
        grid = self.planner.layers(self.world, self.dt, crowd)
        lattice = grid.lattice
        max_speed = self.world.scenario.robot.max_speed
        command = np.clip(actions[:, 0], -1, 1) + 1j * np.clip(actions[:, 1], -1, 1)
        command /= np.maximum(np.abs(command), 1.0)
        wanted = command * max_speed * np.exp(1j * heading) * self.dt  # the displacement the action asks for
        safe = grid.safe_moves()  # (K, M)
        nearest = np.argmin(np.abs(lattice.displacements[None] - wanted[:, None]), 1)
        target = robot + wanted
        clear_now = (np.abs(target[:, None] - grid.predicted[0]) > grid.reach).all(1) & self.planner.static_map(self.world).free(target, exact=False)
        keep = safe[np.arange(len(robot)), nearest] & clear_now
        distance = np.where(safe, np.abs(lattice.displacements[None] - wanted[:, None]), np.inf)
        replacement = np.where(safe.any(1), np.argmin(distance, 1), grid.roomiest())
        out = np.array(actions, dtype=np.float32, copy=True)
        if (~keep).any():
            out[~keep] = moves_to_actions(lattice.displacements[replacement[~keep]], heading[~keep], max_speed * self.dt)
        return out, ~keep


def validate_shield(option: Any, world: CompiledWorld) -> Shield | None:
    """The env's shield (None when off); a one-line ValueError for a bad option or a robot it cannot drive."""
    settings = shield_settings(option)
    if settings is None:
        return None
    if world.scenario.robots is not None:
        raise ValueError("shield: shields one robot; a scenario with robots: is not supported")
    if world.scenario.robot.kinematics != "holonomic":
        raise ValueError(f"shield: plans lattice moves for a holonomic robot; this scenario's robot is {world.scenario.robot.kinematics}")
    shield = Shield(world, settings)
    shield.planner.check(world, shield.dt)
    return shield
