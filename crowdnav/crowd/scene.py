"""A scenario around a recording (``crowdnav scenario from-recording``): bounds, entry areas and a robot route from the data.

:func:`scenario_from_recording` reads a recording (:mod:`crowdnav.crowd.recording`) and returns a
scenario (a plain dict, written as YAML by the command) whose crowd replays it:

- **world**: the box of every recorded position with a ``margin`` (1 m), at least 4 m a side,
  no boundary walls (a robot that leaves ends its episode out of bounds);
- **humans**: ``model: replay`` on the file, ``count`` the places the recording needs
  (:func:`crowdnav.crowd.replay.places_needed`), ``preferred_speed`` the quartiles of the people's
  mean speeds (what reacting people walk at), ``spawn`` the areas where people enter (the box of
  the first positions nearest each side of the world) and ``goal`` those where they leave;
- **robot**: a route across the main flow. The flow's axis is the people's mean direction of
  travel taken as an axis (angles doubled, so people walking both ways add up, weighted by how
  far they walk): if people walk mostly along x, the robot starts in a 1 m strip near the bottom
  (low y) with its goal in one near the top, else from the left to the right; both strips span
  the middle half of the other axis.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.crowd.recording import DEFAULT_ANNOTATION_STEP, RecordingFormat, read_recording, resolve_path
from crowdnav.crowd.replay import places_needed

MIN_SIDE = 4.0
"""The world is at least this wide and tall (m)."""


def scenario_from_recording(path: str | Path, fmt: RecordingFormat = "auto", annotation_step: float = DEFAULT_ANNOTATION_STEP, *,
                            out: str | Path | None = None, time_step: float = 0.2, max_steps: int | None = None,
                            margin: float = 1.0) -> dict[str, Any]:
    """The scenario (dict) replaying recording ``path``; ``out``: where it will be written (the file is then named relative to
    it when inside its folder, else by its absolute path). ``max_steps``: default the recording's length, at most 150."""
    file = resolve_path(path, None)
    recording = read_recording(file, fmt, annotation_step)
    grid = recording.resample(time_step)
    if not grid.tracks:
        raise ValueError(f"{path}: no person is recorded for a whole time step of {time_step:g} s")
    points = np.concatenate([track.positions for track in grid.tracks])
    low = np.array([points.real.min(), points.imag.min()]) - margin
    high = np.array([points.real.max(), points.imag.max()]) + margin
    grow = np.maximum(MIN_SIDE - (high - low), 0.0) / 2
    low, high = low - grow, high + grow
    steps = max_steps if max_steps is not None else max(1, min(150, grid.steps - 1))
    along_x = _flow_along_x(grid.tracks)
    first = np.array([track.positions[0] for track in grid.tracks])
    last = np.array([track.positions[-1] for track in grid.tracks])
    speeds = np.array([np.abs(np.diff(track.positions)).mean() / time_step for track in grid.tracks if len(track.positions) > 1])
    walking = speeds[speeds > 0.1] if (speeds > 0.1).any() else np.array([0.5, 1.3])
    slow, fast = (round(float(q), 2) for q in np.percentile(walking, [25, 75]))
    start, goal, distance = _route(low, high, along_x)
    if out is not None and resolve_within(file, Path(out).resolve().parent):
        named = str(file.relative_to(Path(out).resolve().parent))
    else:
        named = str(file)
    return {
        "description": f"Recorded crowd of {file.name}: {len(grid.tracks)} people over {recording.duration:.0f} s, replayed "
                       f"({'along x' if along_x else 'along y'} mostly); the robot crosses their main flow.",
        "world": {"min": _pair(low), "max": _pair(high), "boundary_walls": False},
        "robot": {"radius": 0.3, "kinematics": "holonomic", "max_speed": 1.0, "start": start, "goal": goal, "goal_radius": 0.3,
                  "min_start_goal_distance": distance},
        "humans": {
            "count": places_needed(grid),
            "radius": 0.3,
            "preferred_speed": [max(0.1, slow), max(0.1, fast)],
            "spawn": _side_areas(first, low, high),
            "goal": _side_areas(last, low, high),
            "model": "replay",
            "replay": {"file": named, "format": recording.format, "annotation_step": annotation_step},
        },
        "time_step": time_step,
        "max_steps": int(steps),
    }


def resolve_within(file: Path, folder: Path) -> bool:
    """Whether ``file`` lies inside ``folder`` (both resolved)."""
    return file.resolve().is_relative_to(folder.resolve())


def _flow_along_x(tracks: list[Any]) -> bool:
    """Whether people walk mostly along x: their displacements' directions as an axis (doubled angles), weighted by length."""
    moves = np.array([track.positions[-1] - track.positions[0] for track in tracks])
    moves = moves[np.abs(moves) > 1e-9]
    if not len(moves):
        return True
    axis = (moves**2 / np.abs(moves)).sum()  # |m| * exp(2i * angle): opposite walkers add up
    return abs(math.cos(np.angle(axis) / 2)) >= abs(math.sin(np.angle(axis) / 2))


def _route(low: np.ndarray, high: np.ndarray, along_x: bool) -> tuple[dict[str, Any], dict[str, Any], float]:
    """Start and goal strips across the flow (1 m deep, 0.3 m inside the world, the middle half of the other axis) and the
    least start-goal distance they allow."""
    across = 1 if along_x else 0  # the robot travels along this axis
    other = 1 - across
    span_low = low[other] + (high[other] - low[other]) / 4
    span_high = high[other] - (high[other] - low[other]) / 4

    def strip(a: float, b: float) -> dict[str, Any]:
        lo, hi = [0.0, 0.0], [0.0, 0.0]
        lo[across], hi[across] = a, b
        lo[other], hi[other] = span_low, span_high
        return {"type": "rectangle", "min": [round(float(v), 3) for v in lo], "max": [round(float(v), 3) for v in hi]}

    start = strip(low[across] + 0.3, low[across] + 1.3)
    goal = strip(high[across] - 1.3, high[across] - 0.3)
    gap = (high[across] - 1.3) - (low[across] + 1.3)
    return start, goal, round(float(max(0.5, 0.8 * gap)), 2)


def _side_areas(points: np.ndarray, low: np.ndarray, high: np.ndarray) -> list[dict[str, Any]]:
    """Rectangles around the points nearest each side of the world (0.5 m padding, inside the world), sides without points left out."""
    gaps = np.stack([points.real - low[0], high[0] - points.real, points.imag - low[1], high[1] - points.imag])
    side = gaps.argmin(axis=0)
    areas = []
    for k in range(4):
        mine = points[side == k]
        if not len(mine):
            continue
        lo = np.maximum([mine.real.min() - 0.5, mine.imag.min() - 0.5], low + 0.3)
        hi = np.minimum([mine.real.max() + 0.5, mine.imag.max() + 0.5], high - 0.3)
        hi = np.maximum(hi, lo + 0.1)
        areas.append({"type": "rectangle", "min": _pair(lo), "max": _pair(hi)})
    return areas


def _pair(values: np.ndarray) -> list[float]:
    return [round(float(v), 3) for v in values]
