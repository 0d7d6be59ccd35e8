"""The robot's people tracker (``sensors.tracker``): detections with a field of view, occlusion, noise and misses, and tracks.

One :class:`PeopleTracker` holds the tracks of K worlds (one for a single env, the batch's worlds for
the stacked vector env) and is stepped by the env: :meth:`PeopleTracker.start` at each episode's reset,
:meth:`PeopleTracker.update` after the reset and after every simulator step. Every reader of the robot's
tracker in a world (the ``humans`` and ``plan`` modalities, the shield, ``baseline:onboard``) reads the
same :meth:`PeopleTracker.columns` of it (:mod:`crowdnav.sensors.tracked`), so they see the same tracks.

Each step, for every person (arrays over worlds and people, no Python loop over either):

1. **Detectable**: its centre within ``max_range`` and the field of view, and at least ``min_visible``
   of its width in sight past walls, furniture and other people (:mod:`crowdnav.sensors.sightlines`).
2. **Detected** with probability ``detection_probability``, at its true centre plus Gaussian noise of
   ``position_noise + position_noise_per_m * distance`` per axis.
3. **Tracks**: a detection continues its person's track (the association is ideal: one track per person,
   no identity switches) unless it lies more than :data:`GATE` from the track's prediction, which starts
   a new track (a respawned person, a long coast). A track is lost with probability ``drop_probability``
   per step (a false drop) or after ``max_missed`` steps without a detection; a new track is reported once
   it has ``confirm_hits`` detections (the tracks of the reset's detections at once: the tracker ran before
   the episode began).
4. **Estimates**: a least-squares line through the track's last ``window`` detections (time, position)
   gives its velocity (the slope); its position is its latest detection, moved on at that velocity while
   the track coasts. One detection: that position, velocity 0.

Randomness: :mod:`crowdnav.sensors.tracker_draws`, never the simulator's generator.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from crowdnav.sensors.sightlines import Sightlines
from crowdnav.sensors.tracker_draws import episode_key, fresh_entropy, normal_pair, uniforms
from crowdnav.sim.state import SELF_DISTANCE

if TYPE_CHECKING:
    from crowdnav.scenario.tracker import TrackerProfile
    from crowdnav.worlds.compiled import CompiledWorld

ROW_STATE = ("_episode", "_key", "_step", "_fresh", "_robot", "_alive", "_hits", "_confirmed", "_last_seen", "_measured",
             "_measured_at", "_moments", "_sums", "_latest", "_position", "_velocity")
"""The tracker's per-world arrays (row ``world``; :data:`ROW_SECOND`: column ``world``): with ``_entropy`` and ``_columns``, a
world's whole tracker state (:meth:`PeopleTracker.row_state`); the tracker's other attributes are settings."""
ROW_SECOND = frozenset({"_moments", "_sums"})
"""The per-world arrays whose world axis is the second."""
GATE = 1.0
"""Metres between a detection and its track's one-step prediction beyond which the detection starts a new track."""


class TrackReading(NamedTuple):
    """What the tracker reports of K worlds' n people now (world frame): the reported tracks, nothing of the others."""

    positions: np.ndarray
    """(K, n) complex: each reported track's estimated centre, NaN where the tracker reports nobody."""
    offset: np.ndarray
    """(K, n) complex: the estimated centre minus the robot's centre, 0 where nobody is reported."""
    distance: np.ndarray
    """(K, n) float: ``|offset|``, inf where nobody is reported."""
    velocity: np.ndarray
    """(K, n) complex: the estimated velocity (m/s), 0 where nobody is reported."""
    reported: np.ndarray
    """(K, n) bool: the tracker reports this person."""


