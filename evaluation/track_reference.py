"""A track's reference results: every scripted baseline played on the track's test episodes, small enough to ship.

``crowdnav track reference NAME --out DIR`` writes ``DIR/<track>/``:

* ``baseline_<name>.csv`` per baseline (:data:`REFERENCE_BASELINES`: straight, social_force,
  orca where pyrvo is installed, onboard where the track allows what it reads (the ``plan``
  observation's inputs: the tracker and the map), predictive, and oracle where it does not refuse
  the track; ``straight_shield`` and ``social_force_shield``, those two with the action-time shield in their loop,
  where the track allows what the shield reads, as ``onboard``), one row per test episode with :data:`COLUMNS`,
  numbers at 4 decimals;
* ``reference.json``: the track (name, version, fingerprint), the crowdnav commit, and one entry
  per baseline (its label, kind, what it observes, file, success rate; ``git_commit`` where it was
  played at another commit than the document's), plus the baselines skipped and why.

Nothing in them depends on the time or the machine, so playing the same commit again writes the
same bytes. It is resumable: a baseline already written by this commit for this version of the
track is kept (``force`` plays it again), and ``reference.json`` is rewritten after each one.
``only`` (``--baseline NAME``) plays just the baselines named (one added to
:data:`REFERENCE_BASELINES` later, say) and keeps every other baseline of this version of the track
as it was published, rows and commit: the document's ``git_commit`` stays theirs and each entry
played now names its own. The reference agents' entries (``crowdnav track reference NAME --agents``,
:mod:`crowdnav.evaluation.track_agents`) are kept as they are while the track's version is the same.
Results are published only from a clean checkout: with ``git status --porcelain`` listing anything
outside DIR, it refuses in one line (``allow_dirty`` for tests), and it records the exact commit.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from crowdnav.evaluation.track import Track, TrackError
from crowdnav.evaluation.track_leaderboard import REFERENCE_FILE, baseline_kind, member, read_index

REFERENCE_BASELINES = ("straight", "social_force", "orca", "onboard", "predictive", "oracle", "straight_shield", "social_force_shield")
COLUMNS = ("test_seed", "outcome", "collision_kind", "steps", "return", "time_to_goal", "path_length", "spl", "min_human_distance", "psc")
AGENT_PREFIX = "agent_"
DIRTY = "+dirty"
"""The suffix of a commit with uncommitted changes."""
"""Entries of reference agents (:mod:`crowdnav.evaluation.track_agents`), which playing the baselines again keeps."""


def source_state(out: Path) -> str:
    """The checkout's commit; :class:`TrackError` (one line) when anything outside ``out`` is changed or untracked."""
    root = Path(__file__).resolve().parents[1]
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=30, check=True).stdout.strip()
        status = subprocess.run(["git", "status", "--porcelain"], cwd=root, capture_output=True, text=True, timeout=60, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        raise TrackError("reference results are published from a git checkout of crowdnav, and this is none (--allow-dirty to write "
                         "them anyway, marked +dirty)") from None
    inside = out.resolve()
    changed = []
    for line in status.splitlines():
        path = (root / line[3:].split(" -> ")[-1].strip('"')).resolve()
        if path != inside and inside not in path.parents:
            changed.append(line[3:])
    if changed:
        raise TrackError(f"the checkout has uncommitted changes ({len(changed)} paths, e.g. {changed[0]}): reference results are published "
                         "from a clean commit; commit or remove them first (--allow-dirty to write them anyway, marked +dirty)")
    return commit



def publishing_commit(out: Path, allow_dirty: bool) -> str:
    """The commit results written to ``out`` are published at: :func:`source_state`'s, or with ``allow_dirty`` the
    checkout's commit marked ``+dirty`` where it has changes (otherwise its :class:`TrackError`)."""
    try:
        return source_state(out)
    except TrackError:
        if not allow_dirty:
            raise
        from crowdnav.evaluation.provenance import git_commit

        return (git_commit() or "unknown").removesuffix(DIRTY) + DIRTY

def _cell(value: Any) -> str:
    if isinstance(value, str):
        return value
    if isinstance(value, int):
        return str(value)
    number = float(value)
    return "nan" if number != number else f"{number:.4f}"


def reference_csv(rows: list[dict[str, Any]]) -> str:
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    writer.writerows([_cell(row[column]) for column in COLUMNS] for row in rows)
    return buffer.getvalue()


def write_reference(track: Track, out: str | Path, *, allow_dirty: bool = False, force: bool = False,
                    only: Sequence[str] | None = None, log: Callable[[str], None] = print) -> Path:
    """Play every reference baseline (``only``: those named) on ``track`` into ``out/<track>/``; returns that folder."""
    from crowdnav.evaluation.baselines import (
        BASELINE_PREFIX,
        BASELINE_READS,
        BASELINES,
        SHIELDED_BASELINES,
        baseline_observations,
        scripted_policy,
        shielded,
    )
    from crowdnav.evaluation.rollout import HeldOutEpisodes
    from crowdnav.evaluation.storage import atomic_write_text

    from crowdnav import __version__
    from crowdnav.planning.oracle import PlannerUnavailable
    from crowdnav.sim.orca_solver import OrcaUnavailableError

    unknown = [name for name in only or () if name not in REFERENCE_BASELINES]
    if unknown:
        raise TrackError(f"unknown reference baseline {unknown[0]!r}; expected some of {', '.join(REFERENCE_BASELINES)}")
    folder = Path(out) / track.name
    commit = publishing_commit(Path(out), allow_dirty)
    index = folder / REFERENCE_FILE
    recorded = read_index(index) if index.is_file() else {}
    same = recorded.get("track") == track.identity()

    def there(entry: dict[str, Any]) -> bool:  # a file of this folder only, never one a planted index names elsewhere
        try:
            return (path := member(folder, str(entry["file"]))).is_file() and not path.is_symlink()
        except TrackError:
            return False

    published = {entry["name"]: {"git_commit": recorded.get("git_commit"), **entry} for entry in recorded.get("entries", [])
                 if same and not entry["name"].startswith(AGENT_PREFIX) and there(entry)}
    """This version's baselines as published, each with the commit that played it."""
    agents = [entry for entry in recorded.get("entries", []) if entry["name"].startswith(AGENT_PREFIX)  # their rows are no baseline's
              and same and there(entry)]
    playing = REFERENCE_BASELINES if only is None else tuple(only)
    keeping = same and only is not None and recorded.get("git_commit") is not None  # the others stay as published
    document: dict[str, Any] = {"track": track.identity(), "git_commit": recorded["git_commit"] if keeping else commit,
                                "crowdnav": recorded.get("crowdnav", __version__) if keeping else __version__,
                                "test_episodes": track.test_episodes, "entries": [], "skipped": []}

    def add(entry: dict[str, Any]) -> None:
        """An entry, naming its own commit where it is not the document's."""
        played_at = entry.pop("git_commit")
        document["entries"].append({**entry, **({"git_commit": played_at} if played_at != document["git_commit"] else {})})

    def index_text() -> str:
        return json.dumps({**document, "entries": document["entries"] + agents}, indent=2, sort_keys=True) + "\n"

    for name in REFERENCE_BASELINES:
        configuration = f"{BASELINE_PREFIX}{name}"
        before = published.get(configuration)
        if name not in playing:  # only the baselines named are played: the others as published
            if before is not None:
                add(dict(before))
                log(f"{track.name}: {configuration} kept (as published at {str(before['git_commit'])[:12]}, v{track.version})")
            document["skipped"].extend(skip for skip in recorded.get("skipped", []) if same and skip["name"] == configuration)
            continue
        if before is not None and not force and before["git_commit"] == commit:
            add(dict(before))
            log(f"{track.name}: {configuration} kept (this commit, v{track.version})")
            continue
        observations = baseline_observations(name)
        try:
            # onboard reads what the plan observation carries, the shield the same (the tracker, the map): the track must allow it
            reads = observations if isinstance(observations, list) else ["plan"] if name in SHIELDED_BASELINES else []
            if reads:
                try:
                    track.check_observations(reads)
                except TrackError as error:
                    raise PlannerUnavailable(f"baseline:{name} reads what the plan observation carries (the tracker, the map): {error}") from None
            policy = scripted_policy(name)
            played = HeldOutEpisodes(shielded(name, track.env_options(["goal"])), track.seeds)
            try:
                rows = played.run(policy, privileged=True)
            finally:
                played.close()
        except (OrcaUnavailableError, PlannerUnavailable) as error:
            reason = str(error).splitlines()[0]
            document["skipped"].append({"name": configuration, "reason": reason})
            log(f"{track.name}: {configuration} skipped: {reason}")
            continue
        file = f"{configuration}.csv"
        folder.mkdir(parents=True, exist_ok=True)
        atomic_write_text(folder / file, reference_csv(rows))
        success = sum(row["outcome"] == "success" for row in rows) / len(rows)
        add({"name": configuration, "label": BASELINES[name], "policy": f"baseline:{name}", "kind": baseline_kind(name),
             "observations": BASELINE_READS[name], "file": file, "episodes": len(rows),
             "success": round(success, 4), "git_commit": commit})
        atomic_write_text(index, index_text())  # after each one: resumable
        log(f"{track.name}: {configuration} success {success:.0%} on {len(rows)} episodes")
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(index, index_text())
    return folder
