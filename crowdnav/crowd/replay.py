"""The recorded crowd (``model: replay``): humans follow recorded pedestrians (:mod:`crowdnav.crowd.recording`).

The replaying group's ``count`` is its number of *places*: each recorded person of the episode's
window takes a free place from the step they appear to the step they leave (the lowest free
place first, in order of appearance; a place stays empty for at least one step between two
people), so people appear and leave as the recording says. An
episode is a window of the recording, ``max_steps + 1`` time steps long, whose first step is drawn
from the episode's generator (the same seed, the same window). A place nobody holds is parked at
:func:`parked`, far outside any world, where no sensor, contact or force reaches.

The model places its humans instead of commanding them: after the step's overlap pushes, each
human of the group is put at its person's recorded position (resampled to the time step by
linear interpolation) with the recorded velocity (the difference to the next position over the
time step; at a person's last step, from the one before). They are *stopped* humans for the rest
of the simulator (no command, no goal rule, no stall check), and by default they ignore the robot.

**Reacting people** (``humans.replay.react_within``, metres): a recorded person whose centre is
within that distance of a robot's at a step reacts from the next step until its track ends: the
model moves it by the social force toward its own recorded position ``react_lookahead`` seconds
ahead (:mod:`crowdnav.crowd.react`), after the robot has moved; when its track ends its place is
parked (or taken by the next person) as in pure replay.

**The robot's start.** The window is drawn after the robot's start: a window in which a recorded
person stands within :data:`START_CLEARANCE` of a robot's start (surfaces) at the first step is
drawn again, up to :data:`WINDOW_TRIES` times (then the last draw is kept).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.crowd.base import CrowdModel, CrowdView
from crowdnav.crowd.react import Reaction
from crowdnav.crowd.recording import RecordingError, Resampled, read_recording
from crowdnav.errors import CrowdNavError
from crowdnav.scenario.crowd import MAX_REPLAY_CELLS, replay_cells
from crowdnav.worlds.compiled import CompiledWorld

PARKING = complex(2.0e7, 2.0e7)
"""Where the first empty place waits (m); the others wait 10 m apart along x from it."""
PARKED_BEYOND = 1.0e6
"""A place within this distance (m) of :data:`PARKING` is empty (:func:`empty_places`)."""
START_CLEARANCE = 0.5
"""Metres between a robot's start and every recorded person of the window's first step (surface to surface)."""
WINDOW_TRIES = 20
"""Windows drawn at most to find one whose first step leaves the robots' starts clear."""


def parked(places: int) -> np.ndarray:
    """(places,) complex: the parking spot of every place, 10 m apart, far outside any world."""
    spots: np.ndarray = PARKING + 10.0 * np.arange(places)
    return spots


def empty_places(positions: np.ndarray) -> np.ndarray:
    """Bool mask (``positions``' shape): the places nobody holds (parked near :data:`PARKING`), e.g. in recorded frames.

    The one test of "nobody is here" that every reader of human positions uses (metrics, rendering, trajectories): a
    parked place is far outside any world but still a position, so a reader that forgot it would measure 28,000 km.
    """
    empty: np.ndarray = np.abs(np.asarray(positions) - PARKING) < PARKED_BEYOND
    return empty


def places_needed(grid: Resampled) -> int:
    """The places a recording on a time grid needs: the most people present at one step, each counted one step longer (a
    place is empty for at least a step between two people, so every track of an export is one person's). Counted over the
    steps where someone comes or goes, never an array of the recording's whole span."""
    if not grid.tracks:
        return 0
    starts = np.array([track.start for track in grid.tracks], dtype=np.int64)
    ends = starts + np.array([len(track.positions) for track in grid.tracks], dtype=np.int64) + 1
    steps, where = np.unique(np.concatenate([starts, ends]), return_inverse=True)
    change = np.zeros(len(steps), dtype=np.int64)
    np.add.at(change, where, np.r_[np.ones(len(starts), dtype=np.int64), -np.ones(len(ends), dtype=np.int64)])
    return int(np.cumsum(change).max())


class ReplayError(CrowdNavError, ValueError):
    """The recording does not fit the scenario (more people at once than the group has places, or too much state per episode),
    or cannot be read; ``field``: the scenario field to name in the error (:class:`crowdnav.crowd.Crowd` reports it there)."""

    def __init__(self, message: str, field: str | None = None):
        super().__init__(message)
        self.field = field


