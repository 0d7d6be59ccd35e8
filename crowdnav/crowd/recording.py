"""Recorded pedestrians: the standard trajectory files read, checked and resampled to a scenario's time step.

The reader of the recorded crowd (issue 40): people's tracks from the files a researcher already
has (no recording ships with crowdnav), in three formats:

- ``obsmat``: the ETH/UCY ``obsmat.txt`` layout, 8 numbers a row: ``frame id x z y vx vz vy``
  (metres; the ground plane is x, y; z and the velocities are ignored);
- ``frames``: the trajectory-prediction benchmarks' 4 columns ``frame id x y`` (whitespace, tab
  or comma separated);
- ``trajnet``: TrajNet++ ndjson, one JSON object a line: ``{"scene": {..., "fps": F}}`` and
  ``{"track": {"f": frame, "p": id, "x": x, "y": y}}`` (the format ``crowdnav trajectories`` writes).

**Time.** Annotations come every few video frames (ETH/UCY: every 10 frames of 25 fps video, so
0.4 s, 2.5 Hz). The annotation step in frame numbers is the most common difference between
consecutive annotated frames; one such step lasts ``annotation_step`` seconds (default 0.4), or
``1 / fps`` for a TrajNet++ file whose scenes give their fps (they must agree). A frame's time is
then ``(frame - first frame) / frame step * annotation_step``.

**Resampling.** :meth:`Recording.resample` puts every person on the scenario's time grid
``k * dt`` by linear interpolation between their annotations (x and y separately), from their
first annotation to their last: a person is present exactly while the recording shows them
(never extrapolated; a gap in a track is bridged in a straight line at constant speed).

**Checks.** The path: a relative one is resolved in the folder of the file that names it and
must stay inside it (after ``..`` and symbolic links); the file must be a regular UTF-8 file of at
most :data:`MAX_BYTES` bytes, :data:`MAX_LINES` lines of at most :data:`MAX_LINE_BYTES` bytes and
:data:`MAX_ROWS` rows, positions within :data:`MAX_COORDINATE` m. It is read a block of lines at a time (never
whole), so a file of comments costs no more than its longest line. On the time grid it may span at
most :data:`MAX_GRID_STEPS` steps and hold :data:`MAX_GRID_POINTS` positions, both counted before
anything of that size is allocated (frames far apart would otherwise cost gigabytes). Every
malformed row is refused in one line, ``FILE:LINE: what is wrong`` (the row's content is not quoted).
"""

from __future__ import annotations

import itertools
import json
import math
import os
import re
import stat
from array import array
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Literal

import numpy as np

from crowdnav.errors import CrowdNavError

RecordingFormat = Literal["auto", "obsmat", "frames", "trajnet"]
MAX_BYTES = 64 * 1024 * 1024
"""The largest recording read (bytes): ETH/UCY files are well under 1 MB, TrajNet++ splits a few MB."""
MAX_ROWS = 2_000_000
"""At most this many annotations (rows) in a recording."""
MAX_LINES = 3_000_000
"""At most this many lines read, comments and blank lines included (64 MiB of comment lines are refused in about a second)."""
MAX_LINE_BYTES = 1024 * 1024
"""The longest line read (bytes): a row is under 200 bytes; a 64 MiB line of millions of fields is never split."""
MAX_GRID_POINTS = 20_000_000
"""At most this many (person, time step) positions after resampling (a smaller time step costs more)."""
MAX_GRID_STEPS = 20_000_000
"""At most this many time steps from the first annotation to the last (11 days at 0.05 s): frames 0 and 2,000,000,010 are
refused before any array of the span is allocated."""
MAX_COORDINATE = 1_000_000.0
"""Largest |x| or |y| (m) of a recorded position: far below where the replay parks absent people, and squared distances stay finite."""
DEFAULT_ANNOTATION_STEP = 0.4
"""Seconds between two annotations of ETH/UCY (2.5 Hz), used unless the file says otherwise."""
_SEPARATORS = re.compile(r"[\s,]+")


class RecordingError(CrowdNavError, ValueError):
    """A recording cannot be used: its path, its size, or a malformed row (``FILE:LINE: message``, one line)."""


@dataclass(frozen=True)
class Track:
    """One person on the scenario's time grid: present from step ``start`` for ``len(positions)`` steps."""

    person: int
    """The id the recording gives them."""
    start: int
    positions: np.ndarray
    """(L,) complex: the position (m) at steps ``start .. start + L - 1``."""


