"""Runs that happen on other machines: their working folder, and moving a finished run into the results.

A Ray task does its run in a *working folder* under a storage root (``--storage``), with the
same relative path as in the results: ``<storage>/<experiment>/<configuration>/seed_<s>``.
Its checkpoints stay there, so a retried task resumes from them. Whether a task sees the
driver's storage is decided by an id file: the driver writes a random id to
``<storage>/.crowdnav-storage`` (:func:`claim_storage`), and a task that reads the same id
there shares that file system (:func:`work_folder`). A task that does not (a node without the
shared file system) works in ``<its temp folder>/crowdnav-storage/<id>/...`` instead, so a
retry on another node starts that run again from scratch.

A finished run travels back as bytes (:func:`pack_folder`, an uncompressed tar of its files:
per-episode CSVs, training outcomes, meta.json, the final checkpoint and the policy snapshots;
the Ray executor leaves out the replay buffer) and the driver unpacks it into the results
(:func:`unpack_folder`) through a staging folder and a rename, so a run folder in the results
is either absent, the partial one it was, or complete; a complete one is never replaced.
"""

from __future__ import annotations

import io
import shutil
import tarfile
import tempfile
import uuid
from pathlib import Path

from crowdnav.evaluation.storage import ResultsError, atomic_write_text, experiment_of

from crowdnav.files import is_swap_leftover, is_temporary, staging_beside, swap_folder

STORAGE_ID_FILE = ".crowdnav-storage"
"""The storage root's id file (one random id, written once, kept)."""


def claim_storage(root: str | Path) -> str:
    """The id of the storage root ``root`` (created, with its id file, the first time); run by the driver."""
    path = Path(root) / STORAGE_ID_FILE
    if not path.is_file():
        try:
            atomic_write_text(path, uuid.uuid4().hex + "\n")
        except OSError as error:
            raise ResultsError(f"storage {root}: cannot write there ({error.strerror or error}); give a writable --storage") from None
    return path.read_text(encoding="utf-8").strip()


def node_local_root(storage_id: str) -> Path:
    """Where a task that does not see the storage root works: a folder of its node's temp folder."""
    return Path(tempfile.gettempdir()) / "crowdnav-storage" / storage_id


def work_folder(root: str | Path, storage_id: str, relative: str | Path) -> tuple[Path, bool]:
    """(working folder of a run, whether it is in the shared storage root), as seen by the task's machine."""
    id_file = Path(root) / STORAGE_ID_FILE
    try:
        shared = id_file.read_text(encoding="utf-8").strip() == storage_id
    except OSError:
        shared = False
    return (Path(root) if shared else node_local_root(storage_id)) / relative, shared


def remove_work_folder(work_dir: str | Path) -> None:
    """Delete a run's working folder once the results have it, and its configuration and experiment folders if now empty."""
    work_dir = Path(work_dir)
    shutil.rmtree(work_dir, ignore_errors=True)
    for parent in (work_dir.parent, experiment_of(work_dir)):  # the configuration's folder, then the experiment's
        try:
            parent.rmdir()
        except OSError:  # not empty (other runs, the experiment's encoder): keep
            break


def _temporary(member: tarfile.TarInfo) -> bool:
    """Files a crash can leave behind: atomic writes' temporaries (``.NAME.tmp``, ``.NAME.PID.HEX.tmp.mp4``) and the copies of
    a folder being swapped (:func:`crowdnav.files.swap_folder`; earlier crowdnavs' ``.partial`` / ``.old`` checkpoints)."""
    return any(part.endswith((".tmp", ".partial", ".old")) or is_temporary(part) or is_swap_leftover(part) for part in Path(member.name).parts)


def pack_folder(folder: str | Path, skip: tuple[str, ...] = ()) -> bytes:
    """Every file below ``folder`` (without temporaries and the relative paths in ``skip``), as an uncompressed tar in memory."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        for path in sorted(Path(folder).rglob("*")):
            if path.is_file() and not path.is_symlink():
                info = tar.gettarinfo(path, arcname=path.relative_to(folder).as_posix())
                if not _temporary(info) and info.name not in skip:
                    with open(path, "rb") as file:
                        tar.addfile(info, file)
    return buffer.getvalue()


def unpack_folder(data: bytes, target: str | Path, marker: str) -> bool:
    """Unpack :func:`pack_folder`'s bytes into ``target``, complete when it holds the file ``marker``.

    Returns False, changing nothing, when ``target`` is already complete (another copy got there
    first). A partial ``target`` is replaced. ResultsError when the bytes lack ``marker``.
    """
    target = Path(target)
    if (target / marker).is_file():
        return False
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = staging_beside(target)
    try:
        with tarfile.open(fileobj=io.BytesIO(data), mode="r") as tar:
            if hasattr(tarfile, "data_filter"):  # Python >= 3.10.12 / 3.11.4: refuse links and paths outside staging
                tar.extractall(staging, filter="data")
            else:  # pragma: no cover - older Pythons; the tar is our own
                tar.extractall(staging)
        if not (staging / marker).is_file():
            raise ResultsError(f"{target}: the transferred folder has no {marker} (incomplete run)")
        if (target / marker).is_file():  # another copy got there first
            return False
        try:
            swap_folder(staging, target)  # a partial run (an interrupted local run, an error.log) is replaced
        except OSError:  # another process put its copy there in between
            if (target / marker).is_file():
                return False
            raise
        return True
    finally:
        shutil.rmtree(staging, ignore_errors=True)
