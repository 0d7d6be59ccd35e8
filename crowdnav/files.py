"""Writing files so that a symbolic link planted in an output folder cannot make crowdnav write elsewhere.

Two ways, one for each kind of write:

* whole files (results, configs, logs rewritten, videos) are written to a fresh temporary file in
  the same folder and renamed over the destination (:func:`replacing`, :func:`atomic_write_text`,
  :func:`atomic_write_bytes`): a rename replaces a link at the destination, never the file it
  points to, and readers see the old file or the new one, never a half-written one;
* files kept open or appended to (locks, the episode log, validation tables) are opened with
  ``O_NOFOLLOW`` (:func:`open_for_write`): a link there is refused with :class:`LinkedFileError`,
  one line.

Folders made fresh by a writer (a checkpoint's staging folder) hold no links, so what is written
inside them needs neither; :func:`remove_tree` removes a link in a folder's place without following it.

Whole folders (checkpoints, results, runs copied back, the encoder) are written the same way, one
level up: into a hidden staging folder beside the destination (:func:`staging_beside`), which then
takes the destination's place (:func:`swap_folder`); a reader first calls :func:`recover_folder`,
which finishes what a kill cut short. One writer at a time is kept by an OS file lock
(:func:`hold_lock`).
"""

from __future__ import annotations

import errno
import functools
import os
import re
import shutil
import sys
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from crowdnav.errors import CrowdNavError
from crowdnav.paths import OutputPathError

_NO_FOLLOW = getattr(os, "O_NOFOLLOW", 0)
_CLOSE_ON_EXEC = getattr(os, "O_CLOEXEC", 0)


class LinkedFileError(OutputPathError):
    """A file crowdnav would write is a symbolic link (writing through it would change the file it points to)."""


def link_refusal(path: str | Path) -> LinkedFileError:
    target = os.readlink(path) if os.path.islink(path) else "?"
    return LinkedFileError(f"{path} is a symbolic link (to {target}); crowdnav does not write through links: "
                           "remove it, or write to another folder")


def refuse_link(path: str | Path) -> Path:
    """``path``, or :class:`LinkedFileError` if it is a symbolic link (dangling or not)."""
    if os.path.islink(path):
        raise link_refusal(path)
    return Path(path)


def open_for_write(path: str | Path, flags: int = os.O_WRONLY | os.O_CREAT | os.O_APPEND, mode: int = 0o666) -> int:
    """A descriptor of ``path`` opened with ``flags`` and ``O_NOFOLLOW``: :class:`LinkedFileError` if ``path`` is a link."""
    if not _NO_FOLLOW:  # pragma: no cover - Windows: check first (a race remains there)
        refuse_link(path)
    try:
        return os.open(path, flags | _NO_FOLLOW | _CLOSE_ON_EXEC, mode)
    except OSError as error:
        # Linux says ELOOP for a final link under O_NOFOLLOW, the BSDs EMLINK
        if error.errno in (errno.ELOOP, errno.EMLINK) and os.path.islink(path):
            raise link_refusal(path) from None
        raise


def open_text_for_append(path: str | Path, *, readable: bool = False) -> IO[str]:
    """``path`` opened for appending text (created if missing; ``readable``: for reading too), never through a link."""
    flags = (os.O_RDWR if readable else os.O_WRONLY) | os.O_CREAT | os.O_APPEND
    return os.fdopen(open_for_write(path, flags), "a+" if readable else "a", encoding="utf-8", newline="")


_TEMPORARY_NAME = re.compile(r"\..+\.[0-9]+\.[0-9a-f]{8}\.tmp(\.[A-Za-z0-9]+)?")
""":func:`temporary_beside`'s names: ``.<name>.<pid>.<8 hex>.tmp`` and a writer's optional suffix (``.mp4``, ``.npz``)."""


def temporary_beside(path: Path, suffix: str = "") -> Path:
    """A new hidden name in ``path``'s folder (made if missing) to write ``path``'s content under before renaming it over ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    # a name no other process uses (mkstemp would also do, but makes the file private to its owner)
    return path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp{suffix}")


def is_temporary(name: str) -> bool:
    """Whether the file name ``name`` is one :func:`temporary_beside` makes (an orphan once its writer was killed)."""
    return _TEMPORARY_NAME.fullmatch(name) is not None


@contextmanager
def replacing(path: str | Path, *, suffix: str = "") -> Iterator[Path]:
    """A fresh temporary path in ``path``'s folder to write; once the body ends without error it is renamed over ``path``.

    The temporary is hidden (``.<name>.<pid>.<random>.tmp<suffix>``; ``suffix`` for writers that
    pick the format by it) and removed if the body raises. A link at ``path`` is replaced.
    """
    path = Path(path)
    temporary = temporary_beside(path, suffix)
    try:
        yield temporary
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | Path, data: bytes, *, fsync: bool = False) -> Path:
    """Write ``data`` to ``path`` through a temporary file and a rename (:func:`replacing`); ``fsync``: durable before the rename."""
    path = Path(path)
    with replacing(path) as temporary, open(temporary, "xb") as file:  # "x": never an existing file, nor a link
        file.write(data)
        if fsync:
            file.flush()
            os.fsync(file.fileno())
    return path


def atomic_write_text(path: str | Path, text: str, *, fsync: bool = False) -> Path:
    """``text`` as UTF-8 (newlines as given) through :func:`atomic_write_bytes`."""
    return atomic_write_bytes(path, text.encode("utf-8"), fsync=fsync)


def remove_tree(path: str | Path) -> None:
    """Remove the folder ``path``; a link (or file) in its place is unlinked, what it points to left alone."""
    if os.path.islink(path) or os.path.isfile(path):
        os.unlink(path)
    elif os.path.isdir(path):
        shutil.rmtree(path)


# --------------------------------------------------------------------------- folders written whole

_NEW, _READY, _OLD = "new", "ready", "old"
"""The roles of a folder's hidden copies beside it: being written, complete but not yet in place, the replaced one set aside."""

