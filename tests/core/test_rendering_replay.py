"""Rendering a recorded crowd: an empty place (parked far outside the world) has no disc and no trail, so no line runs from
the parking place to where a person appears. The recording is written by the test (no data ships)."""

from __future__ import annotations

import numpy as np

from crowdnav import Simulator
from crowdnav.crowd.replay import empty_places
from crowdnav.rendering import Renderer
from crowdnav.rendering.renderer import present_runs

PEOPLE = {k + 1: (3.0 * k, 3.0 * k + 6.0, (-4 + (k % 3 - 1) * 2j) * (-1) ** k, (4 + (k % 3 - 1) * 2j) * (-1) ** k) for k in range(12)}
"""Someone enters every 3 s for 6 s along one of three lines, alternately left to right and right to left."""


def _write(path) -> None:
    rows = []
    for person, (t0, t1, a, b) in PEOPLE.items():
        for k in range(round(t0 / 0.4), round(t1 / 0.4) + 1):
            where = a + (b - a) * (k * 0.4 - t0) / (t1 - t0)
            rows.append((k * 10, person, where.real, where.imag))
    path.write_text("".join(f"{f}\t{p}\t{x:.4f}\t{y:.4f}\n" for f, p, x, y in sorted(rows)))


def test_present_runs_are_the_stretches_of_two_or_more_present_rows_per_column():
    present = np.array([[1, 0, 1], [1, 1, 1], [0, 1, 1], [1, 0, 0], [1, 1, 0]], dtype=bool)
    assert present_runs(present) == [(0, 0, 2), (0, 3, 5), (1, 1, 3), (2, 0, 3)]


def test_trails_are_drawn_only_between_present_positions_when_people_appear(tmp_path):
    _write(tmp_path / "walk.txt")
    sim = Simulator("open_space", {"humans.model": "replay", "humans.count": 4, "max_steps": 60,
                                   "humans.replay": {"file": str(tmp_path / "walk.txt")}})
    sim.reset(seed=0)
    renderer = Renderer(sim)
    trail = np.array(renderer.palette.human_trail)
    corners = renderer.to_pixels(np.array([complex(*sim.scenario.world.min), complex(*sim.scenario.world.max)]))
    (left, bottom), (right, top) = corners.astype(int)
    history: list[np.ndarray] = []
    appeared = 0
    for _ in range(40):
        renderer.record()
        history.append(sim.human_positions.copy())
        recent = np.array(history[-renderer.options.trail_length :])
        shown = ~empty_places(recent)
        appeared += int((~shown[:-1] & shown[1:]).sum()) if len(recent) > 1 else 0
        frame = renderer.frame()
        rows, columns = np.nonzero((frame[top:bottom, left:right] == trail).all(axis=2))
        points = renderer.to_pixels(recent[shown])  # (k, 2): where present people were
        steps = np.abs(np.diff(recent, axis=0))[shown[1:] & shown[:-1]]
        reach = (steps.max() if len(steps) else 0.0) * renderer.scale + 3  # a pixel of a drawn segment lies this near an end
        pixels = np.column_stack([columns + left, rows + top])
        if len(pixels):
            nearest = np.linalg.norm(pixels[:, None, :] - points[None, :, :], axis=2).min(axis=1)
            assert nearest.max() <= reach, "a trail pixel lies away from every present position (a line from the parking place)"
        sim.step(np.zeros(2))
    assert appeared >= 1  # the window shows someone entering a place while the trail remembers the empty steps
