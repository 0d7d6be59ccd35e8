"""Per-episode navigation metrics, computed vectorized from a recorded trajectory.

Every function is pure and works on numpy arrays (positions as complex numbers ``x + 1j*y``,
metres, world frame), so it can be checked by hand on small made-up trajectories. The
formulas, with their sources (Francis et al. 2023, "Principles and Guidelines for Evaluating
Social Robot Navigation Algorithms", for STL and personal-space compliance; Anderson et al.
2018 for SPL; Hall 1966 for the proxemic zones), are in docs/evaluation.md.

Conventions: a trajectory has states ``t = 0 .. T`` (0: after reset, t: after step t); the
per-step quantities (distances, zones, time to collision, social force) use the states after
each step, ``t = 1 .. T``; velocities are displacements over one step,
``v_t = (p_t - p_{t-1}) / dt``, and the robot starts at rest. An empty place of a recorded crowd
(``humans.model: replay``) is nobody: no metric measures it (:attr:`Trajectory.present`), so
``min_human_distance`` is ``inf`` in an episode where nobody is present.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowdnav.crowd.replay import empty_places

INTIMATE = 0.45
"""Upper bound (m) of the intimate zone (Hall's proxemics), on the surface distance."""
PERSONAL = 1.2
"""Upper bound (m) of the personal zone."""
SOCIAL = 3.6
"""Upper bound (m) of the social zone."""
PERSONAL_SPACE = INTIMATE
"""Radius (m, surface to surface) of the personal space that personal-space compliance counts
intrusions into: the intimate zone, the space a stranger should not enter."""

METRIC_COLUMNS = (
    "steps", "time_to_goal", "path_length", "straight_line_distance", "spl", "stl", "min_human_distance",
    "intimate_share", "personal_share", "social_share", "psc", "mean_speed", "max_speed", "mean_acceleration",
    "max_acceleration", "mean_jerk", "max_jerk", "min_time_to_collision", "social_force", "human_stalls", "group_intrusions",
)
"""The keys of :func:`episode_metrics`, in column order."""


@dataclass(frozen=True)
class Trajectory:
    """One recorded episode: what the metrics need, nothing else."""

    positions: np.ndarray
    """(T + 1, n + 1) complex: column 0 the robot, columns 1.. the humans, row t the state after step t."""
    radii: np.ndarray
    """(n + 1,) body radii (m), robot first."""
    goal: complex
    """The robot's goal (m)."""
    goal_radius: float
    """The goal counts as reached within this centre distance (m)."""
    dt: float
    """Time step (s)."""
    social_force: np.ndarray
    """(T,) magnitude of the humans' social force on the robot after each step (the reward's social term / w_social)."""
    max_speed: float
    """The robot's maximum speed (m/s): the fastest time to the goal is the straight line at this speed."""
    human_stalls: int = 0
    """Times a human stalled during the episode (``humans.stall``; the simulator's ``human_stalls`` summed at the end)."""
    walking_group: np.ndarray | None = None
    """(n,) int: each human's walking group (a group with ``walk_together``), -1 for the others; None: no such group."""

    @property
    def steps(self) -> int:
        return len(self.positions) - 1

    @property
    def present(self) -> np.ndarray:
        """(T + 1, n) bool: the humans present at each state; an empty place of a recorded crowd (parked far outside the
        world, :func:`crowdnav.crowd.replay.empty_places`) is nobody, so no metric measures it."""
        present: np.ndarray = ~empty_places(self.positions[:, 1:])
        return present


def path_length(points: np.ndarray) -> float:
    """Length (m) of the polyline through ``points`` (complex)."""
    return float(np.abs(np.diff(points)).sum())


def straight_line_distance(start: complex, goal: complex, goal_radius: float) -> float:
    """Shortest distance (m) from ``start`` into the goal disc, ignoring obstacles: ``max(|g - p0| - r_goal, 0)``."""
    return max(abs(goal - start) - goal_radius, 0.0)


def spl(success: bool, length: float, shortest: float) -> float:
    """Success weighted by path length (Anderson et al. 2018): ``S * l / max(p, l)`` (1 when ``l == 0`` and successful)."""
    if not success:
        return 0.0
    longest = max(length, shortest)
    return 1.0 if longest <= 0.0 else shortest / longest


def stl(success: bool, duration: float, fastest: float) -> float:
    """Success weighted by time length (Francis et al. 2023): ``S * t* / max(t, t*)`` (1 when ``t* == t == 0`` and successful).

    ``duration``: the episode's time ``T dt`` (s); ``fastest``: ``t* = l / v_max``, the straight
    line into the goal disc at the robot's maximum speed.
    """
    if not success:
        return 0.0
    longest = max(duration, fastest)
    return 1.0 if longest <= 0.0 else fastest / longest


def personal_space_compliance(closest: np.ndarray) -> float:
    """Share of steps with no human closer than :data:`PERSONAL_SPACE` (surface distance); 1 without steps or humans."""
    return float(np.mean(closest >= PERSONAL_SPACE)) if len(closest) else 1.0


def surface_distances(robot: np.ndarray, humans: np.ndarray, robot_radius: float, human_radii: np.ndarray) -> np.ndarray:
    """(T, n) distance (m) between the robot's body and each human's body (negative when overlapping).

    ``robot``: (T,) complex positions; ``humans``: (T, n) complex positions; ``human_radii``: (n,).
    """
    return np.abs(humans - robot[:, None]) - robot_radius - np.asarray(human_radii)[None, :]


def closest_distance(distances: np.ndarray) -> np.ndarray:
    """(T,) distance to the closest human per step, ``inf`` when there are no humans."""
    if distances.shape[1] == 0:
        return np.full(distances.shape[0], np.inf)
    return distances.min(axis=1)


def zone_shares(closest: np.ndarray) -> dict[str, float]:
    """Fraction of steps whose closest human is in the intimate (< 0.45 m), personal (0.45-1.2 m) or social (1.2-3.6 m) zone."""
    if len(closest) == 0:
        return {"intimate_share": 0.0, "personal_share": 0.0, "social_share": 0.0}
    return {
        "intimate_share": float(np.mean(closest < INTIMATE)),
        "personal_share": float(np.mean((closest >= INTIMATE) & (closest < PERSONAL))),
        "social_share": float(np.mean((closest >= PERSONAL) & (closest < SOCIAL))),
    }


def step_velocities(positions: np.ndarray, dt: float) -> np.ndarray:
    """(T, ...) velocity during each step: ``(p_t - p_{t-1}) / dt`` along axis 0."""
    return np.diff(positions, axis=0) / dt


def motion_magnitudes(robot: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed (T,), acceleration (T,) and jerk (T - 1,) magnitudes of a path that starts at rest.

    ``v_t = (p_t - p_{t-1}) / dt``, ``a_t = (v_t - v_{t-1}) / dt`` with ``v_0 = 0``,
    ``j_t = (a_t - a_{t-1}) / dt`` for ``t >= 2``.
    """
    velocity = np.concatenate([[0j], step_velocities(robot, dt)])
    acceleration = np.diff(velocity) / dt
    jerk = np.diff(acceleration) / dt
    return np.abs(velocity[1:]), np.abs(acceleration), np.abs(jerk)


def time_to_collision(offset: np.ndarray, relative_velocity: np.ndarray, contact: np.ndarray | float) -> np.ndarray:
    """Time (s) until two discs touch if both keep their velocities; 0 if they already do, ``inf`` if never.

    ``offset``: position of the other disc relative to this one; ``relative_velocity``: its
    velocity relative to this one; ``contact``: sum of the radii. Solves
    ``|offset + relative_velocity * tau| = contact`` for the smallest ``tau >= 0``; any shapes
    that broadcast.
    """
    a = np.abs(relative_velocity) ** 2
    b = 2.0 * (offset.real * relative_velocity.real + offset.imag * relative_velocity.imag)
    c = np.abs(offset) ** 2 - np.asarray(contact) ** 2
    discriminant = b * b - 4.0 * a * c
    approaching = (a > 0.0) & (b < 0.0) & (discriminant >= 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = (-b - np.sqrt(np.where(approaching, discriminant, 0.0))) / (2.0 * a)
    return np.where(c <= 0.0, 0.0, np.where(approaching, tau, np.inf))


def min_time_to_collision(positions: np.ndarray, radii: np.ndarray, dt: float, present: np.ndarray | None = None) -> float:
    """Smallest robot-human time to collision over the states ``t = 1 .. T`` under constant step velocities.

    ``present`` (T + 1, n) bool: a human counts at state t only when present at t and t - 1 (a person entering a
    place of a recorded crowd would otherwise "move" from the parking place); None: every human always.
    """
    if positions.shape[1] < 2 or len(positions) < 2:
        return float("inf")
    velocity = step_velocities(positions, dt)  # (T, n + 1)
    offset = positions[1:, 1:] - positions[1:, :1]
    relative = velocity[:, 1:] - velocity[:, :1]
    tau = time_to_collision(offset, relative, radii[0] + radii[1:])
    if present is not None:
        tau = np.where(present[1:] & present[:-1], tau, np.inf)
    return float(tau.min())


def cumulative_social_force(force: np.ndarray, dt: float) -> float:
    """Time integral of the social force's magnitude on the robot: ``sum_t |F_t| dt``."""
    return float(np.sum(np.abs(force)) * dt)


GROUP_LINK = 2.0
"""Members of a walking group at most this far apart (m, centre to centre) are linked: a robot between them splits the group."""


def group_intrusions(robot: np.ndarray, humans: np.ndarray, walking_group: np.ndarray | None, robot_radius: float,
                     link: float = GROUP_LINK) -> int:
    """Steps in which the robot cuts through a walking group.

    ``robot`` (T,) and ``humans`` (T, n) complex: the states after each step; ``walking_group`` (n,):
    each human's walking group, -1 for none. A step counts when, for two members i and j of one
    walking group whose centres are at most ``link`` apart, the robot's body touches the segment
    joining their centres strictly between them: the foot of the perpendicular from the robot's
    centre falls inside the segment (not at or beyond either member) and lies less than the robot's
    radius from that centre.
    """
    if walking_group is None or len(robot) == 0:
        return 0
    label = np.asarray(walking_group)
    first, second = np.triu_indices(len(label), 1)
    paired = (label[first] == label[second]) & (label[first] >= 0)
    first, second = first[paired], second[paired]
    if len(first) == 0:
        return 0
    a, b = humans[:, first], humans[:, second]  # (T, P): the pairs of fellow members
    span = b - a
    length2 = np.abs(span) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):  # two members on one point: no segment, never counted
        along = ((robot[:, None] - a) * np.conj(span)).real / length2
    between = (along > 0.0) & (along < 1.0) & (length2 <= link * link)
    crossing = between & (np.abs(robot[:, None] - (a + along * span)) < robot_radius)
    return int(crossing.any(axis=1).sum())


def _mean_max(values: np.ndarray) -> tuple[float, float]:
    if len(values) == 0:
        return float("nan"), float("nan")
    return float(values.mean()), float(values.max())


def episode_metrics(trajectory: Trajectory, success: bool) -> dict[str, float]:
    """Every metric of :data:`METRIC_COLUMNS` for one episode (``success``: it ended at the goal)."""
    positions, dt = trajectory.positions, trajectory.dt
    robot, steps = positions[:, 0], trajectory.steps
    length = path_length(robot)
    shortest = straight_line_distance(complex(robot[0]), trajectory.goal, trajectory.goal_radius)
    after = positions[1:]  # the states after each step
    present = trajectory.present
    humans = np.where(present[1:], after[:, 1:], complex(np.nan, np.nan))  # nobody in an empty place: no distance, no group
    distances = surface_distances(after[:, 0], humans, trajectory.radii[0], trajectory.radii[1:])
    closest = closest_distance(np.where(present[1:], distances, np.inf))
    speed, acceleration, jerk = motion_magnitudes(robot, dt)
    metrics = {
        "steps": steps,
        "time_to_goal": steps * dt if success else float("nan"),
        "path_length": length,
        "straight_line_distance": shortest,
        "spl": spl(success, length, shortest),
        "stl": stl(success, steps * dt, shortest / trajectory.max_speed),
        "min_human_distance": float(closest.min()) if len(closest) else float("inf"),
        **zone_shares(closest),
        "psc": personal_space_compliance(closest),
    }
    metrics["mean_speed"], metrics["max_speed"] = _mean_max(speed)
    metrics["mean_acceleration"], metrics["max_acceleration"] = _mean_max(acceleration)
    metrics["mean_jerk"], metrics["max_jerk"] = _mean_max(jerk)
    metrics["min_time_to_collision"] = min_time_to_collision(positions, trajectory.radii, dt, present)
    metrics["social_force"] = cumulative_social_force(trajectory.social_force, dt)
    metrics["human_stalls"] = trajectory.human_stalls  # the crowd's health, not the robot's: a stall-free crowd has 0
    metrics["group_intrusions"] = group_intrusions(after[:, 0], humans, trajectory.walking_group, float(trajectory.radii[0]))
    return metrics
