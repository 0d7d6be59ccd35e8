"""A folder written whole (crowdnav.files.swap_folder): a kill between any two steps leaves the old or the new folder
complete, and recover_folder puts it in place, for the names of today and those earlier crowdnavs left on disk."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from crowdnav import files
from crowdnav.files import (
    RunBusyError,
    discard_leftovers,
    hold_lock,
    is_swap_leftover,
    recover_folder,
    staging_beside,
    swap_folder,
)


class Killed(BaseException):
    """Stands for a SIGKILL: no ``except Exception`` runs, so what is on disk is what a kill leaves."""


def _write(folder: Path, version: int, complete: bool = True) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "data.txt").write_text(f"data {version}")
    if complete:
        (folder / "version").write_text(str(version))  # written last: the folder's "policy.json"
    return folder


def _version(folder: Path) -> int | None:
    """The rank a reader gives a copy: its version if complete, else None (as recover_checkpoint's episodes)."""
    marker = folder / "version"
    return int(marker.read_text()) if marker.is_file() else None


def _entries(parent: Path) -> list[str]:
    return sorted(path.name for path in parent.iterdir())


def _staged(tmp_path: Path, version: int) -> tuple[Path, Path]:
    folder = tmp_path / "checkpoint"
    return folder, _write(staging_beside(folder), version)


@pytest.fixture(params=["exchange", "aside"])
def exchange(request, monkeypatch) -> bool:
    """Both ways to replace a folder: Linux's atomic exchange, and (other systems) renaming the old one aside first."""
    if request.param == "aside":
        monkeypatch.setattr(files, "_exchange", lambda first, second: False)
    return request.param == "exchange"


def test_a_new_folder_is_swapped_in_and_no_copy_is_left(tmp_path):
    folder, staging = _staged(tmp_path, 1)
    assert staging.name.startswith(".checkpoint.") and staging.name.endswith(".new") and is_swap_leftover(staging.name)
    assert swap_folder(staging, folder) == folder
    assert _version(folder) == 1 and _entries(tmp_path) == ["checkpoint"]


def test_an_existing_folder_is_replaced_whole_and_the_old_one_removed(tmp_path, exchange):
    folder = _write(tmp_path / "checkpoint", 1)
    (folder / "only_in_old.txt").write_text("old")
    _, staging = _staged(tmp_path, 2)
    swap_folder(staging, folder)
    assert _version(folder) == 2 and _entries(folder) == ["data.txt", "version"] and _entries(tmp_path) == ["checkpoint"]


def test_a_link_in_the_folders_place_is_replaced_and_what_it_points_to_left_alone(tmp_path, exchange):
    victim = _write(tmp_path / "victim", 7)
    folder = tmp_path / "run" / "checkpoint"
    folder.parent.mkdir()
    folder.symlink_to(victim, target_is_directory=True)
    _, staging = _staged(tmp_path / "run", 2)
    swap_folder(staging, folder)
    assert not folder.is_symlink() and _version(folder) == 2 and _version(victim) == 7 and _entries(victim) == ["data.txt", "version"]


def _killing_rename(monkeypatch, at: int, after: bool) -> None:
    """Kill at the ``at``-th rename swap_folder makes (0: the first), just before it or just after it."""
    rename, count = os.rename, [0]

    def killing(source, target):
        count[0] += 1
        if count[0] - 1 == at and not after:
            raise Killed
        rename(source, target)
        if count[0] - 1 == at:
            raise Killed

    monkeypatch.setattr(files.os, "rename", killing)


# (rename index, kill after it) -> what a kill there leaves: whether the new folder was already complete beside the old
# (renamed .ready), and whether it was in place. Replacing through an aside makes three renames: staging -> ready,
# folder -> aside, ready -> folder.
ASIDE_KILLS = {(0, False): (False, False), (0, True): (True, False), (1, False): (True, False), (1, True): (True, False),
               (2, False): (True, False), (2, True): (True, True)}


@pytest.mark.parametrize(("at", "after"), sorted(ASIDE_KILLS))
def test_a_kill_between_any_two_renames_leaves_a_whole_folder_that_recovery_puts_in_place(tmp_path, monkeypatch, at, after):
    monkeypatch.setattr(files, "_exchange", lambda first, second: False)
    for rank in (None, _version):
        run = tmp_path / f"rank_{rank is not None}"
        folder = _write(run / "checkpoint", 1)
        _, staging = _staged(run, 2)
        with monkeypatch.context() as patch:
            _killing_rename(patch, at, after)
            with pytest.raises(Killed):
                swap_folder(staging, folder)
        ready, in_place = ASIDE_KILLS[(at, after)]
        assert _entries(run) != ["checkpoint"]  # the kill left copies beside it (or no folder)
        recover_folder(folder, rank)
        # undone without a rank (the old folder, unless the new one was in place), else the newest complete one
        expected = 2 if in_place or (rank is not None and ready) else 1
        assert _version(folder) == expected and _entries(run) == ["checkpoint"], (at, after, rank)


@pytest.mark.parametrize("step", ["exchange", "removal"])
def test_a_kill_during_or_after_the_exchange_leaves_the_new_folder_in_place(tmp_path, monkeypatch, step):
    exchange_now = files._exchange

    def killing_exchange(first, second):
        exchange_now(first, second)
        raise Killed

    def killing_removal(path):
        raise Killed

    for rank in (None, _version):
        run = tmp_path / f"rank_{rank is not None}"
        folder = _write(run / "checkpoint", 1)
        _, staging = _staged(run, 2)
        with monkeypatch.context() as patch:
            if step == "exchange":
                patch.setattr(files, "_exchange", killing_exchange)
            else:
                patch.setattr(files, "remove_tree", killing_removal)
            with pytest.raises(Killed):
                swap_folder(staging, folder)
        if not files._renameat2():  # pragma: no cover - a system without the exchange: the aside way, tested above
            continue
        assert len(_entries(run)) == 2  # the old folder, under the new copy's name
        recover_folder(folder, rank)
        assert _version(folder) == 2 and _entries(run) == ["checkpoint"]


def test_an_error_in_the_last_rename_puts_the_old_folder_back_and_removes_the_new_one(tmp_path, monkeypatch):
    monkeypatch.setattr(files, "_exchange", lambda first, second: False)
    folder = _write(tmp_path / "checkpoint", 1)
    _, staging = _staged(tmp_path, 2)
    rename = os.rename

    def failing(source, target):
        if Path(source).name.endswith(".ready") and Path(target) == folder:
            raise OSError(28, "No space left on device")
        rename(source, target)

    monkeypatch.setattr(files.os, "rename", failing)
    with pytest.raises(OSError, match="No space left"):
        swap_folder(staging, folder)
    assert _version(folder) == 1 and _entries(tmp_path) == ["checkpoint"]


# --------------------------------------------------------------------------- earlier crowdnavs' names

@pytest.mark.parametrize(
    ("present", "rank", "expected"),
    [
        # checkpoints: written into checkpoint.partial, swapped through checkpoint.old
        ({"checkpoint.old": 4, "checkpoint.partial": 6}, _version, 6),
        ({"checkpoint.old": 4, "checkpoint.partial": None}, _version, 4),
        ({"checkpoint": 4, "checkpoint.partial": 6}, _version, 6),
        ({"checkpoint": 6, "checkpoint.old": 4}, _version, 6),
        # shared robot checkpoints: built in checkpoint.next (complete in its policy.json, not yet its state), then .partial
        ({"checkpoint": 4, "checkpoint.next": 6, "checkpoint.next.partial": None, "checkpoint.next.old": 5}, _version, 4),
        ({"checkpoint.old": 4, "checkpoint.partial": 6, "checkpoint.next": 8}, _version, 6),
        # crowdnav evaluate's results: .<name>.new-<pid>-<hex>, the old one set aside as .<name>.old-<hex>
        ({".checkpoint.old-0123abcd": 4, ".checkpoint.new-99-89abcdef": 6}, None, 4),
        ({"checkpoint": 6, ".checkpoint.old-0123abcd": 4}, None, 6),
        ({"checkpoint": 4, ".checkpoint.new-99-89abcdef": None}, None, 4),
        # runs copied back from other machines: .<name>.<hex>.incoming, the partial one set aside as .<name>.<hex>.replaced
        ({".checkpoint.0123abcd.replaced": None, ".checkpoint.89abcdef.incoming": 6}, _version, 6),
        ({".checkpoint.0123abcd.replaced": 4, ".checkpoint.89abcdef.incoming": 6}, None, 4),
        # today's names, a copy of a copy (a checkpoint saved into a staging folder) among them
        ({".checkpoint.1.0123abcd.old": 4, ".checkpoint.1.89abcdef.ready": 6}, _version, 6),
        ({".checkpoint.1.0123abcd.old": 4, ".checkpoint.1.89abcdef.ready": 6}, None, 4),
        ({"checkpoint": 4, ".checkpoint.1.89abcdef.new": 6, "..checkpoint.1.89abcdef.new.1.01234567.ready": 8}, _version, 4),
    ],
)
def test_an_interrupted_swap_under_each_naming_scheme_is_recovered(tmp_path, present, rank, expected):
    for name, version in present.items():
        _write(tmp_path / name, version or 0, complete=version is not None)
    others = ["checkpoint_b.partial", ".checkpoint_b.1.0123abcd.old", "snapshots"]  # not copies of checkpoint/: kept
    for name in others:
        (tmp_path / name).mkdir()
    recover_folder(tmp_path / "checkpoint", rank)
    assert _version(tmp_path / "checkpoint") == expected
    assert _entries(tmp_path) == sorted(["checkpoint", *others])


def test_without_a_complete_copy_the_folder_stays_as_it_is_and_the_copies_go(tmp_path):
    _write(tmp_path / "checkpoint", 0, complete=False)
    _write(tmp_path / "checkpoint.partial", 0, complete=False)
    _write(tmp_path / ".checkpoint.1.0123abcd.ready", 0, complete=False)
    recover_folder(tmp_path / "checkpoint", _version)
    assert _entries(tmp_path) == ["checkpoint"] and _entries(tmp_path / "checkpoint") == ["data.txt"]
    recover_folder(tmp_path / "nothing", _version)  # nothing there: nothing done
    assert _entries(tmp_path) == ["checkpoint"]


def test_a_link_among_the_copies_is_removed_never_followed_nor_promoted(tmp_path):
    victim = _write(tmp_path / "victim", 9)
    run = tmp_path / "run"
    _write(run / "checkpoint", 4)
    for name in ("checkpoint.partial", ".checkpoint.1.0123abcd.ready", ".checkpoint.old-0123abcd"):
        (run / name).symlink_to(victim, target_is_directory=True)
    recover_folder(run / "checkpoint", _version)
    assert _version(run / "checkpoint") == 4 and _entries(run) == ["checkpoint"] and _entries(victim) == ["data.txt", "version"]


def test_a_writer_discards_every_leftover_copy_before_writing_anew(tmp_path):
    for name in ("checkpoint.partial", "checkpoint.old", "checkpoint.next", ".checkpoint.new-1-0123abcd", ".checkpoint.1.0123abcd.old"):
        _write(tmp_path / name, 1)
    _write(tmp_path / "checkpoint", 2)
    assert len(discard_leftovers(tmp_path / "checkpoint")) == 5
    assert _entries(tmp_path) == ["checkpoint"] and _version(tmp_path / "checkpoint") == 2


def test_swap_names_are_recognised_as_leftovers_and_real_names_are_not():
    assert is_swap_leftover(".checkpoint.123.0123abcd.ready") and is_swap_leftover(".seed_0.4.89abcdef.old")
    assert is_swap_leftover("..checkpoint.1.0123abcd.new.2.89abcdef.new")
    assert not any(map(is_swap_leftover, ("checkpoint", "episode_00004", ".seed_0.lock", ".log.csv.1.0123abcd.tmp")))


# --------------------------------------------------------------------------- one writer at a time

def test_a_second_holder_of_a_lock_is_refused_in_one_line_naming_the_first(tmp_path):
    lock = tmp_path / ".table.lock"
    with hold_lock(lock, lambda holder: f"busy (PID {holder})", remove=True):
        with pytest.raises(RunBusyError, match=rf"^busy \(PID {os.getpid()}\)$"):
            with hold_lock(lock, lambda holder: f"busy (PID {holder})"):
                pass  # pragma: no cover - refused
        assert lock.read_text() == f"{os.getpid()}\n"
    assert not lock.exists()  # removed on release
    with hold_lock(lock, lambda holder: "busy"):  # free again
        pass


def test_an_interrupted_training_is_told_to_resume_when_a_whole_checkpoint_copy_waits_beside_the_folder(tmp_path):
    from crowdnav.cli.train import _how_to_continue

    assert "no checkpoint yet" in _how_to_continue(tmp_path)
    staging = staging_beside(tmp_path / "checkpoint")  # a write under way: not a checkpoint
    assert "no checkpoint yet" in _how_to_continue(tmp_path)
    staging.rename(str(staging).replace(".new", ".ready"))  # killed after it was complete, before it was put in place
    assert "add --resume" in _how_to_continue(tmp_path)
