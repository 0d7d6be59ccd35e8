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
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

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
