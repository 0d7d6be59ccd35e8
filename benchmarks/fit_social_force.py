"""Check crowdnav's social force against recorded people, and fit it (issue 40 item 4).

    python -m benchmarks.fit_social_force RECORDING [--format auto|obsmat|frames|trajnet] [--horizon 4.8] [--out table.md]
    python -m benchmarks.fit_social_force --synthetic walkers.txt   # write a synthetic obsmat recording, then check it

From a recording (:mod:`crowdnav.crowd.recording`, on a grid of ``--time-step``, default the
annotation step 0.4 s) it cuts windows: every ``--stride`` steps, the people present from one
step before the window's start to ``--horizon`` seconds after it are *simulated*: the social
force (the kernels of :mod:`crowdnav.social_force`, the simulator's step without the overlap
pushes) starts from each one's recorded position and velocity (the step before) and walks toward
its recorded position at the horizon's end (its destination known, as in the social-force
baselines of trajectory-prediction benchmarks), among the other people at their recorded
positions (those not present for the whole window) and each other. It reports, as a markdown table:

- the speed distribution (median, IQR), the closest distance to anyone else (median, 10th
  percentile) and the path straightness (net displacement / path length, median) of the
  simulated people, recorded and simulated;
- ADE and FDE (mean and final displacement errors, m) of the social force with the ``default``
  humans' parameters (preferred speed 1.0 m/s, the middle of ``humans.preferred_speed``'s
  [0.8, 1.2]; ``humans.social_force``'s defaults), of the best parameters of a grid search
  (preferred speed, relaxation time, human_strength) minimizing ADE, and of constant velocity.

No recording ships with crowdnav; docs/simulator.md says where the public ones are and what
is (not) measured here.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crowdnav import social_force as sf
from crowdnav.crowd.recording import read_recording
from crowdnav.files import atomic_write_text
from crowdnav.scenario.crowd import SocialForce

DEFAULT_PREFERRED_SPEED = 1.0
"""The middle of the default humans.preferred_speed [0.8, 1.2] (m/s)."""
RADIUS = 0.3
"""Every person's body radius (m), humans.radius's default."""
GRID = {"preferred_speed": (0.6, 0.8, 1.0, 1.2, 1.4, 1.6), "relaxation_time": (0.25, 0.5, 1.0, 2.0),
        "human_strength": (0.5, 1.0, 2.0, 4.0)}
"""The fit's grid."""


@dataclass
class Params:
    preferred_speed: float
    relaxation_time: float
    human_strength: float


DEFAULT = Params(DEFAULT_PREFERRED_SPEED, SocialForce().relaxation_time, SocialForce().human_strength)


@dataclass
class Windows:
    """W windows of H+2 grid steps (one before the start, the start, H ahead) over N people each (NaN: absent)."""

    positions: np.ndarray
    """(W, H+2, N) complex recorded positions."""
    simulated: np.ndarray
    """(W, N) bool: present for the whole window, so simulated and scored."""
    dt: float


def cut_windows(path: str | Path, fmt: str = "auto", annotation_step: float = 0.4, time_step: float | None = None,
                horizon: float = 4.8, stride: int = 2) -> Windows:
    """The windows of a recording (see the module docstring)."""
    recording = read_recording(path, fmt, annotation_step)  # type: ignore[arg-type]
    dt = time_step or annotation_step
    grid = recording.resample(dt)
    dense = np.full((grid.steps, len(grid.tracks)), np.nan + 0j)
    for column, track in enumerate(grid.tracks):  # per person, once
        dense[track.start : track.start + len(track.positions), column] = track.positions
    ahead = round(horizon / dt)
    cuts, full = [], []
    for start in range(1, grid.steps - ahead, stride):  # per window
        block = dense[start - 1 : start + ahead + 1]
        there = ~np.isnan(block.real)
        columns = np.flatnonzero(there.any(0))
        if there[:, columns].all(0).any():
            cuts.append(block[:, columns])
            full.append(there[:, columns].all(0))
    if not cuts:
        raise ValueError(f"{path}: nobody is recorded for {horizon:g} s plus a step; expected longer tracks or a shorter --horizon")
    people = max(cut.shape[1] for cut in cuts)
    positions = np.full((len(cuts), ahead + 2, people), np.nan + 0j)
    simulated = np.zeros((len(cuts), people), dtype=bool)
    for w, (cut, mask) in enumerate(zip(cuts, full, strict=True)):  # per window
        positions[w, :, : cut.shape[1]] = cut
        simulated[w, : cut.shape[1]] = mask
    return Windows(positions, simulated, dt)