_SWAP_SUFFIX = r"\.[0-9]+\.[0-9a-f]{8}\.(new|ready|old)"
""":func:`staging_beside`'s and :func:`swap_folder`'s names: ``.<name>.<pid>.<8 hex>.<role>``."""

_LEGACY_NAMES = (
    # what earlier crowdnavs named them (folders they left on users' disks must still be recovered); ``{}``: the folder's name
    (r"{}\.partial", _READY),                     # checkpoints and the encoder, written in place: complete once the reader says so
    (r"{}\.old", _OLD),                           # checkpoints: the replaced one
    (r"{}\.next(\.partial|\.old)?", _NEW),        # shared robot checkpoints, built here before becoming ``.partial``
    (r"\.{}\.new-[0-9]+-[0-9a-f]{{8}}", _READY),    # crowdnav evaluate's results
    (r"\.{}\.old-[0-9a-f]{{8}}", _OLD),
    (r"\.{}\.[0-9a-f]{{8}}\.incoming", _READY),    # runs copied back from other machines
    (r"\.{}\.[0-9a-f]{{8}}\.replaced", _OLD),
)


def _beside(folder: Path, role: str) -> Path:
    # a name no other process uses, hidden (no listing takes it for a result or a snapshot)
    return folder.with_name(f".{folder.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.{role}")


def staging_beside(folder: str | Path) -> Path:
    """A new empty hidden folder beside ``folder`` (parents made) to write its next content in; :func:`swap_folder` puts it in place."""
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    staging = _beside(folder, _NEW)
    staging.mkdir()
    return staging


def is_swap_leftover(name: str) -> bool:
    """Whether the name ``name`` is one of :func:`staging_beside`'s or :func:`swap_folder`'s folders (an orphan once its writer was killed)."""
    return re.fullmatch(r"\..+" + _SWAP_SUFFIX, name) is not None


def _role(folder_name: str, name: str) -> str | None:
    """The role of the entry ``name`` as a copy of the folder ``folder_name`` (None: not one)."""
    # a copy of a copy (a checkpoint saved into a staging folder) is part of a write in progress
    if match := re.fullmatch(rf"\.+{re.escape(folder_name)}((?:{_SWAP_SUFFIX})+)", name):
        roles = re.findall(_SWAP_SUFFIX, match.group(1))
        return _NEW if len(roles) > 1 else str(roles[0])
    return next((role for pattern, role in _LEGACY_NAMES if re.fullmatch(pattern.format(re.escape(folder_name)), name)), None)


def _copies(folder: Path) -> dict[str, list[Path]]:
    """Role -> the copies of ``folder`` beside it (links included), sorted by name."""
    copies: dict[str, list[Path]] = {_NEW: [], _READY: [], _OLD: []}
    if folder.parent.is_dir():
        for entry in sorted(folder.parent.iterdir()):  # the name's start first: a snapshots folder holds many
            if entry.name.lstrip(".").startswith(folder.name.lstrip(".")) and (role := _role(folder.name, entry.name)) is not None:
                copies[role].append(entry)
    return copies


def whole_copies(folder: str | Path) -> list[Path]:
    """The copies of ``folder`` a killed swap left beside it that may be whole (what :func:`recover_folder` can pick)."""
    copies = _copies(Path(folder))
    return [copy for copy in copies[_READY] + copies[_OLD] if copy.is_dir() and not copy.is_symlink()]


def discard_leftovers(folder: str | Path) -> list[Path]:
    """Remove every copy of ``folder`` a killed swap left beside it (earlier crowdnavs' names too); returns them.

    For a writer about to write ``folder`` anew, holding its lock (another writer's copies would go too).
    """
    leftovers = [copy for copies in _copies(Path(folder)).values() for copy in copies]
    for copy in leftovers:
        remove_tree(copy)
    return leftovers


