"""A track's reference results: every scripted baseline played on the track's test episodes, small enough to ship.

``crowdnav track reference NAME --out DIR`` writes ``DIR/<track>/``:

* ``baseline_<name>.csv`` per baseline (:data:`REFERENCE_BASELINES`: straight, social_force,
  orca where pyrvo is installed, predictive, and oracle where it does not refuse the track), one
  row per test episode with :data:`COLUMNS`, numbers at 4 decimals;
* ``reference.json``: the track (name, version, fingerprint), the crowdnav commit, and one entry
  per baseline (its label, kind, file, success rate), plus the baselines skipped and why.

Nothing in them depends on the time or the machine, so playing the same commit again writes the
same bytes. It is resumable: a baseline already written by this commit for this version of the
track is kept (``force`` plays it again), and ``reference.json`` is rewritten after each one. The
reference agents' entries (``crowdnav track reference NAME --agents``, :mod:`crowdnav.evaluation.track_agents`)
are kept as they are while the track's version is the same.
Results are published only from a clean checkout: with ``git status --porcelain`` listing anything
outside DIR, it refuses in one line (``allow_dirty`` for tests), and it records the exact commit.
"""

from __future__ import annotations

import json
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

from crowdnav.evaluation.track import Track, TrackError
from crowdnav.evaluation.track_leaderboard import CEILING, REFERENCE_FILE

REFERENCE_BASELINES = ("straight", "social_force", "orca", "predictive", "oracle")
COLUMNS = ("test_seed", "outcome", "collision_kind", "steps", "return", "time_to_goal", "path_length", "spl", "min_human_distance", "psc")
PRIVILEGED = "privileged: the simulator's state"
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
                    log: Callable[[str], None] = print) -> Path:
    """Play every reference baseline on ``track`` into ``out/<track>/``; returns that folder."""
    from crowdnav.evaluation.baselines import BASELINE_PREFIX, BASELINES, scripted_policy
    from crowdnav.evaluation.rollout import HeldOutEpisodes
    from crowdnav.evaluation.storage import atomic_write_text, read_json

    from crowdnav import __version__
    from crowdnav.orca import OrcaUnavailableError
    from crowdnav.planning.oracle import PlannerUnavailable

    folder = Path(out) / track.name
    commit = publishing_commit(Path(out), allow_dirty)
    index = folder / REFERENCE_FILE
    recorded = read_json(index) if index.is_file() else {}
    previous = recorded if not force else {}
    same = previous.get("track") == track.identity() and previous.get("git_commit") == commit
    kept = {entry["name"]: entry for entry in previous.get("entries", []) if same and (folder / entry["file"]).is_file()}
    agents = [entry for entry in recorded.get("entries", []) if entry["name"].startswith(AGENT_PREFIX)  # their rows are no baseline's
              and recorded.get("track") == track.identity() and (folder / entry["file"]).is_file()]
    document: dict[str, Any] = {"track": track.identity(), "git_commit": commit, "crowdnav": __version__, "test_episodes": track.test_episodes,
                                "entries": [], "skipped": []}

    def index_text() -> str:
        return json.dumps({**document, "entries": document["entries"] + agents}, indent=2, sort_keys=True) + "\n"

    for name in REFERENCE_BASELINES:
        configuration = f"{BASELINE_PREFIX}{name}"
        if configuration in kept:
            document["entries"].append(kept[configuration])
            log(f"{track.name}: {configuration} kept (this commit, v{track.version})")
            continue
        try:
            policy = scripted_policy(name)
            played = HeldOutEpisodes(track.env_options(["goal"]), track.seeds)
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
        document["entries"].append({"name": configuration, "label": BASELINES[name], "policy": f"baseline:{name}",
                                    "kind": CEILING if name == "oracle" else "scripted, privileged", "observations": PRIVILEGED,
                                    "file": file, "episodes": len(rows), "success": round(success, 4)})
        atomic_write_text(index, index_text())  # after each one: resumable
        log(f"{track.name}: {configuration} success {success:.0%} on {len(rows)} episodes")
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(index, index_text())
    return folder