def rollout(windows: Windows, params: Params, force: SocialForce | None = None) -> np.ndarray:
    """(W, H+2, N) complex: the recorded positions with the simulated people's replaced by the social force's, all windows at once."""
    force = force or SocialForce()
    dt, out = windows.dt, windows.positions.copy()
    sim = windows.simulated
    velocity = np.where(sim, (out[:, 1] - out[:, 0]) / dt, 0)
    goal = out[:, -1]
    gain = sf.repulsion_gain(params.human_strength, 2 * RADIUS, force.human_range)
    relax = min(1.0, dt / params.relaxation_time)
    people = out.shape[2]
    for k in range(1, out.shape[1] - 1):  # per step of the horizon
        now = out[:, k]
        offset = now[:, None, :] - now[:, :, None]  # (W, N, N): from each person to every other
        distance = np.abs(offset)
        void = np.isnan(distance) | np.eye(people, dtype=bool)
        total = sf.goal_force(np.where(sim, goal - now, 0), force.goal_weight, force.goal_saturation_distance)
        total += sf.repulsion(np.where(void, 0, offset), np.where(void, 1.0, distance), np.where(void, 0.0, gain), -1.0 / force.human_range)
        velocity = sf.velocity_command(np.where(sim, total, 0), velocity, params.preferred_speed,
                                       params.preferred_speed * force.max_speed_factor, relax)
        out[:, k + 1] = np.where(sim, now + velocity * dt, out[:, k + 1])
    return out


def constant_velocity(windows: Windows) -> np.ndarray:
    """(W, H+2, N): the simulated people walking on at their velocity of the start."""
    out, sim = windows.positions.copy(), windows.simulated
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


def fit(windows: Windows, grid: dict[str, tuple[float, ...]] = GRID) -> tuple[Params, float]:
    """The grid's parameters with the least ADE, and that ADE."""
    best, best_ade = DEFAULT, np.inf
    for values in itertools.product(*grid.values()):  # per grid point
        params = Params(**dict(zip(grid, values, strict=True)))
        ade, _ = errors(windows, rollout(windows, params))
        if ade < best_ade:
            best, best_ade = params, ade
    return best, best_ade