def recover_folder(folder: str | Path, rank: Callable[[Path], float | None] | None = None) -> None:
    """Finish what a kill cut short while :func:`swap_folder` replaced ``folder``, then remove every copy left beside it.

    Without ``rank`` the swap is undone: ``folder`` stays if it is there, else the copy set aside is
    put back. With ``rank`` (a copy's rank, None for an incomplete one) the complete copy ranked
    highest becomes ``folder``; on a tie ``folder`` itself, then a new copy, then an old one. A link
    is never a copy: it is removed, not followed (one at ``folder`` stays unless a copy replaces it).
    Earlier crowdnavs' names (``<name>.partial``, ``<name>.old``, ``.<name>.new-*``, ...) count.
    Call it holding ``folder``'s writer lock: a write in progress would lose its copies.
    """
    folder = Path(folder)
    copies = _copies(folder)
    candidates = whole_copies(folder)
    best: Path | None = None
    if rank is None:
        old = [copy for copy in candidates if copy in copies[_OLD]]
        if old and not folder.exists():  # killed between the two renames of a replacement: the old folder is whole
            best = old[-1]
    else:
        here = [] if folder.is_symlink() else [folder]
        ranked = [(value, -k, copy) for k, copy in enumerate(here + candidates) if copy.is_dir() and (value := rank(copy)) is not None]
        if ranked:
            best = max(ranked, key=lambda item: item[:2])[2]
    if best is not None and best != folder:
        remove_tree(folder)
        os.rename(best, folder)
    discard_leftovers(folder)


def swap_folder(staging: str | Path, folder: str | Path) -> Path:
    """Put the complete folder ``staging`` in ``folder``'s place and remove the old one; readers see one or the other whole.

    ``staging`` is first renamed ``.<name>.<pid>.<hex>.ready`` (complete from then on), then takes
    ``folder``'s place: one rename for a new folder; for an existing one, one exchange of the two
    where the system has it (Linux's ``renameat2``), else ``folder`` is renamed aside
    (``.<name>.<pid>.<hex>.old``) first. A kill at any point leaves ``folder`` or a whole copy of
    the old or new one beside it, for :func:`recover_folder`. An error puts the old folder back and
    removes the new one. A link in ``folder``'s place is removed, not followed.
    """
    staging, folder = Path(staging), Path(folder)
    ready = _beside(folder, _READY)
    os.rename(staging, ready)
    try:
        if os.path.islink(folder):
            os.unlink(folder)
        if not folder.exists():
            os.rename(ready, folder)
            return folder
        if _exchange(ready, folder):
            old = ready  # it holds the old folder now
        else:
            old = _beside(folder, _OLD)
            os.rename(folder, old)
            try:
                os.rename(ready, folder)
            except Exception:
                os.rename(old, folder)  # the old one back in its place
                raise
    except Exception:
        shutil.rmtree(ready, ignore_errors=True)
        raise
    remove_tree(old)
    return folder


@functools.cache
def _renameat2() -> Any:
    """Linux's ``renameat2`` through ctypes, or None (another system, a C library without it: glibc < 2.28, musl)."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        function = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    return function


def _exchange(first: Path, second: Path) -> bool:
    """Swap two folders atomically (``renameat2(RENAME_EXCHANGE)``); False where the system or file system cannot."""
    renameat2 = _renameat2()
    at_fdcwd, rename_exchange = -100, 2
    return renameat2 is not None and renameat2(at_fdcwd, os.fsencode(first), at_fdcwd, os.fsencode(second), rename_exchange) == 0


# --------------------------------------------------------------------------- one writer at a time

class RunBusyError(CrowdNavError, RuntimeError):
    """Another process is writing this run folder (or result, or table): it holds the lock."""


class LockUnavailableError(CrowdNavError, OSError):
    """The file system of a folder crowdnav writes cannot lock files (``flock``), so one writer at a time cannot be kept."""


@contextmanager
def hold_lock(path: str | Path, busy: Callable[[str], str], *, remove: bool = False) -> Iterator[None]:
    """Hold the OS lock (``flock``) of the file ``path``; :class:`RunBusyError` with ``busy(holder's PID)`` if another has it.

    The file keeps the holder's PID; the lock goes with its holder's process, however it ends.
    ``remove``: the file is deleted on release (while still held; a process that locked the
    deleted file meanwhile sees it is no longer ``path`` and takes the new one). Where ``fcntl``
    does not exist (Windows) no lock is taken.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    path = Path(path)
    while True:
        handle = open_text_for_append(path, readable=True)  # never through a link; closed after the lock's whole life
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            handle.close()
            raise RunBusyError(busy(holder)) from None
        except OSError as error:  # a file system without flock (some network mounts): ENOLCK, EOPNOTSUPP
            handle.close()
            if remove:
                path.unlink(missing_ok=True)
            raise LockUnavailableError(f"{path.parent}: this file system cannot lock files ({error.strerror or error}), so "
                                       "crowdnav cannot keep a second writer out; write to a folder on a local disk") from None
        try:
            current = os.stat(path).st_ino
        except FileNotFoundError:
            current = None
        if current == os.fstat(handle.fileno()).st_ino:
            break
        handle.close()  # removed by the holder that just let go: lock the file now at ``path``
    with handle:
        handle.seek(0)
        handle.truncate()
        handle.write(f"{os.getpid()}\n")
        handle.flush()
        try:
            yield
        finally:
            if remove:
                path.unlink(missing_ok=True)