class TrackedColumns(NamedTuple):
    """K worlds as the tracker reports them, in the simulator's layout (the robot first, then the n people): what the
    readers of the tracker get in place of the simulator's ``positions``, ``velocities``, ``robot_offset``, ``robot_distance``."""

    positions: np.ndarray
    """(K, n+1) complex: the robot's centre, then each reported track's estimated centre (NaN: nobody reported)."""
    velocities: np.ndarray
    """(K, n+1) complex: the robot's velocity, then each reported track's estimated velocity (0: nobody reported)."""
    offset: np.ndarray
    """(K, n+1) complex: 0, then the estimated centres minus the robot's (0: nobody reported)."""
    distance: np.ndarray
    """(K, n+1) float: :data:`crowdnav.sim.state.SELF_DISTANCE`, then ``|offset|`` (inf: nobody reported)."""


class PeopleTracker:
    """The tracks of ``num_worlds`` worlds of ``world`` with the tracker ``values`` (see the module docstring)."""

    def __init__(self, world: CompiledWorld, values: TrackerProfile, num_worlds: int):
        self.values = values
        self.num_worlds = int(num_worlds)
        self.dt = float(world.scenario.time_step)
        self.sight = Sightlines(world) if values.occlusion else None
        self.half_fov = math.radians(values.fov_deg) / 2.0
        self.full_circle = values.fov_deg >= 360.0
        self._entropy: list[int | None] = [None] * self.num_worlds
        """Per world: the seed of its last seeded reset (or fresh entropy), None before its first reset."""
        self._episode = np.zeros(self.num_worlds, dtype=np.int64)
        """Per world: episodes since that reset (0: the seeded one)."""
        self._key = np.zeros(self.num_worlds, dtype=np.uint64)
        self._step = np.zeros(self.num_worlds, dtype=np.int64)
        self._fresh = np.zeros(self.num_worlds, dtype=bool)
        """Per world: started, its first detections not made yet."""
        self._robot = np.zeros(self.num_worlds, dtype=complex)
        """Per world: the robot's centre at the last start / update (the reading's origin)."""
        self._allocate(int(world.scenario.humans.max_count))

    def _allocate(self, n: int) -> None:
        k, w = self.num_worlds, self.values.window
        self._alive = np.zeros((k, n), dtype=bool)
        self._hits = np.zeros((k, n), dtype=np.int64)
        """Detections since the track's birth (its window holds the last ``window`` of them, slot ``hit % window``)."""
        self._all = np.arange(k)
        self._confirmed = np.zeros((k, n), dtype=bool)
        """The track is reported: ``confirm_hits`` detections since its birth, or born at the episode's reset."""
        self._last_seen = np.zeros((k, n), dtype=np.int64)
        self._measured = np.zeros((k, n, w), dtype=complex)
        self._measured_at = np.zeros((k, n, w))
        self._moments = np.zeros((3, k, n))
        """Per track, over its window's detections: their number, the sum of their steps before now, and of its square."""
        self._sums = np.zeros((2, k, n), dtype=complex)
        """Per track: the sum of its window's positions, and of each times its steps before now."""
        self._latest = np.zeros((k, n), dtype=complex)
        """Per track: its latest detection."""
        self._position = np.zeros((k, n), dtype=complex)
        self._velocity = np.zeros((k, n), dtype=complex)
        self._columns = TrackedColumns(np.full((k, n + 1), complex(math.nan, math.nan)), np.zeros((k, n + 1), dtype=complex),
                                       np.zeros((k, n + 1), dtype=complex), np.full((k, n + 1), math.inf))
        """What the readers get, made once per update (:meth:`columns`)."""
        self._columns.distance[:, 0] = SELF_DISTANCE

    def start(self, worlds: Sequence[int] | np.ndarray, seeds: Sequence[int | None]) -> None:
        """New episodes in ``worlds`` (reset with ``seeds``: None continues that world's seed): no tracks yet.

        The episode's first detections come with the worlds' next :meth:`update` (after the reset, before any step).
        """
        rows = np.asarray(worlds, dtype=np.intp)
        keys = []
        for world, seed in zip(rows.tolist(), seeds, strict=True):  # per reset, not per step
            if seed is not None or self._entropy[world] is None:
                self._entropy[world] = int(seed) if seed is not None else fresh_entropy()
                episode = 0
            else:
                episode = int(self._episode[world]) + 1
            self._episode[world] = episode
            entropy = self._entropy[world]
            assert entropy is not None
            keys.append(episode_key(entropy, episode))
        self._key[rows] = keys
        self._step[rows] = 0
        self._fresh[rows] = True
        self._alive[rows] = False
        self._moments[:, rows] = 0.0
        self._sums[:, rows] = 0.0

    @property
    def pending(self) -> np.ndarray:
        """The worlds started and not updated since (their readers must wait for their first :meth:`update`)."""
        return np.flatnonzero(self._fresh)

    def update(self, worlds: Sequence[int] | np.ndarray, positions: np.ndarray, robot_velocity: np.ndarray, heading: np.ndarray,
               radii: np.ndarray) -> None:
        """The tracks of ``worlds`` after their reset (a world just started: its first detections) or their next step.

        ``positions``: (K, n+1) complex, the robot then the people, of those worlds now; ``robot_velocity``: (K,)
        complex, the robots' own (odometry: passed on to the readers); ``heading``: (K,) the robots' headings;
        ``radii``: (n+1,) shared by the K worlds.
        """
        rows = np.asarray(worlds, dtype=np.intp)
        n = positions.shape[1] - 1
        if n > self._alive.shape[1]:  # more people than the scenario's max_count (a scene staged by hand)
            self._allocate(n)
        full = self._covers(rows, n)
        # every world's every person (the usual batch): views of the state, updated in place; else gathered copies
        at: tuple[Any, Any] = (slice(None), slice(None)) if full else (rows[:, None], np.arange(n)[None, :])
        sel = slice(None) if full else rows  # the worlds' rows of the per-world state
        fresh = self._fresh[rows]
        self._step[sel] += ~fresh
        self._fresh[sel] = False
        self._robot[sel] = positions[:, 0]
        if n:
            self._observe(at, not full, sel, fresh, positions, heading, radii[1:])
        self._publish(at, sel, n, positions[:, 0], robot_velocity)

    def _covers(self, rows: np.ndarray, n: int) -> bool:
        """``rows`` are all the worlds in order and ``n`` all the people: the state's own arrays serve, as views."""
        return len(rows) == self.num_worlds and n == self._alive.shape[1] and bool((rows == self._all).all())

    def _publish(self, at: tuple[Any, Any], rows: np.ndarray | slice, n: int, robot: np.ndarray, robot_velocity: np.ndarray) -> None:
        """Make the readers' columns of ``rows`` from the tracks now."""
        positions, velocities, offset, distance = self._columns
        reported = self._alive[at] & self._confirmed[at]
        estimate = self._position[at]
        people = (at[0], at[1] + 1) if not isinstance(at[1], slice) else (at[0], slice(1, None))
        positions[rows, 0], velocities[rows, 0] = robot, robot_velocity
        positions[people] = np.where(reported, estimate, complex(math.nan, math.nan))
        velocities[people] = np.where(reported, self._velocity[at], 0.0)
        relative = np.where(reported, estimate - robot[:, None], 0.0)
        offset[people] = relative
        distance[people] = np.where(reported, np.abs(relative), math.inf)

    def columns(self, worlds: Sequence[int] | np.ndarray, n: int) -> TrackedColumns:
        """The readers' view of ``worlds`` (their first ``n`` people) now: the state's own arrays when they are every world's
        (read them, never write them), else copies."""
        rows = np.asarray(worlds, dtype=np.intp)
        if self._covers(rows, n):
            return self._columns
        return TrackedColumns(*(values[rows, : n + 1] for values in self._columns))

    def reading(self, worlds: Sequence[int] | np.ndarray, n: int) -> TrackReading:
        """The tracks of ``worlds`` (their first ``n`` people) now, without the robot's column (new arrays)."""
        rows = np.asarray(worlds, dtype=np.intp)
        positions, velocities, offset, distance = (values[rows, 1 : n + 1] for values in self._columns)
        return TrackReading(positions, offset, distance, velocities, self._alive[rows, :n] & self._confirmed[rows, :n])

    def frozen(self, world: int) -> Callable[[int], TrackedColumns]:
        """World ``world``'s columns now, kept: for a snapshot of the world that must not follow later steps."""
        kept = TrackedColumns(*(values[world : world + 1].copy() for values in self._columns))
        return lambda n: TrackedColumns(*(values[:, : n + 1] for values in kept))

    # ------------------------------------------------------------ world states

    def row_state(self, world: int) -> dict[str, Any]:
        """World ``world``'s tracks and draws now, copied (:data:`ROW_STATE`; :meth:`load_row` takes them back, into any row)."""
        out: dict[str, Any] = {"entropy": self._entropy[world]}
        for name in ROW_STATE:  # keyed without the attribute's underscore
            values = getattr(self, name)
            out[name[1:]] = values[:, world].copy() if name in ROW_SECOND else values[world].copy()
        out["columns"] = tuple(values[world].copy() for values in self._columns)
        return out

    def load_row(self, world: int, state: dict[str, Any]) -> None:
        """Make ``state`` (a :meth:`row_state` of a tracker of the same scenario) world ``world``'s tracks and draws."""
        people = np.shape(state["alive"])[-1]
        if people != self._alive.shape[1]:
            raise ValueError(f"a people tracker's state of {people} people cannot load into a tracker of {self._alive.shape[1]}")
        self._entropy[world] = state["entropy"]
        for name in ROW_STATE:
            values = getattr(self, name)
            if name in ROW_SECOND:
                values[:, world] = state[name[1:]]
            else:
                values[world] = state[name[1:]]
        for values, row in zip(self._columns, state["columns"], strict=True):
            values[world] = row

    # ---------------------------------------------------------------- one step

    def _observe(self, at: tuple[Any, Any], gathered: bool, rows: np.ndarray | slice, fresh: np.ndarray, positions: np.ndarray,
                 heading: np.ndarray, radius: np.ndarray) -> None:
        """This step's detections and the tracks' new estimates; ``at`` indexes the state arrays' (rows, people), as views
        (``gathered`` False) or copies written back at the end.

        Every (world, person) entry is updated on its own, as dense arrays: a detection's updates are masked (``where=``,
        or a term that is 0 where nothing changes: the entries not updated keep their values, bit for bit), cheaper
        than gathering the detections.
        """
        values, now, window = self.values, self._step[rows], self.values.window
        detected, measured, draws = self._detect(rows, now, positions, heading, radius)
        alive, hits, last_seen = self._alive[at], self._hits[at], self._last_seen[at]
        moments, sums = self._moments[:, at[0], at[1]], self._sums[:, at[0], at[1]]
        count, steps, squares, total, weighted = moments[0], moments[1], moments[2], sums[0], sums[1]
        now_column = now[:, None]
        # the window's detections are a step older (a fresh world's tracks are empty: nothing moves)
        squares += count - 2.0 * steps
        steps -= count
        weighted -= total
        # a track is kept unless falsely dropped or coasted too long; a detection far from its prediction starts a new one
        predicted = self._position[at] + self._velocity[at] * self.dt
        alive &= draws[..., 1] >= values.drop_probability
        alive &= detected | (last_seen >= (now - values.max_missed)[:, None])
        continued = np.abs(measured - predicted) <= GATE
        continued &= alive
        new = detected > continued
        hits[new] = 0
        np.copyto(moments, 0.0, where=new)
        np.copyto(sums, 0.0, where=new)
        # each track's window slot for this detection, as an index into the flat ring (C-contiguous: views or fresh copies)
        slot = hits % window
        slot += _ring_base(hits.shape[0], hits.shape[1], window)
        ring, ring_at = self._measured[at].reshape(-1), self._measured_at[at].reshape(-1)
        held, held_at = ring[slot], ring_at[slot]
        # a full window drops its oldest detection (the slot the new one takes); the moments are whole numbers (exact), the
        # sums never -0.0 (so x - 0.0 is x)
        dropped = count >= window
        grown = detected > dropped
        dropped &= detected
        age = held_at - now_column  # the dropped detection's steps before now
        moved = age * dropped
        steps -= moved
        squares -= moved * moved
        np.subtract(total, held, out=total, where=dropped)
        np.subtract(weighted, age * held, out=weighted, where=dropped)
        count += grown
        # ... and takes the new one, at 0 steps before now
        np.copyto(held, measured, where=detected)
        np.copyto(held_at, now_column, where=detected)
        ring[slot], ring_at[slot] = held, held_at
        np.add(total, measured, out=total, where=detected)
        hits += detected
        alive |= detected
        confirmed = self._confirmed[at]
        np.greater(confirmed, new, out=confirmed)  # kept unless a new track
        confirmed |= hits >= values.confirm_hits
        if fresh.any():
            confirmed |= alive & fresh[:, None]
        np.copyto(last_seen, now_column, where=detected)
        latest = self._latest[at]
        np.copyto(latest, measured, where=detected)
        # least squares through the window: slope = cov(step, position) / var(step); one detection: slope 0
        tracks = np.maximum(count, 1.0)
        mean = steps / tracks
        spread = squares - steps * mean
        slope = (weighted - mean * total) / np.where(spread > 0.0, spread, np.inf)  # metres per step
        if gathered:
            self._alive[at], self._hits[at], self._last_seen[at], self._latest[at] = alive, hits, last_seen, latest
            self._measured[at], self._measured_at[at] = ring.reshape(*hits.shape, window), ring_at.reshape(*hits.shape, window)
            self._moments[:, at[0], at[1]], self._sums[:, at[0], at[1]] = moments, sums
            self._confirmed[at] = confirmed
        # the latest detection, moved on at the estimated velocity while the track coasts
        self._position[at] = np.where(alive, latest + slope * (now_column - last_seen), 0.0)
        self._velocity[at] = np.where(alive, slope * (1.0 / self.dt), 0.0)

    def _detect(self, rows: np.ndarray | slice, now: np.ndarray, positions: np.ndarray, heading: np.ndarray,
                radius: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(detected (K, n) bool, measured positions (K, n) complex, this step's draws (K, n, 4))."""
        values, robot, people = self.values, positions[:, 0], positions[:, 1:]
        toward = people - robot[:, None]
        distance = np.abs(toward)
        draws = uniforms(self._key[rows], now, people.shape[1])
        # in range (a robot inside a person's disc sees nobody there), and the detector fires: then is it in view, in sight?
        detected = distance <= values.max_range
        detected &= distance > radius
        detected &= draws[..., 0] < values.detection_probability
        if not self.full_circle:
            bearing = np.arctan2(toward.imag, toward.real) - heading[:, None]
            detected &= np.abs(np.mod(bearing + math.pi, 2.0 * math.pi) - math.pi) <= self.half_fov
        if self.sight is not None:
            detected &= self.sight.visible_fraction(robot, toward, distance, radius, detected) >= self.values.min_visible - 1e-9
        across, along = normal_pair(draws[..., 2], draws[..., 3])
        # the spread (a number where it does not grow with distance: p + 0 * d is p + 0, bit for bit, as d >= 0)
        per_m = values.position_noise_per_m
        sigma = values.position_noise + per_m * distance if per_m else values.position_noise + per_m
        noise = np.empty(people.shape, dtype=complex)
        noise.real, noise.imag = sigma * across, sigma * along
        return detected, people + noise, draws


_RING_BASES: dict[tuple[int, int, int], np.ndarray] = {}


def _ring_base(k: int, n: int, window: int) -> np.ndarray:
    """(k, n) each track's first slot in a flat ring of k x n windows (kept per shape)."""
    base = _RING_BASES.get((k, n, window))
    if base is None:
        if len(_RING_BASES) > 64:  # bounded
            _RING_BASES.clear()
        base = _RING_BASES[k, n, window] = np.arange(0, k * n * window, window).reshape(k, n)
    return base


def make_tracker(world: CompiledWorld, num_worlds: int) -> PeopleTracker | None:
    """The tracker of ``world``'s scenario (``sensors.tracker``) for ``num_worlds`` worlds; None for ``perfect``."""
    values = world.scenario.sensors.tracker.values
    return None if values is None else PeopleTracker(world, values, num_worlds)