def check_replay_state(places: int, max_steps: int) -> None:
    """ReplayError (one line) when an episode of ``places`` places over ``max_steps`` steps holds more than
    :data:`crowdnav.scenario.crowd.MAX_REPLAY_CELLS` (place, step) cells, before any is allocated."""
    cells = places * (max_steps + 1)
    if cells > MAX_REPLAY_CELLS:
        raise ReplayError(f"model replay: {places:,} places x {max_steps + 1:,} steps is {cells:,} (place, step) positions an "
                          f"episode, more than {MAX_REPLAY_CELLS:,}; expected fewer places (humans count) or a smaller max_steps")


class ReplayModel(CrowdModel):
    """One world's recorded crowd: the recording on the scenario's time grid and this episode's places."""

    name = "replay"
    places = True

    def __init__(self, world: CompiledWorld):
        super().__init__(world)
        humans = world.scenario.humans
        settings = humans.replay
        assert settings is not None  # the schema asks for it with model: replay
        crowd = [group for _, group in humans.crowd]
        self._group = next(i for i, group in enumerate(crowd) if not group.standing and group.model == "replay")
        count = crowd[self._group].count
        assert isinstance(count, int)  # the schema refuses a range
        check_replay_state(count, world.scenario.max_steps)  # a scenario built without validation (model_construct) too
        label = world.source.label if world.source is not None else ""
        folder = Path(label).parent if label and Path(label).is_file() else None
        try:
            self._grid: Resampled = read_recording(settings.file, settings.format, settings.annotation_step, folder).resample(self.dt)
        except RecordingError as error:  # named at the file's field, not at the model that asked for it
            raise ReplayError(str(error), "humans.replay.file") from None
        self._offset = complex(settings.offset[0], settings.offset[1])
        self._steps = world.scenario.max_steps + 1
        self.count = count
        peak = places_needed(self._grid)
        if peak > count:
            raise ReplayError(f"model replay: the recording {settings.file} needs {peak} places (the people it shows at once, "
                              f"a place empty for a step between two people); the group has {count}: expected count >= {peak}",
                              (replay_cells(humans, 0) or ("humans.count", 0))[0])
        self.react_within = settings.react_within
        """None: pure replay; else the distance (m) to a robot within which a recorded person starts reacting."""
        self._ahead = max(1, round(settings.react_lookahead / self.dt))
        self._reaction = Reaction(world) if self.react_within is not None else None
        self._clearance = humans.radius + world.scenario.robot.radius + START_CLEARANCE
        tracks = self._grid.tracks
        self._track_start = np.array([track.start for track in tracks], dtype=np.int64)
        self._track_length = np.array([len(track.positions) for track in tracks], dtype=np.int64)
        self._track_first = np.r_[0, np.cumsum(self._track_length)[:-1]].astype(np.int64)
        self._track_points = np.concatenate([np.zeros(0, dtype=complex), *(track.positions for track in tracks)])
        self.start = 0
        self._positions = np.zeros((self._steps, count), dtype=complex)
        self._velocities = np.zeros((self._steps, count), dtype=complex)
        self._targets = np.zeros((self._steps, count), dtype=complex)
        self._holder = np.full((self._steps, count), -1, dtype=np.int64)
        self.reacting = np.zeros(count, dtype=bool)
        """(count,) bool: the places whose person reacts to the robot now (always False in pure replay)."""
        self._moving = np.zeros(count, dtype=complex)

    def copy(self) -> ReplayModel:
        twin = copy.copy(self)
        twin.reacting, twin._moving = self.reacting.copy(), self._moving.copy()
        return twin

    def present_at(self, step: int) -> np.ndarray:
        """(P,) complex: where the people present at the recording's grid step ``step`` are (offset applied)."""
        there = (self._track_start <= step) & (step < self._track_start + self._track_length)
        points: np.ndarray = self._track_points[self._track_first[there] + step - self._track_start[there]] + self._offset
        return points

    def _draw_window(self, view: CrowdView, rng: np.random.Generator) -> int:
        """A window start whose first step leaves every robot's start clear (at most :data:`WINDOW_TRIES` draws)."""
        robots = view.agent_positions[: view.robot_count]
        start = 0
        for _ in range(WINDOW_TRIES):  # a few draws at most, once per episode
            start = self._grid.window_start(rng, self._steps)
            people = self.present_at(start)
            if not len(people) or np.abs(people[:, None] - robots[None, :]).min() >= self._clearance:
                break
        return start

    def start_episode(self, view: CrowdView, rng: np.random.Generator) -> None:
        """Draw the episode's window and give each of its people a place for as long as they are recorded."""
        self._lay_out(self._draw_window(view, rng))
        self.reacting = np.zeros(self.count, dtype=bool)
        self._moving = np.zeros(self.count, dtype=complex)

    def episode_state(self) -> dict[str, Any]:
        """The episode's window (its places follow from it) and who reacts now, at which velocity."""
        return {"start": int(self.start), "reacting": self.reacting.copy(), "moving": self._moving.copy()}

    def resume(self, view: CrowdView, state: Mapping[str, Any]) -> None:
        self._lay_out(int(state["start"]))
        self.reacting, self._moving = np.array(state["reacting"], dtype=bool), np.array(state["moving"], dtype=complex)

    def _lay_out(self, start: int) -> None:
        """The window starting at the recording's step ``start``: each of its people in a place for as long as they are recorded."""
        steps, dt = self._steps, self.dt
        self.start = start
        """The recording's time step (of the scenario's ``dt``) this episode starts at."""
        stop = self.start + steps  # the window's tracks, in the order Resampled.window() gives them (read here track by track)
        chosen = np.flatnonzero((self._track_start < stop) & (self._track_start + self._track_length > self.start))
        places = np.broadcast_to(parked(self.count), (steps, self.count)).copy()
        velocities = np.zeros((steps, self.count), dtype=complex)
        targets = places.copy()
        holder = np.full((steps, self.count), -1, dtype=np.int64)
        free_from = np.zeros(self.count, dtype=np.int64)  # the first step each place is free again
        for person, index in enumerate(chosen.tolist()):  # per recorded person of the window, once per episode
            begin = int(self._track_start[index])
            first = max(begin, self.start) - self.start  # the window steps it is present at, first to last
            last = min(begin + int(self._track_length[index]), stop) - 1 - self.start
            place = int(np.flatnonzero(free_from <= first)[0])  # exists: the peak fits the places
            free_from[place] = last + 2
            offset = int(self._track_first[index]) + self.start + first - begin
            track = self._track_points[offset : offset + last - first + 1] + self._offset
            places[first : last + 1, place] = track
            holder[first : last + 1, place] = person
            if len(track) > 1:
                step = np.diff(track) / dt
                velocities[first:last, place] = step
                velocities[last, place] = step[-1]
            if self._reaction is not None:  # its own position `ahead` steps on, its last near the track's end
                targets[first : last + 1, place] = self._ahead_of(index, first, last)
        self._positions, self._velocities, self._targets, self._holder = places, velocities, targets, holder

    def _ahead_of(self, track_index: int, first: int, last: int) -> np.ndarray:
        """(last - first + 1,) complex: track ``track_index`` at window steps first+ahead .. last+ahead, held at its last
        recorded position (read from the whole track, past the window's end too)."""
        track = self._grid.tracks[track_index]
        start = self.start + first - track.start  # index into the track of window step `first`
        index = np.minimum(np.arange(start, start + last - first + 1) + self._ahead, len(track.positions) - 1)
        ahead: np.ndarray = track.positions[index] + self._offset
        return ahead

    def commands(self, view: CrowdView) -> np.ndarray:
        return np.zeros(len(view.human_group), dtype=complex)  # placed, not commanded (and stopped)

    def place(self, view: CrowdView) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The group's humans (indices among the humans) with their recorded positions and velocities at this step
        (reacting ones: one social-force step from where they are; see the module docstring)."""
        step = min(int(view.step_count), self._steps - 1)
        index = np.flatnonzero(view.human_group == self._group)
        if self._reaction is None or self.react_within is None:
            return index, self._positions[step], self._velocities[step]
        positions, velocities = self._positions[step].copy(), self._velocities[step].copy()
        reacting = self.reacting
        if step:  # a place whose person left (or changed) replays again
            reacting &= self._holder[step] == self._holder[step - 1]
            reacting &= self._holder[step] >= 0
        if reacting.any():
            who = np.flatnonzero(reacting)
            moving = self._reaction.velocities(view, index[who], self._targets[step, who], self._moving[who])
            positions[who] = view.agent_positions[view.robot_count + index[who]] + moving * self.dt
            velocities[who] = moving
            self._moving[who] = moving
        robots = view.agent_positions[: view.robot_count]
        near = np.abs(positions[:, None] - robots[None, :]).min(axis=1) <= self.react_within
        near &= (self._holder[step] >= 0) & ~reacting
        if near.any():  # from the next step on
            reacting |= near
            self._moving[near] = velocities[near]
        return index, positions, velocities
