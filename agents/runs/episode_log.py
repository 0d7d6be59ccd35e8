"""The training episode log (``episodes.csv``): written so that a kill at any moment loses nothing, read so that damage is named.

Writing (:class:`EpisodeLogWriter`, :func:`prepare_log`):

* the log comes into being with its header, through a temporary file, an fsync and a rename:
  it never exists empty or header-less, whenever the process is killed;
* each row is one ``write`` on an append-only descriptor (no Python buffer): a kill leaves
  whole rows behind (at worst, after a full disk, a cut last row);
* the log is fsync'd before every checkpoint, so a checkpoint never counts episodes the log lost.

Repairing (:func:`prepare_log`, at every start of training and before evaluation reads the log):
an empty log gets its header; a header-less one (written by an older crowdnav killed before it
flushed its header) gets it back; a cut last row and the rows of episodes after the checkpoint
(trained again by the resume) move to ``episodes.csv.discarded``. A damaged row inside the log
stays where it is, for :func:`read_log` to name.

Reading (:func:`read_log`): every row checked; :class:`EpisodeLogError` says, in one line, which
file and line is wrong and what to do.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from crowdnav.errors import CrowdNavError
from crowdnav.files import atomic_write_text, open_for_write, open_text_for_append
from crowdnav.sim.simulator import OUTCOMES

COLUMNS = ("episode", "seed", "outcome", "return", "length", "timesteps", "seconds")
HEADER = ",".join(COLUMNS)
DISCARDED_SUFFIX = ".discarded"
"""``episodes.csv.discarded`` keeps the rows a repair or a resume took out of the log (appended, nothing is deleted)."""

Row = tuple[int, int, str, float, int, int, float]


class EpisodeLogError(CrowdNavError, ValueError):
    """An episode log that cannot be read as one row per training episode; the message names the file and the fix."""


def parse_row(line: str) -> Row | None:
    """The row ``line`` holds, or None when it is not a whole, well-formed row (cut, garbage, a wrong outcome)."""
    fields = line.rstrip("\r").split(",")
    if len(fields) != len(COLUMNS):
        return None
    episode, seed, outcome, reward, length, timesteps, seconds = fields
    try:
        row = (int(episode), int(seed), outcome, float(reward), int(length), int(timesteps), float(seconds))
    except ValueError:
        return None
    if row[0] < 0 or outcome not in OUTCOMES or row[4] < 0 or row[5] < 0 or not math.isfinite(row[6]):
        return None
    return row


def _fsync_folder(folder: Path) -> None:
    try:
        handle = os.open(folder, os.O_RDONLY)
    except OSError:  # a file system (or OS) without directory descriptors: the rename is as durable as it gets
        return
    try:
        os.fsync(handle)
    except OSError:
        pass
    finally:
        os.close(handle)


def _replace(path: Path, lines: list[str]) -> None:
    """Write ``lines`` to ``path`` through a temporary file, fsync'd, renamed over it: a kill leaves the old or the new file whole.

    The rename replaces a link at ``path`` rather than writing through it.
    """
    atomic_write_text(path, "".join(line + "\n" for line in lines), fsync=True)
    _fsync_folder(path.parent)


def _discard(path: Path, lines: list[str]) -> None:
    if not lines:
        return
    discarded = path.with_name(path.name + DISCARDED_SUFFIX)
    with open_text_for_append(discarded) as file:  # appended to, never through a link
        if file.tell() == 0:
            file.write(HEADER + "\n")
        file.write("".join(line + "\n" for line in lines))
        file.flush()
        os.fsync(file.fileno())


def _split(path: Path) -> tuple[list[str], str | None]:
    """The log's whole lines, and its cut last line (no newline: a write a kill interrupted), if any."""
    text = path.read_bytes().decode("utf-8", errors="replace")
    lines = text.split("\n")
    cut = lines.pop()  # "" when the file ends with a newline
    return [line.rstrip("\r") for line in lines], (cut or None)


