"""The recorded crowd (``model: replay``): humans follow recorded pedestrians (:mod:`crowdnav.crowd.recording`).

The replaying group's ``count`` is its number of *places*: each recorded person of the episode's
window takes a free place from the step they appear to the step they leave (the lowest free
place first, in order of appearance), so people appear and leave as the recording says. An
episode is a window of the recording, ``max_steps + 1`` time steps long, whose first step is drawn
from the episode's generator (the same seed, the same window). A place nobody holds is parked at
:func:`parked`, far outside any world, where no sensor, contact or force reaches.

The model places its humans instead of commanding them: after the step's overlap pushes, each
human of the group is put at its person's recorded position (resampled to the time step by
linear interpolation) with the recorded velocity (the difference to the next position over the
time step; at a person's last step, from the one before). They are *stopped* humans for the rest
of the simulator (no command, no goal rule, no stall check), and they ignore the robot.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from crowdnav.crowd.base import CrowdModel, CrowdView
from crowdnav.crowd.recording import Resampled, read_recording
from crowdnav.errors import CrowdNavError
from crowdnav.world import CompiledWorld

PARKING = complex(2.0e7, 2.0e7)
"""Where the first empty place waits (m); the others wait 10 m apart along x from it."""


def parked(places: int) -> np.ndarray:
    """(places,) complex: the parking spot of every place, 10 m apart, far outside any world."""
    spots: np.ndarray = PARKING + 10.0 * np.arange(places)
    return spots


class ReplayError(CrowdNavError, ValueError):
    """The recording does not fit the scenario (more people at once than the group has places)."""


class ReplayModel(CrowdModel):
    """One world's recorded crowd: the recording on the scenario's time grid and this episode's places."""

    name = "replay"
    places = True

    def __init__(self, world: CompiledWorld):
        super().__init__(world)
        humans = world.scenario.humans
        settings = humans.replay
        assert settings is not None  # the schema asks for it with model: replay
        label = world.source.label if world.source is not None else ""
        folder = Path(label).parent if label and Path(label).is_file() else None
        recording = read_recording(settings.file, settings.format, settings.annotation_step, folder)
        self._grid: Resampled = recording.resample(self.dt)
        self._offset = complex(settings.offset[0], settings.offset[1])
        self._steps = world.scenario.max_steps + 1
        crowd = [group for _, group in humans.crowd]
        self._group = next(i for i, group in enumerate(crowd) if not group.standing and group.model == "replay")
        count = crowd[self._group].count
        assert isinstance(count, int)  # the schema refuses a range
        self.count = count
        peak = self._peak()
        if peak > count:
            raise ReplayError(f"model replay: the recording {settings.file} shows up to {peak} people at once in a window of "
                              f"{self._steps} steps; the group has {count} places: expected count >= {peak}")
        self.start = 0
        self._positions = np.zeros((self._steps, count), dtype=complex)
        self._velocities = np.zeros((self._steps, count), dtype=complex)

    def _peak(self) -> int:
        """The most people present at one time step of the recording."""
        present = np.zeros(self._grid.steps + 1, dtype=np.int64)
        for track in self._grid.tracks:  # per person, once per load
            present[track.start] += 1
            present[track.start + len(track.positions)] -= 1
        return int(np.cumsum(present).max()) if len(self._grid.tracks) else 0

    def start_episode(self, view: CrowdView, rng: np.random.Generator) -> None:
        """Draw the episode's window and give each of its people a place for as long as they are recorded."""
        steps, dt = self._steps, self.dt
        self.start = self._grid.window_start(rng, steps)
        """The recording's time step (of the scenario's ``dt``) this episode starts at."""
        _, positions, present = self._grid.window(self.start, steps)
        places = np.broadcast_to(parked(self.count), (steps, self.count)).copy()
        velocities = np.zeros((steps, self.count), dtype=complex)
        free_from = np.zeros(self.count, dtype=np.int64)  # the first step each place is free again
        for person in range(positions.shape[1]):  # per recorded person of the window, once per episode
            there = np.flatnonzero(present[:, person])
            first, last = int(there[0]), int(there[-1])
            place = int(np.flatnonzero(free_from <= first)[0])  # exists: the peak fits the places
            free_from[place] = last + 1
            track = positions[first : last + 1, person] + self._offset
            places[first : last + 1, place] = track
            if len(track) > 1:
                step = np.diff(track) / dt
                velocities[first:last, place] = step
                velocities[last, place] = step[-1]
        self._positions, self._velocities = places, velocities

    def commands(self, view: CrowdView) -> np.ndarray:
        return np.zeros(len(view.human_group), dtype=complex)  # placed, not commanded (and stopped)

    def place(self, view: CrowdView) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The group's humans (indices among the humans) with their recorded positions and velocities at this step."""
        step = min(int(view.step_count), self._steps - 1)
        index = np.flatnonzero(view.human_group == self._group)
        return index, self._positions[step], self._velocities[step]
