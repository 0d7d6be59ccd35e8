"""The layout of a training run's folder (``crowdnav.agents.train``'s ``out``), as a small public API.

::

    <train_dir>/checkpoint/              the latest checkpoint (crowdnav.agents.runs.checkpoint): policy.json, model.zip, ...
    <train_dir>/snapshots/episode_<N>/   the policy after N episodes (saved every checkpoint_every episodes)
    <train_dir>/snapshots/steps_<N>/     with a budget in env steps: the policy after N env steps (every checkpoint_every_steps)
    <train_dir>/episodes.csv             one row per training episode

Training writes this layout and everything that reads a run (evaluation, the benchmark's
video, the progress bar) goes through these functions, so the layout is known in one place.
Torch-free; a policy folder loads with :func:`crowdnav.agents.load_policy` (torch and SB3).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from crowdnav.errors import CrowdNavError
from crowdnav.files import LockUnavailableError as LockUnavailableError  # the lock lives in the core; its names stay importable here
from crowdnav.files import RunBusyError as RunBusyError
from crowdnav.files import hold_lock, recover_folder

CHECKPOINT_DIR = "checkpoint"
SNAPSHOTS_DIR = "snapshots"
EPISODE_LOG = "episodes.csv"
POLICY_FILE = "policy.json"
"""A policy folder (checkpoint or snapshot) is complete once it holds this file (written last)."""
REPLAY_FILE = "replay_buffer.pkl"
"""The checkpoint's replay buffer (off-policy runs with ``save_replay_buffer``)."""
RNG_FILE = "rng_state.pkl"
"""The checkpoint's random streams (torch, numpy, Python, action space), so a resumed run continues the same run."""
ROLLOUT_FILE = "rollout_state.pkl"
"""An on-policy checkpoint's unfinished business: the collected rollout, the env mid-episode, the last observation."""
LOCK_FILE = "writer.lock"
"""Held (an OS file lock) by the one process writing a run folder; holds that process's PID."""

_SNAPSHOT = {"episodes": re.compile(r"episode_(\d+)$"), "steps": re.compile(r"steps_(\d+)$")}
UNITS = tuple(_SNAPSHOT)
"""What a run's evaluation points count: training episodes, or env steps over all worlds."""


def checkpoint_dir(train_dir: str | Path) -> Path:
    """The folder of the run's latest checkpoint (it may not exist yet; :func:`crowdnav.agents.runs.checkpoint.find_checkpoint` looks)."""
    return Path(train_dir) / CHECKPOINT_DIR


def snapshot_dir(train_dir: str | Path, point: int, unit: str = "episodes") -> Path:
    """The folder of the policy snapshot after ``point`` training episodes (or env steps, ``unit="steps"``)."""
    return Path(train_dir) / SNAPSHOTS_DIR / (f"episode_{point:05d}" if unit == "episodes" else f"steps_{point:09d}")


def episode_log(train_dir: str | Path) -> Path:
    """The run's per-episode log (CSV, one row per training episode; it may not exist yet)."""
    return Path(train_dir) / EPISODE_LOG


def replay_buffer_file(train_dir: str | Path) -> Path:
    """The checkpoint's replay buffer file (large; a run resumes without it, training its buffer anew)."""
    return checkpoint_dir(train_dir) / REPLAY_FILE


def checkpoint_info(train_dir: str | Path) -> dict[str, Any] | None:
    """The checkpoint's ``policy.json`` (``episodes``, ``timesteps``, ``algo``, ``env``, ...), or None without a checkpoint."""
    file = checkpoint_dir(train_dir) / POLICY_FILE
    return json.loads(file.read_text(encoding="utf-8")) if file.is_file() else None


def checkpoint_episodes(train_dir: str | Path) -> int:
    """Training episodes behind the run's checkpoint (0 if there is none yet)."""
    info = checkpoint_info(train_dir)
    return int(info["episodes"]) if info is not None else 0


def policy_snapshots(train_dir: str | Path, unit: str = "episodes") -> dict[int, Path]:
    """Episodes (or env steps, ``unit="steps"``) -> folder of every policy saved so far on the checkpoint's training history.

    The snapshots up to the checkpoint, and (episodes) the checkpoint itself (a run from an older
    crowdnav can have been killed after its checkpoint and before its snapshot). A snapshot newer
    than the checkpoint (or any snapshot without one) was saved just before a kill; the resume
    trains that stretch again.
    """
    folders: dict[int, Path] = {}
    latest = 0
    if (checkpoint_dir(train_dir) / POLICY_FILE).is_file():
        if unit == "episodes":
            latest = checkpoint_episodes(train_dir)
            folders[latest] = checkpoint_dir(train_dir)
        else:  # a step-budget checkpoint is taken at a rollout's end, at or after the evaluation point it follows
            latest = int((checkpoint_info(train_dir) or {}).get("timesteps", 0))
    for point, folder in snapshot_folders(train_dir, unit).items():
        if (folder / POLICY_FILE).is_file() and point <= latest:
            folders[point] = folder
    return folders


