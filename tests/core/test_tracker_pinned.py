"""The people tracker's outputs are pinned bit for bit: published results (the ``*_lidar_tracker`` tracks) depend on every
track and every draw, so a faster tracker must report exactly what the first one did.

The digests were recorded with the tracker as first published (before its speed-up of 2026-12-07) on moving people
fed to the tracker directly, so they pin the tracker alone, whatever the simulator does.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from crowdnav.scenario.tracker import TRACKER_PROFILES
from crowdnav.sensors.tracker import PeopleTracker
from crowdnav.worlds.compiled import load_world

PINNED = [("lidar_tracker", 1, "e501fef95f9718a9"), ("lidar_tracker", 6, "e34612fa69c08510"),
          ("camera_front", 1, "ae9bf3ae877edff8"), ("camera_front", 6, "76205fa289bed4fb")]


def tracks_digest(profile: str, worlds: int, steps: int = 80, n: int = 10) -> str:
    """A hash of the readers' columns after each of ``steps`` updates of people wandering in room_furniture (furniture
    and people occlude), respawning now and then, with new episodes and updates of a subset of the worlds."""
    world, values = load_world("room_furniture"), TRACKER_PROFILES[profile]
    assert values is not None
    track = PeopleTracker(world, values, worlds)
    (x0, y0), (x1, y1) = world.scenario.world.min, world.scenario.world.max
    rng = np.random.default_rng(0)

    def anywhere(shape: tuple[int, ...] | int) -> np.ndarray:
        return rng.uniform(x0 + 0.5, x1 - 0.5, shape) + 1j * rng.uniform(y0 + 0.5, y1 - 0.5, shape)

    positions, heading, radii = anywhere((worlds, n + 1)), rng.uniform(-np.pi, np.pi, worlds), np.full(n + 1, 0.3)
    every = np.arange(worlds)
    digest = hashlib.sha256()
    track.start(every, list(range(worlds)))
    for step in range(steps):
        if step and step % 25 == 0:  # new episodes in some worlds (seedless: the next episode of their seed)
            again = every[rng.random(worlds) < 0.5]
            if len(again):
                track.start(again, [None] * len(again))
        rows = every if step % 7 else every[rng.random(worlds) < 0.7]  # now and then a subset of the worlds
        if len(rows):
            track.update(rows, positions[rows], np.zeros(len(rows), complex), heading[rows], radii)
        for values in track.columns(every, n):
            digest.update(np.ascontiguousarray(values).tobytes())
        positions += rng.normal(0, 0.08, positions.shape) + 1j * rng.normal(0, 0.08, positions.shape)
        jump = rng.random(positions.shape) < 0.01  # a person respawns elsewhere: a new track
        positions[jump] = anywhere(int(jump.sum()))
        positions.real.clip(x0 + 0.3, x1 - 0.3, out=positions.real)
        positions.imag.clip(y0 + 0.3, y1 - 0.3, out=positions.imag)
        heading += rng.normal(0, 0.2, worlds)
    return digest.hexdigest()[:16]


@pytest.mark.parametrize(("profile", "worlds", "pinned"), PINNED)
def test_the_trackers_reports_are_those_it_first_published_bit_for_bit(profile, worlds, pinned):
    assert tracks_digest(profile, worlds) == pinned