def report(windows: Windows, source: str) -> str:
    """The markdown table of the check and the fit."""
    best, _ = fit(windows)
    columns = {"recorded": windows.positions, "social force, default": rollout(windows, DEFAULT),
               "social force, fit": rollout(windows, best), "constant velocity": constant_velocity(windows)}
    stats = {name: statistics(windows, positions) for name, positions in columns.items()}
    lines = [f"Recording {source}: {len(windows.positions)} windows of {(windows.positions.shape[1] - 2) * windows.dt:g} s, "
             f"{int(windows.simulated.sum())} simulated people, time step {windows.dt:g} s.", "",
             f"Fit (least ADE on the grid): preferred_speed {best.preferred_speed:g} m/s, relaxation_time {best.relaxation_time:g} s, "
             f"human_strength {best.human_strength:g}; default: {DEFAULT.preferred_speed:g}, {DEFAULT.relaxation_time:g}, "
             f"{DEFAULT.human_strength:g}.", "",
             "| statistic | " + " | ".join(columns) + " |", "|---|" + "---:|" * len(columns)]
    for key in stats["recorded"]:
        lines.append(f"| {key} | " + " | ".join(f"{stats[name][key]:.3f}" for name in columns) + " |")
    for k, key in enumerate(("ADE (m)", "FDE (m)")):
        cells = ["-" if name == "recorded" else f"{errors(windows, positions)[k]:.3f}" for name, positions in columns.items()]
        lines.append(f"| {key} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_synthetic_obsmat(path: str | Path, walkers: int = 36, seed: int = 0, preferred_speed: float = 1.3,
                           relaxation_time: float = 0.5, human_strength: float = 2.0) -> None:
    """A synthetic ETH/UCY obsmat recording: ``walkers`` people entering every 0.8 s at x = -8 or 8 (random y in [-4, 4]),
    crossing to the other side, simulated by the social force with these parameters at 0.1 s and annotated every 0.4 s
    (frames every 10, as ETH/UCY). A stand-in for real data in tests and examples: it measures nothing about people."""
    rng = np.random.default_rng(seed)
    force, dt = SocialForce(), 0.1
    side = rng.choice([-1.0, 1.0], walkers)
    start = side * 8 + 1j * rng.uniform(-4, 4, walkers)
    goal = -side * 8 + 1j * rng.uniform(-4, 4, walkers)
    enter = np.round(np.arange(walkers) * 8).astype(int)  # sim steps (0.8 s apart)
    position = np.full(walkers, np.nan + 0j)
    velocity = np.zeros(walkers, dtype=complex)
    gone = np.zeros(walkers, dtype=bool)
    gain = sf.repulsion_gain(human_strength, 2 * RADIUS, force.human_range)
    rows = []
    for step in range(enter[-1] + 400):  # per simulated step
        new = (enter == step)
        position[new], velocity[new] = start[new], 0
        here = ~np.isnan(position.real)
        offset = position[None, :] - position[:, None]
        distance = np.abs(offset)
        void = ~(here[:, None] & here[None, :]) | np.eye(walkers, dtype=bool)
        total = sf.goal_force(np.where(here, goal - position, 0), force.goal_weight, force.goal_saturation_distance)
        total += sf.repulsion(np.where(void, 0, offset), np.where(void, 1.0, distance), np.where(void, 0.0, gain), -1.0 / force.human_range)
        velocity = np.where(here, sf.velocity_command(total, velocity, preferred_speed, preferred_speed * force.max_speed_factor,
                                                      min(1.0, dt / relaxation_time)), 0)
        position = np.where(here, position + velocity * dt, position)
        if step % 4 == 0:
            rows.extend((step // 4 * 10, int(i) + 1, position[i]) for i in np.flatnonzero(here))
        arrived = here & (np.abs(goal - position) < 0.3)
        gone |= arrived
        position[arrived] = np.nan
        if gone.all():
            break
    rows.sort(key=lambda row: (row[0], row[1]))
    atomic_write_text(path, "".join(f"{f:.7e} {p:.7e} {z.real:.7e} 0.0000000e+00 {z.imag:.7e} 0 0 0\n" for f, p, z in rows))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("recording", nargs="?", help="an ETH/UCY obsmat.txt, a frame id x y file or TrajNet++ ndjson")
    parser.add_argument("--format", default="auto", choices=("auto", "obsmat", "frames", "trajnet"))
    parser.add_argument("--annotation-step", type=float, default=0.4, help="seconds between annotations (ETH/UCY: 0.4)")
    parser.add_argument("--time-step", type=float, default=None, help="the grid's step (default: the annotation step)")
    parser.add_argument("--horizon", type=float, default=4.8, help="seconds simulated from each recorded state (default 4.8)")
    parser.add_argument("--stride", type=int, default=2, help="grid steps between two windows' starts (default 2)")
    parser.add_argument("--synthetic", type=Path, metavar="FILE", help="write a synthetic obsmat recording to FILE and check it")
    parser.add_argument("--out", type=Path, help="also write the table to this file")
    args = parser.parse_args(argv)
    if args.synthetic is not None:
        write_synthetic_obsmat(args.synthetic)
        args.recording = str(args.synthetic)
    if args.recording is None:
        parser.error("give a RECORDING or --synthetic FILE")
    try:
        windows = cut_windows(args.recording, args.format, args.annotation_step, args.time_step, args.horizon, args.stride)
    except ValueError as error:
        print(f"fit_social_force: error: {str(error).splitlines()[0]}", file=sys.stderr)
        return 1
    table = report(windows, Path(args.recording).name)
    print(table, end="")
    if args.out is not None:
        atomic_write_text(args.out, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