def snapshot_folders(train_dir: str | Path, unit: str = "episodes") -> dict[int, Path]:
    """Point -> folder of every snapshot named in ``unit`` (complete or not, before or after the checkpoint), in order."""
    snapshots = Path(train_dir) / SNAPSHOTS_DIR
    folders = {}
    for folder in sorted(snapshots.iterdir()) if snapshots.is_dir() else []:
        if match := _SNAPSHOT[unit].match(folder.name):
            folders[int(match.group(1))] = folder
    return folders


def last_logged_row(train_dir: str | Path) -> dict[str, str] | None:
    """The episode log's last complete row as ``{column: text}`` (None before the first); reads the log's tail only.

    A row being written can be cut short: the last row with every column (and a whole-number
    ``episode``) counts.
    """
    log = episode_log(train_dir)
    if not log.is_file():
        return None
    with open(log, "rb") as file:
        header = file.readline().decode("utf-8").strip().split(",")
        size = file.seek(0, 2)
        file.seek(max(0, size - 4096))
        lines = file.read().decode("utf-8", errors="replace").splitlines()
    for line in reversed(lines):
        fields = line.split(",")
        if len(fields) == len(header) and fields[0].isdigit():
            return dict(zip(header, fields, strict=True))
    return None


def logged_episodes(train_dir: str | Path) -> int:
    """Training episodes the episode log has a row for so far (cheap: reads the last row's index)."""
    row = last_logged_row(train_dir)
    return int(row["episode"]) + 1 if row is not None else 0


def _complete(folder: Path) -> int | None:
    """Episodes of a complete checkpoint folder (policy.json is written last), else None."""
    info = folder / POLICY_FILE
    if not info.is_file():
        return None
    try:
        return int(json.loads(info.read_text(encoding="utf-8"))["episodes"])
    except (ValueError, KeyError, TypeError):
        return None


def recover_checkpoint(train_dir: str | Path) -> int:
    """Make ``checkpoint/`` the newest complete checkpoint a kill left behind; returns its episodes (0: none).

    A checkpoint is written into a staging folder beside ``checkpoint/`` and swapped in
    (:func:`crowdnav.files.swap_folder`). A kill can leave it, its new copy or the old one set aside
    (earlier crowdnavs' ``checkpoint.partial`` and ``checkpoint.old`` too); the complete one with the
    most episodes becomes ``checkpoint/`` and the others are removed, so a resume never restarts
    from scratch while a complete checkpoint exists.
    """
    current = checkpoint_dir(train_dir)
    recover_folder(current, _complete)  # a link is never a checkpoint a kill left: it is removed, not followed
    return (None if current.is_symlink() else _complete(current)) or 0


@contextmanager
def writing(folder: str | Path) -> Iterator[None]:
    """Hold the folder's writer lock while writing it: a second writer gets :class:`RunBusyError` at once.

    Two processes resuming one run (an orphaned worker of a killed sweep, two terminals) would
    otherwise interleave rows in the same logs. The lock is the OS's (``flock``), so it is released
    when its holder exits in any way, kill included. Where ``fcntl`` does not exist (Windows) no
    lock is taken.

    A refusal leaves no run folder behind: when the body raises a :class:`CrowdNavError` (a bad
    scenario, config or option, reported in one line) in a folder this call created, and the folder
    holds nothing trained yet (only ``config.yaml``, an ``episodes.csv`` without rows and the lock),
    the folder and the parents this call created are removed.
    """
    folder = Path(folder)
    created = next((path for path in reversed([folder, *folder.parents]) if not path.exists()), None)
    folder.mkdir(parents=True, exist_ok=True)
    try:
        with hold_lock(folder / LOCK_FILE, lambda holder: f"{folder} is being written by another process (PID {holder}); "
                                                          "wait for it to finish or stop it, then resume"):
            yield
    except CrowdNavError:
        if created is not None:
            _remove_untrained(folder, created)
        raise


_SETUP_FILES = frozenset({LOCK_FILE, "config.yaml", EPISODE_LOG})
"""What a run folder holds before its first episode is logged (the header-only log included)."""


def _remove_untrained(folder: Path, created: Path) -> None:
    """Remove ``folder`` if it holds only setup files and no logged episode, then its empty parents up to ``created``."""
    entries = list(folder.iterdir())
    if any(entry.name not in _SETUP_FILES or not entry.is_file() for entry in entries):
        return
    log = folder / EPISODE_LOG
    if log.is_file() and len(log.read_text(encoding="utf-8").splitlines()) > 1:
        return
    for entry in entries:
        entry.unlink(missing_ok=True)
    for path in [folder, *folder.parents]:
        try:
            path.rmdir()
        except OSError:  # not empty (another writer's files), or gone
            return
        if path == created:
            return


def training_run(path: str | Path) -> Path:
    """The training run a policy path names: a protocol run folder's ``train/`` (it holds the checkpoint), else the path."""
    path = Path(path)
    return path / "train" if (path / "train" / "checkpoint").is_dir() else path