@dataclass(frozen=True)
class Resampled:
    """A recording on a time grid of step ``dt``: :attr:`steps` grid times, one :class:`Track` per person."""

    dt: float
    steps: int
    tracks: list[Track]

    def window(self, start: int, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The people present during steps ``start .. start + steps - 1``: their ids (P,), positions (steps, P)
        complex (NaN while absent) and a (steps, P) bool mask of presence, people in order of their first step."""
        stop = start + steps
        chosen = [track for track in self.tracks if track.start < stop and track.start + len(track.positions) > start]
        positions = np.full((steps, len(chosen)), np.nan + 0j)
        for column, track in enumerate(chosen):  # per person of the window, once per episode
            first, last = max(track.start, start), min(track.start + len(track.positions), stop)
            positions[first - start : last - start, column] = track.positions[first - track.start : last - track.start]
        ids = np.array([track.person for track in chosen], dtype=np.int64)
        return ids, positions, ~np.isnan(positions.real)

    def window_start(self, rng: np.random.Generator, steps: int) -> int:
        """An episode's first step, uniform over the windows of ``steps`` steps that fit (0 when the recording is shorter)."""
        return int(rng.integers(0, max(self.steps - steps, 0) + 1))


@dataclass(frozen=True)
class Recording:
    """Every annotation of a recording: time (s from its first annotation), person id and position, sorted by person then time."""

    source: str
    times: np.ndarray
    """(R,) float seconds."""
    people: np.ndarray
    """(R,) int64 person ids."""
    positions: np.ndarray
    """(R,) complex metres."""
    format: str = "auto"
    """The layout read (obsmat, frames or trajnet)."""

    @property
    def duration(self) -> float:
        return float(self.times.max()) if len(self.times) else 0.0

    def resample(self, dt: float) -> Resampled:
        """Every person on the grid ``k * dt`` (k = 0, 1, ...), linearly interpolated between their annotations."""
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"expected a time step > 0, got {dt!r}")
        span = math.floor(min(self.duration / dt, 1e18) + 1e-9) + 1  # min: a float too big for int() is refused below all the same
        if span > MAX_GRID_STEPS:
            raise RecordingError(f"{self.source}: spans {self.duration:.6g} s, {span:,} time steps of {dt:g} s, more than "
                                 f"{MAX_GRID_STEPS:,}; expected annotations closer in time (frame numbers far apart?) "
                                 "or a longer time step")
        steps = int(span)
        bounds = np.flatnonzero(np.diff(self.people)) + 1
        firsts, lasts = np.r_[0, bounds], np.r_[bounds, len(self.people)]
        begins = np.ceil(self.times[firsts] / dt - 1e-9).astype(np.int64)
        ends = np.floor(self.times[lasts - 1] / dt + 1e-9).astype(np.int64)
        total = int(np.maximum(ends - begins + 1, 0).sum())  # every person's grid, counted before one is allocated
        if total > MAX_GRID_POINTS:
            raise RecordingError(f"{self.source}: {total:,} positions at a time step of {dt:g} s, more than {MAX_GRID_POINTS:,}; "
                                 "expected a shorter recording or a longer time step")
        tracks = []
        for first, last, begin, end in zip(firsts, lasts, begins.tolist(), ends.tolist(), strict=True):  # per person, once per recording
            times, where = self.times[first:last], self.positions[first:last]
            if end < begin:  # seen for less than a time step between two grid times: never on the grid
                continue
            grid = np.arange(begin, end + 1) * dt
            line = np.interp(grid, times, where.real) + 1j * np.interp(grid, times, where.imag)
            tracks.append(Track(int(self.people[first]), begin, line))
        tracks.sort(key=lambda track: (track.start, track.person))
        return Resampled(dt, steps, tracks)


def resolve_path(path: str | Path, folder: str | Path | None) -> Path:
    """``path`` as named in a file of ``folder``: a relative path must stay inside ``folder`` (None: the current folder)."""
    path = Path(path)
    if path.is_absolute():
        return path
    root = Path(folder if folder is not None else ".").resolve()
    resolved = (root / path).resolve()
    if not resolved.is_relative_to(root):
        raise RecordingError(f"{path}: a recording's relative path must stay inside {root} (the folder of the file naming it); "
                             "give an absolute path to read one elsewhere")
    return resolved


