"""Fit the social force to recorded people (issue 52 item 1): ``crowdnav scenario fit RECORDING``.

The model and its windows are :mod:`crowdnav.crowd.fit_model`. The fit minimises the ADE of the
simulated people over the *training* windows (the first part of the recording) with scipy's
bounded Nelder-Mead in the unit cube (log scale for the positive parameters, see :data:`SPACE`),
from the default humans' values; the figures it reports (ADE, FDE, the distribution statistics)
are measured on the *held-out* windows (the last part, no recorded step shared with training). A
parameter that ends within 1% of its search interval (in the search's scale) of a bound is
reported in a warning line: the optimum may lie outside the space searched. scipy is the ``fit``
extra (docs/simulator.md#fitting-the-social-force-to-people says why).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from crowdnav.crowd.fit_model import (
    DEFAULT,
    RADIUS,
    Params,
    Windows,
    constant_velocity,
    errors,
    interaction_step,
    preferred_speeds,
    rollout,
    statistics,
)
from crowdnav.files import atomic_write_text


@dataclass(frozen=True)
class Bound:
    low: float
    high: float
    log: bool

    def to_unit(self, value: float) -> float:
        lo, hi, x = (math.log(self.low), math.log(self.high), math.log(value)) if self.log else (self.low, self.high, value)
        return min(1.0, max(0.0, (x - lo) / (hi - lo)))

    def from_unit(self, unit: float) -> float:
        lo, hi = (math.log(self.low), math.log(self.high)) if self.log else (self.low, self.high)
        value = lo + min(1.0, max(0.0, unit)) * (hi - lo)
        return math.exp(value) if self.log else value


SPACE = {"speed_low": Bound(0.05, 2.0, True), "speed_width": Bound(0.0, 1.5, False), "relaxation_time": Bound(0.1, 5.0, True),
         "human_strength": Bound(0.01, 20.0, True), "human_range": Bound(0.05, 3.0, True), "anisotropy": Bound(0.0, 1.0, False)}
"""The searched space: preferred speeds uniform on [speed_low, speed_low + speed_width] (m/s), relaxation time (s), human repulsion strength
(dimensionless, at contact) and range (m), anisotropy lambda (1: isotropic, crowdnav's humans)."""
EDGE = 0.01
"""A fitted value within this share of its interval (search scale) from a bound gets a warning."""


@dataclass
class Fit:
    params: Params
    train_ade: float
    evaluations: int
    fitted: tuple[str, ...]

    def warnings(self) -> list[str]:
        """One line per fitted parameter that ended on (within 1% of) a bound of :data:`SPACE`."""
        lines = []
        for name in self.fitted:
            bound, value = SPACE[name], getattr(self.params, name)
            unit = bound.to_unit(value)
            if unit <= EDGE or unit >= 1 - EDGE:
                side, edge = ("lower", bound.low) if unit <= EDGE else ("upper", bound.high)
                lines.append(f"warning: {name} ended at {value:.4g}, on its {side} bound {edge:g}: the best value may lie outside "
                             f"[{bound.low:g}, {bound.high:g}]")
        return lines


def fit(windows: Windows, fixed: dict[str, float] | None = None, max_evaluations: int = 400, tolerance: float = 1e-3) -> Fit:
    """The parameters of :data:`SPACE` (less ``fixed``) with the least ADE on ``windows``, by bounded Nelder-Mead from the default."""
    from scipy.optimize import minimize  # the fit extra; the rest of crowdnav runs without scipy

    fixed = fixed or {}
    unknown = sorted(set(fixed) - set(SPACE))
    if unknown:
        raise ValueError(f"cannot fix {', '.join(unknown)}: expected one of {', '.join(SPACE)}")
    names = tuple(name for name in SPACE if name not in fixed)
    start = replace(DEFAULT, preferred_speed=None, **fixed)

    def params_at(unit: np.ndarray) -> Params:
        return replace(start, **{name: SPACE[name].from_unit(float(u)) for name, u in zip(names, unit, strict=True)})

    def ade(unit: np.ndarray) -> float:
        return errors(windows, rollout(windows, params_at(unit)))[0]

    x0 = np.array([SPACE[name].to_unit(getattr(start, name)) for name in names])
    x0 = np.clip(x0, 0.05, 0.95)  # lambda = 1 (isotropic) starts inside, so the simplex can move both ways
    result = minimize(ade, x0, method="Nelder-Mead", bounds=[(0.0, 1.0)] * len(names),
                      options={"maxfev": max_evaluations, "xatol": tolerance, "fatol": tolerance * 1e-1, "adaptive": True})
    return Fit(params_at(result.x), float(result.fun), int(result.nfev), names)


def describe(params: Params, names: tuple[str, ...]) -> str:
    return ", ".join(f"{name} {getattr(params, name):.3g}" for name in names)


def report(train: Windows, test: Windows, source: str, fixed: dict[str, float] | None = None, max_evaluations: int = 400) -> str:
    """The fit on ``train`` and the markdown table of ``test``: recorded, default humans, fit, constant velocity."""
    result = fit(train, fixed, max_evaluations)
    columns = {"recorded": test.positions, "social force, default": rollout(test, DEFAULT),
               "social force, fit": rollout(test, result.params), "constant velocity": constant_velocity(test)}
    stats = {name: statistics(test, positions) for name, positions in columns.items()}
    speeds = preferred_speeds(train, result.params)[train.simulated]
    q10, q50, q90 = np.percentile(speeds, [10, 50, 90])
    horizon = (train.positions.shape[1] - 2) * train.dt
    lines = [f"Recording {source}: windows of {horizon:g} s at a time step of {train.dt:g} s; fitted on {len(train.positions)} "
             f"training windows ({int(train.simulated.sum())} simulated people), figures on {len(test.positions)} held-out windows "
             f"({int(test.simulated.sum())} people, the recording's last part).", "",
             f"Fit (bounded Nelder-Mead, {result.evaluations} rollouts, training ADE {result.train_ade:.3f} m): "
             f"{describe(result.params, result.fitted)}" + (f"; fixed: {describe(result.params, tuple(fixed))}" if fixed else "") + ".",
             f"Preferred speeds (quantile-mapped, training windows): 10th percentile {q10:.2f}, median {q50:.2f}, 90th percentile "
             f"{q90:.2f} m/s; in a scenario: humans.preferred_speed [{result.params.speed_low:.2f}, "
             f"{result.params.speed_low + result.params.speed_width:.2f}].", *result.warnings(), "",
             "| statistic | " + " | ".join(columns) + " |", "|---|" + "---:|" * len(columns)]
    for key in stats["recorded"]:
        lines.append(f"| {key} | " + " | ".join(f"{stats[name][key]:.3f}" for name in columns) + " |")
    for k, key in enumerate(("ADE (m)", "FDE (m)")):
        cells = ["-" if name == "recorded" else f"{errors(test, positions)[k]:.3f}" for name, positions in columns.items()]
        lines.append(f"| {key} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def write_synthetic_obsmat(path: str | Path, walkers: int = 48, seed: int = 0, params: Params | None = None,
                           speeds: tuple[float, float] = (0.9, 1.5), every: float = 0.8, dt: float = 0.4) -> None:
    """A synthetic ETH/UCY obsmat recording made by the fit's own model (so a fit can recover ``params``): ``walkers`` people
    entering every ``every`` s at x = -8 or 8 (random y in [-4, 4]), each with a preferred speed uniform in ``speeds``,
    crossing to a random point of the other side, until 10 s after the last one entered (a recording's tail of the last
    few, some stuck face to face, would be another crowd than its body), stepped by :func:`interaction_step` at ``dt`` and annotated every step
    (frames 10 apart, as ETH/UCY). A stand-in for real data in tests and examples: it measures nothing about people."""
    params = params or Params(relaxation_time=0.5, human_strength=2.0, human_range=0.3, anisotropy=1.0)
    rng = np.random.default_rng(seed)
    side = rng.choice([-1.0, 1.0], walkers)
    start = side * 8 + 1j * rng.uniform(-4, 4, walkers)
    goal = -side * 8 + 1j * rng.uniform(-4, 4, walkers)
    preferred = rng.uniform(*speeds, walkers)
    enter = np.round(np.arange(walkers) * every / dt).astype(int)
    position = np.full(walkers, np.nan + 0j)
    velocity = np.zeros(walkers, dtype=complex)
    gone = np.zeros(walkers, dtype=bool)
    rows: list[tuple[int, int, complex]] = []
    for step in range(enter[-1] + round(10 / dt)):  # per simulated step; stops 10 s after the last entry, before the flow thins out
        new = enter == step
        position[new], velocity[new] = start[new], 0
        here = ~np.isnan(position.real)
        velocity = interaction_step(position, velocity, goal, preferred, here, params, dt)
        position = np.where(here, position + velocity * dt, position)
        rows.extend((step * 10, int(i) + 1, position[i]) for i in np.flatnonzero(here))
        arrived = here & (np.abs(goal - position) < RADIUS)
        gone |= arrived
        position[arrived] = np.nan
        if gone.all():
            break
    atomic_write_text(path, "".join(f"{f:.7e} {p:.7e} {z.real:.7e} 0.0000000e+00 {z.imag:.7e} 0 0 0\n" for f, p, z in rows))
