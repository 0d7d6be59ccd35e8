"""The model :mod:`crowdnav.crowd.fit` fits: recorded windows, the social-force rollout over them, and their scores.

From a recording (:mod:`crowdnav.crowd.recording`, on a grid of the annotation step, 0.4 s for
ETH/UCY) windows are cut every ``stride`` steps: the people present from one step before a
window's start to ``horizon`` seconds after it are *simulated*. Each starts from its recorded
position and velocity (the step before) and walks toward its destination, the last position its
track records (where it leaves the scene or stops being annotated: the destination known, as in the
social-force baselines of trajectory prediction), among the other people at their recorded
positions and each other, by the kernels of
:mod:`crowdnav.sim.forces` (the simulator's step without its overlap pushes) with two additions
the simulator does not have:

- **per-person preferred speeds by quantile mapping**: people are ranked by their median speed
  over their whole recorded track (their cruising speed, a trait of the person like its
  destination); a person at mid-rank ``u = (rank + 1/2) / people`` in (0, 1) prefers
  ``speed_low + speed_width * u``. The fitted preferred speeds are so uniform on
  ``[speed_low, speed_low + speed_width]``, as ``humans.preferred_speed`` draws them, and the
  order of who walks fast is the recording's own (interactions slow people below their preferred
  speed, so a recorded speed is not itself a preferred speed);
- **anisotropy** (Helbing and Molnár 1995; Helbing, Farkas and Vicsek 2000): a neighbour at angle
  phi from a person's walking direction repels it with weight ``lambda + (1 - lambda) (1 + cos phi) / 2``;
  ``lambda = 1`` is crowdnav's isotropic repulsion.

Recordings carry no obstacles, so the obstacle terms are absent here (not identifiable).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crowdnav.crowd.recording import read_recording
from crowdnav.scenario.crowd import SocialForce
from crowdnav.sim import forces as sf

RADIUS = 0.3
"""Every person's body radius (m), humans.radius's default."""
MIN_SPEED = 1e-3
"""A floor on preferred speeds (m/s): the speed cap divides by it."""


@dataclass(frozen=True)
class Params:
    """One point of the fitted space; ``preferred_speed`` set: everyone walks at it (the default humans), else per person."""

    speed_low: float = 0.8
    speed_width: float = 0.4
    relaxation_time: float = 0.5
    human_strength: float = 2.0
    human_range: float = 0.3
    anisotropy: float = 1.0
    preferred_speed: float | None = None


_DEFAULT_FORCE = SocialForce()
DEFAULT = Params(relaxation_time=_DEFAULT_FORCE.relaxation_time, human_strength=_DEFAULT_FORCE.human_strength,
                 human_range=_DEFAULT_FORCE.human_range, anisotropy=1.0, preferred_speed=1.0)
"""The default humans: 1.0 m/s each (the middle of humans.preferred_speed's [0.8, 1.2]), humans.social_force's defaults."""


@dataclass
class Windows:
    """W windows of H+2 grid steps (one before the start, the start, H ahead) over N people each (NaN: absent)."""

    positions: np.ndarray
    """(W, H+2, N) complex recorded positions."""
    simulated: np.ndarray
    """(W, N) bool: present for the whole window, so simulated and scored."""
    dt: float
    start: np.ndarray
    """(W,) int: each window's first grid step (the step before its start), for splitting by time."""
    goal: np.ndarray
    """(W, N) complex: each person's destination, its track's last position (NaN: nobody)."""
    rank: np.ndarray
    """(W, N): each person's mid-rank in (0, 1) among the recording's people by median recorded speed (0: nobody)."""

    def subset(self, keep: np.ndarray) -> Windows:
        return Windows(self.positions[keep], self.simulated[keep], self.dt, self.start[keep], self.goal[keep], self.rank[keep])


def cut_windows(path: str | Path, fmt: str = "auto", annotation_step: float = 0.4, time_step: float | None = None,
                horizon: float = 4.8, stride: int = 2) -> Windows:
    """The windows of a recording (see the module docstring)."""
    recording = read_recording(path, fmt, annotation_step)  # type: ignore[arg-type]
    dt = time_step or annotation_step
    grid = recording.resample(dt)
    dense = np.full((grid.steps, len(grid.tracks)), np.nan + 0j)
    goals = np.array([track.positions[-1] for track in grid.tracks])
    cruising = [np.median(np.abs(np.diff(track.positions))) if len(track.positions) > 1 else 0.0 for track in grid.tracks]
    ranks = (np.argsort(np.argsort(cruising, kind="stable"), kind="stable") + 0.5) / len(cruising)
    for column, track in enumerate(grid.tracks):  # per person, once
        dense[track.start : track.start + len(track.positions), column] = track.positions
    ahead = round(horizon / dt)
    if ahead < 1:
        raise ValueError(f"horizon {horizon:g} s is shorter than the time step {dt:g} s; expected a longer horizon")
    cuts, full, starts, who = [], [], [], []
    for start in range(1, grid.steps - ahead, stride):  # per window
        block = dense[start - 1 : start + ahead + 1]
        there = ~np.isnan(block.real)
        columns = np.flatnonzero(there.any(0))
        if there[:, columns].all(0).any():
            cuts.append(block[:, columns])
            full.append(there[:, columns].all(0))
            starts.append(start - 1)
            who.append(columns)
    if not cuts:
        raise ValueError(f"{path}: nobody is recorded for {horizon:g} s plus a step; expected longer tracks or a shorter horizon")
    people = max(cut.shape[1] for cut in cuts)
    positions = np.full((len(cuts), ahead + 2, people), np.nan + 0j)
    simulated = np.zeros((len(cuts), people), dtype=bool)
    goal, rank = np.full((len(cuts), people), np.nan + 0j), np.zeros((len(cuts), people))
    for w, (cut, mask, columns) in enumerate(zip(cuts, full, who, strict=True)):  # per window
        positions[w, :, : cut.shape[1]] = cut
        simulated[w, : cut.shape[1]] = mask
        goal[w, : cut.shape[1]], rank[w, : cut.shape[1]] = goals[columns], ranks[columns]
    return Windows(positions, simulated, dt, np.array(starts), goal, rank)


def split(windows: Windows, held_out: float) -> tuple[Windows, Windows]:
    """(training, held-out) windows by time: the last ``held_out`` share of the windows' span is held out, and training
    windows that reach into it are dropped, so no recorded step is scored in both."""
    if not 0 < held_out < 1:
        raise ValueError(f"held-out share {held_out:g}: expected a number between 0 and 1")
    length = windows.positions.shape[1]
    first, last = int(windows.start.min()), int(windows.start.max()) + length
    cut = last - held_out * (last - first)
    test = windows.start >= cut
    train = windows.start + length <= cut
    if not train.any() or not test.any():
        raise ValueError(f"{len(windows.start)} windows cannot be split into training and held-out ones at {held_out:g}; "
                         "expected a longer recording, a shorter horizon or another --held-out")
    return windows.subset(train), windows.subset(test)


def interaction_step(now: np.ndarray, velocity: np.ndarray, goal: np.ndarray, preferred: np.ndarray, walking: np.ndarray,
                     params: Params, dt: float, force: SocialForce = _DEFAULT_FORCE) -> np.ndarray:
    """(..., N) complex: the next velocity of each walking person (0 for the others) among everyone present (NaN: absent).

    ``now``, ``velocity``, ``goal`` (..., N) complex; ``preferred`` (..., N) preferred speeds; ``walking`` (..., N) bool."""
    offset = now[..., None, :] - now[..., :, None]  # (..., N, N): from each person (row) to every other
    distance = np.abs(offset)
    void = np.isnan(distance) | np.eye(now.shape[-1], dtype=bool)
    gain = np.broadcast_to(sf.repulsion_gain(params.human_strength, 2 * RADIUS, params.human_range), void.shape)
    if params.anisotropy < 1:  # a neighbour behind weighs lambda, one ahead 1 (only the fit's rollout has this)
        speed = np.abs(velocity)
        heading = np.where(speed > 0, velocity / np.where(speed > 0, speed, 1.0), 0)
        cos = np.real(np.conj(heading)[..., :, None] * offset) / np.where(void, 1.0, distance)
        gain = gain * (params.anisotropy + (1 - params.anisotropy) * (1 + cos) / 2)
    total = sf.goal_force(np.where(walking, goal - now, 0), force.goal_weight, force.goal_saturation_distance)
    total = total + sf.repulsion(np.where(void, 0, offset), np.where(void, 1.0, distance), np.where(void, 0.0, gain),
                                 -1.0 / params.human_range)
    command = sf.velocity_command(np.where(walking, total, 0), np.where(walking, velocity, 0), preferred,
                                  preferred * force.max_speed_factor, min(1.0, dt / params.relaxation_time))
    return np.where(walking, command, 0)


def preferred_speeds(windows: Windows, params: Params) -> np.ndarray:
    """(W, N): each simulated person's preferred speed under ``params`` (see :class:`Params`)."""
    if params.preferred_speed is not None:
        return np.full(windows.simulated.shape, params.preferred_speed)
    return np.maximum(params.speed_low + params.speed_width * windows.rank, MIN_SPEED)


def rollout(windows: Windows, params: Params) -> np.ndarray:
    """(W, H+2, N) complex: the recorded positions with the simulated people's replaced by the social force's, all windows at once."""
    dt, sim = windows.dt, windows.simulated
    out: np.ndarray = windows.positions.copy()
    velocity = np.where(sim, (out[:, 1] - out[:, 0]) / dt, 0)
    goal, preferred = windows.goal, preferred_speeds(windows, params)
    for k in range(1, out.shape[1] - 1):  # per step of the horizon
        velocity = interaction_step(out[:, k], velocity, goal, preferred, sim, params, dt)
        out[:, k + 1] = np.where(sim, out[:, k] + velocity * dt, out[:, k + 1])
    return out


def constant_velocity(windows: Windows) -> np.ndarray:
    """(W, H+2, N): the simulated people walking on at their velocity of the start."""
    sim = windows.simulated
    out: np.ndarray = windows.positions.copy()
    steps = np.arange(out.shape[1] - 1)[None, :, None]
    moved = out[:, 1:2] + (out[:, 1:2] - out[:, 0:1]) * steps
    out[:, 1:] = np.where(sim[:, None], moved, out[:, 1:])
    return out


def errors(windows: Windows, predicted: np.ndarray) -> tuple[float, float]:
    """ADE and FDE (m) of the simulated people over the horizon."""
    gap = np.abs(predicted[:, 2:] - windows.positions[:, 2:])
    mask = np.broadcast_to(windows.simulated[:, None], gap.shape)
    return float(gap[mask].mean()), float(gap[:, -1][windows.simulated].mean())


def statistics(windows: Windows, positions: np.ndarray) -> dict[str, float]:
    """Speed (median, IQR), closest distance (median, 10th percentile) and straightness (median) of the simulated people."""
    sim, dt = windows.simulated, windows.dt
    track = positions[:, 1:]
    speed = np.abs(np.diff(track, axis=1)) / dt
    speeds = speed[np.broadcast_to(sim[:, None], speed.shape)]
    distance = np.abs(track[:, :, :, None] - track[:, :, None, :])
    distance[:, :, np.arange(track.shape[2]), np.arange(track.shape[2])] = np.nan
    closest = np.nanmin(np.where(np.isnan(distance), np.inf, distance), axis=3)
    closest = closest[np.broadcast_to(sim[:, None], closest.shape)]
    closest = closest[np.isfinite(closest)]
    length = np.abs(np.diff(track, axis=1)).sum(1)[sim]
    net = np.abs(track[:, -1] - track[:, 0])[sim]
    straight = net[length > 0.1] / length[length > 0.1]
    q25, q50, q75 = np.percentile(speeds, [25, 50, 75])
    return {"speed median (m/s)": q50, "speed IQR (m/s)": q75 - q25,
            "closest distance median (m)": float(np.median(closest)) if len(closest) else np.nan,
            "closest distance 10th percentile (m)": float(np.percentile(closest, 10)) if len(closest) else np.nan,
            "straightness median": float(np.median(straight)) if len(straight) else np.nan}