def read_recording(path: str | Path, fmt: RecordingFormat = "auto", annotation_step: float = DEFAULT_ANNOTATION_STEP,
                   folder: str | Path | None = None) -> Recording:
    """Read a recording (see the module docstring); ``folder``: where a relative ``path`` is resolved and must stay."""
    file = resolve_path(path, folder)
    source = str(path)
    with _open_recording(file) as stream:
        rows = _rows(stream, file, source)
        if fmt == "auto":
            first = next(rows, None)
            fmt = _guess_format(file, first, source)
            rows = itertools.chain([first] if first is not None else [], rows)
        if fmt == "trajnet":
            frames, people, positions, fps = _parse_trajnet(rows, source)
            step = 1.0 / fps if fps is not None else annotation_step
        else:
            frames, people, positions = _parse_columns(rows, source, 8 if fmt == "obsmat" else 4)
            step = annotation_step
    if not len(frames):
        raise RecordingError(f"{source}: holds no annotation; expected rows of {_FORMAT_WORDS[fmt]}")
    order = np.lexsort((frames, people))
    frames, people, positions = frames[order], people[order], positions[order]
    same = (np.diff(people) == 0) & (np.diff(frames) == 0)
    if same.any():
        k = int(np.flatnonzero(same)[0])
        raise RecordingError(f"{source}: person {people[k]} has two positions at frame {frames[k]}; expected one per frame")
    distinct = np.unique(frames)
    gaps = np.diff(distinct)
    if len(gaps):  # the most common gap (the smallest of equals), counted over the distinct gaps: frames may be far apart
        values, counts = np.unique(gaps, return_counts=True)
        frame_step = int(values[np.argmax(counts)])
    else:
        frame_step = 1
    times = (frames - distinct[0]) / frame_step * step
    return Recording(source, times.astype(float), people, positions, fmt)


_FORMAT_WORDS = {"obsmat": "8 numbers (frame id x z y vx vz vy)", "frames": "4 numbers (frame id x y)",
                 "trajnet": 'TrajNet++ JSON lines ({"track": {"f": ..., "p": ..., "x": ..., "y": ...}})'}


def _open_recording(file: Path) -> BinaryIO:
    """``file`` opened for reading: a regular file (a FIFO or a device is refused without blocking) of at most MAX_BYTES."""
    try:
        handle = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as error:
        raise RecordingError(f"{file}: cannot read the recording: {error.strerror or error}; expected a readable file") from None
    try:
        info = os.fstat(handle)
        if not stat.S_ISREG(info.st_mode):
            raise RecordingError(f"{file}: not a regular file; expected a recording (obsmat, frame id x y, or TrajNet++ ndjson)")
        if info.st_size > MAX_BYTES:
            raise RecordingError(f"{file}: holds more than {MAX_BYTES:,} bytes; expected a recording of at most that size")
        return os.fdopen(os.dup(handle), "rb")
    finally:
        os.close(handle)


def _rows(stream: BinaryIO, file: Path, source: str) -> Iterator[tuple[int, str]]:
    """(line number, stripped line) of every non-blank line that is not a '#' comment, at most MAX_ROWS of them, read one
    block of whole lines at a time (about MAX_LINE_BYTES; MAX_LINES lines and MAX_BYTES in all: a file that grows is cut too)."""
    count = number = read = 0
    while True:
        block = stream.read(MAX_LINE_BYTES)
        if not block:
            return
        if not block.endswith(b"\n"):  # complete the last line, itself at most MAX_LINE_BYTES
            rest = stream.readline(MAX_LINE_BYTES + 1)
            if len(rest) > MAX_LINE_BYTES:
                where = number + block.count(b"\n") + 1
                raise RecordingError(f"{file}:{where}: a line longer than {MAX_LINE_BYTES:,} bytes; expected one row a line")
            block += rest
        read += len(block)
        if read > MAX_BYTES:
            raise RecordingError(f"{file}: holds more than {MAX_BYTES:,} bytes; expected a recording of at most that size")
        try:
            text = block.decode("utf-8-sig" if number == 0 else "utf-8")
        except UnicodeDecodeError as error:
            where = number + block.count(b"\n", 0, error.start) + 1
            raise RecordingError(f"{file}:{where}: not UTF-8 text; expected a text recording") from None
        lines = text.splitlines()  # the line breaks str.splitlines knows (a lone \r too): blocks end at a \n, so as a whole text's
        if number + len(lines) > MAX_LINES:
            raise RecordingError(f"{source}:{MAX_LINES + 1}: more than {MAX_LINES:,} lines; expected a smaller recording")
        for line in lines:
            number += 1
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            count += 1
            if count > MAX_ROWS:
                raise RecordingError(f"{source}:{number}: more than {MAX_ROWS:,} rows; expected a smaller recording")
            yield number, line


def _guess_format(file: Path, first: tuple[int, str] | None, source: str) -> RecordingFormat:
    """The format of ``file`` from its name, else from its first row ``first`` (None: it has none)."""
    if file.suffix.lower() in (".ndjson", ".json", ".jsonl"):
        return "trajnet"
    if first is None:
        raise RecordingError(f"{source}: holds no annotation; expected obsmat, frame id x y, or TrajNet++ ndjson rows")
    number, line = first
    if line.startswith("{"):
        return "trajnet"
    columns = len(_SEPARATORS.split(line))
    if columns in (8, 4):
        return "obsmat" if columns == 8 else "frames"
    raise RecordingError(f"{source}:{number}: {columns} columns; expected 8 (obsmat: frame id x z y vx vz vy), "
                         "4 (frame id x y) or TrajNet++ JSON lines")