def prepare_log(path: str | Path, first_episode: int) -> list[str]:
    """Make ``path`` a whole log of the episodes before ``first_episode``, ready for appending; returns what it repaired.

    Creates the log with its header if it is missing or empty; restores a missing header; moves a
    cut last row, and the rows of episodes >= ``first_episode`` (a resume trains them again), to
    ``<log>.discarded``. EpisodeLogError when the first line is neither the header nor a row
    (another file is in the log's place).
    """
    path = Path(path)
    existed = path.is_file()
    lines, cut = _split(path) if existed else ([], None)
    if not any(line.strip() for line in lines) and (cut is None or HEADER.startswith(cut)):
        # missing, empty, or only part of the header: killed before the header was whole
        _replace(path, [HEADER])
        return [f"{path.name} was empty (killed before its header was written): header restored"] if existed else []
    notes = []
    if lines and lines[0] == HEADER:
        lines = lines[1:]
    else:
        if lines and lines[0].strip() and parse_row(lines[0]) is None:
            raise EpisodeLogError(f"{path}: its first line ({lines[0][:60]!r}) is neither the episode log's header nor a row; "
                                  "move that file away and resume again")
        notes.append(f"{path.name} had no header (an older crowdnav was killed before writing it): header restored")
        lines = [line for line in lines if line.strip()]
    rows = [parse_row(line) for line in lines]
    # the first row of the history a resume throws away: damaged lines after it belong to that history too
    cut_at = 0 if first_episode == 0 else next((k for k, row in enumerate(rows) if row is not None and row[0] >= first_episode),
                                               len(rows))
    kept: list[str] = []
    moved: list[str] = []
    for k, (line, row) in enumerate(zip(lines, rows, strict=True)):
        later = row[0] >= first_episode if row is not None else k >= cut_at
        (moved if later else kept).append(line)
    if cut is not None:
        notes.append(f"{path.name}: its cut last line ({cut[:40]!r}) moved to {path.name}{DISCARDED_SUFFIX}")
        moved.append(cut)
    if notes or moved:  # setting aside the rows a resume trains again is routine, not a repair
        _discard(path, moved)
        _replace(path, [HEADER, *kept])
    return notes


def read_log(path: str | Path, episodes: int | None = None) -> list[Row]:
    """Every row of the log, one per episode 0, 1, ..., in order (``episodes``: exactly that many); EpisodeLogError otherwise.

    A run resumed by an older crowdnav logged some episodes twice: the later row counts.
    """
    path = Path(path)
    fix = "the training episodes cannot be recovered from what is left: remove the run's folder to train it again"
    if not path.is_file():
        raise EpisodeLogError(f"{path} is missing; {fix}")
    lines, cut = _split(path)
    if not lines or lines[0] != HEADER:
        raise EpisodeLogError(f"{path}: the first line is not the header {HEADER!r}; resume the run to restore it")
    if cut is not None:
        raise EpisodeLogError(f"{path}: line {len(lines) + 1} is cut short ({cut[:40]!r}); resume the run to set it aside")
    by_episode: dict[int, Row] = {}
    for number, line in enumerate(lines[1:], start=2):
        row = parse_row(line)
        if row is None:
            raise EpisodeLogError(f"{path}: line {number} is damaged ({line[:60]!r}); {fix}")
        by_episode[row[0]] = row
    count = len(by_episode) if episodes is None else episodes
    missing = [episode for episode in range(count) if episode not in by_episode]
    extra = sorted(episode for episode in by_episode if episode >= count)
    if missing or extra:
        what = f"no row for episode(s) {missing[:5]}" if missing else f"rows past the run's {count} episodes: {extra[:5]}"
        raise EpisodeLogError(f"{path}: {what}; {fix}")
    return [by_episode[episode] for episode in range(count)]


class EpisodeLogWriter:
    """Appends rows to a prepared log, each with one ``write`` on an ``O_APPEND`` descriptor (no buffer a kill could lose)."""

    def __init__(self, path: str | Path):
        self._fd: int | None = open_for_write(path, os.O_WRONLY | os.O_APPEND)  # prepared by prepare_log; never a link

    def write(self, line: str) -> None:
        if self._fd is None:
            raise ValueError(f"{line!r}: the episode log is closed")
        data = (line + "\n").encode("utf-8")
        while data:  # a short write happens only on a full disk or a signal; the rest follows (or the error is raised)
            written = os.write(self._fd, data)
            data = data[written:]

    def sync(self) -> None:
        """Make the rows written so far durable (before a checkpoint claims their episodes)."""
        if self._fd is not None:
            os.fsync(self._fd)

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.fsync(fd)
            os.close(fd)

    def __del__(self) -> None:  # a run stopped by an exception: the descriptor is not left open
        fd = getattr(self, "_fd", None)
        if fd is not None:
            os.close(fd)
            self._fd = None