def _integer(value: float) -> bool:
    return math.isfinite(value) and value == int(value) and abs(value) < 2**53


def _columns() -> tuple[array[int], array[int], array[float], array[float]]:
    """Frames, ids, x and y as they are read: 8 bytes a value (Python lists would hold 2,000,000 rows in about 300 MB)."""
    return array("q"), array("q"), array("d"), array("d")


def _parse_columns(rows: Iterator[tuple[int, str]], source: str, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames, ids and positions of an obsmat (width 8: x at column 3, y at column 5) or a frame id x y file (width 4)."""
    frames, people, xs, ys = _columns()
    y_column = 4 if width == 8 else 3
    for number, line in rows:
        fields = _SEPARATORS.split(line)
        if len(fields) != width:
            raise RecordingError(f"{source}:{number}: {len(fields)} columns; expected {_FORMAT_WORDS['obsmat' if width == 8 else 'frames']}")
        try:
            values = [float(field) for field in fields]
        except ValueError:
            raise RecordingError(f"{source}:{number}: a column is not a number; expected {width} numbers") from None
        if not all(math.isfinite(value) for value in values):
            raise RecordingError(f"{source}:{number}: a column is not finite (nan or inf); expected finite numbers")
        if abs(values[2]) > MAX_COORDINATE or abs(values[y_column]) > MAX_COORDINATE:
            raise RecordingError(f"{source}:{number}: a position beyond {MAX_COORDINATE:g} m; expected coordinates in metres")
        if not (_integer(values[0]) and _integer(values[1])):
            raise RecordingError(f"{source}:{number}: the frame and the id must be whole numbers")
        frames.append(int(values[0]))
        people.append(int(values[1]))
        xs.append(values[2])
        ys.append(values[y_column])
    return np.array(frames, dtype=np.int64), np.array(people, dtype=np.int64), np.array(xs) + 1j * np.array(ys)


def _parse_trajnet(rows: Iterator[tuple[int, str]], source: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float | None]:
    frames, people, xs, ys = _columns()
    fps: float | None = None
    for number, line in rows:
        try:
            row = json.loads(line)
        except (ValueError, RecursionError):
            raise RecordingError(f"{source}:{number}: not a JSON object; expected one TrajNet++ scene or track a line") from None
        if not isinstance(row, dict) or len(row) != 1 or not isinstance(next(iter(row.values())), dict):
            raise RecordingError(f'{source}:{number}: expected {{"scene": {{...}}}} or {{"track": {{...}}}}')
        kind, body = next(iter(row.items()))
        if kind == "scene":
            rate = body.get("fps")
            if rate is not None:
                if isinstance(rate, bool) or not isinstance(rate, int | float) or not 0 < rate <= 1e6:  # no float() of 10**400
                    raise RecordingError(f"{source}:{number}: scene fps must be a number > 0 and at most 1e6")
                if fps is not None and float(rate) != fps:
                    raise RecordingError(f"{source}:{number}: scene fps {rate:g} differs from an earlier scene's {fps:g}; expected one rate")
                fps = float(rate)
            continue
        if kind != "track":
            raise RecordingError(f"{source}:{number}: unknown line kind {kind[:40]!r}; expected scene or track")
        frame, person, x, y = (body.get(key) for key in ("f", "p", "x", "y"))
        if any(isinstance(v, bool) or not isinstance(v, int) for v in (frame, person)):
            raise RecordingError(f'{source}:{number}: a track needs whole numbers "f" (frame) and "p" (person)')
        if any(isinstance(v, bool) or not isinstance(v, int | float) or (isinstance(v, float) and not math.isfinite(v)) for v in (x, y)):
            raise RecordingError(f'{source}:{number}: a track needs finite numbers "x" and "y" (metres)')
        assert isinstance(frame, int) and isinstance(person, int) and isinstance(x, int | float) and isinstance(y, int | float)
        if abs(x) > MAX_COORDINATE or abs(y) > MAX_COORDINATE:  # an int may be any size (10**400 has no float)
            raise RecordingError(f"{source}:{number}: a position beyond {MAX_COORDINATE:g} m; expected coordinates in metres")
        if abs(frame) >= 2**53 or abs(person) >= 2**63:
            raise RecordingError(f"{source}:{number}: frame or person id out of range")
        frames.append(frame)
        people.append(person)
        xs.append(float(x))
        ys.append(float(y))
    return np.array(frames, dtype=np.int64), np.array(people, dtype=np.int64), np.array(xs) + 1j * np.array(ys), fps
