"""A track's leaderboard: a user's policies ranked among the reference results, paired on the shared episodes.

``crowdnav leaderboard --track NAME RESULTS...`` reads two kinds of entries, and nothing else:

* ``crowdnav evaluate POLICY --track NAME`` results below RESULTS (``meta.json`` whose ``track``
  names the track; results of other tracks or of plain ``--scenario`` evaluations are skipped);
* reference folders written by ``crowdnav track reference`` (``reference.json`` and one small CSV
  per scripted baseline; by default the repository's ``docs/results/tracks/<name>/``).

Every entry must carry the track's current version and fingerprint, and a result the setting it
recorded (scenario, overrides, time limit, observations) and the track's test seeds: anything else
is refused in one line (:func:`crowdnav.evaluation.track.check_version`), never ranked beside the
others, so a result played on a modified copy of the track cannot be ranked on it. Files are read
only as regular files of bounded size (no link, FIFO or device), and a reference index names files
of its own folder only. A RESULTS folder holding no result of the track is refused in one line.

Rows are sorted by success rate (then fewer collisions, then name); the privileged ceiling
(``baseline:oracle``, which knows the humans' future) is listed apart, above the ranks. Rates carry
a 95% Wilson interval. The paired statistics compare every row with one *challenger*: the entry
named (``--challenger``), by default the user's best entry that is not a scripted baseline (a
user's evaluation of a reference baseline with the reference's outcomes is shown once, as the
reference). On the episodes both played (the same seeds: the same episodes), ``Δ success`` is the
challenger's success rate minus the row's, and ``p`` is **McNemar's exact test**: under the null
hypothesis that both policies succeed equally often, the episodes where exactly one of them
succeeded split like a fair coin, so with ``b`` and ``c`` such episodes,
``p = min(1, 2 * P[Binomial(b + c, 1/2) <= min(b, c)])`` (two-sided; 1 when ``b + c = 0``).
With many rows some p falls below 0.05 by chance, so ``Holm p`` adjusts them (:func:`holm`).

Nothing here needs pandas or torch: the core install ranks scripted policies.
"""

from __future__ import annotations

import csv
import errno
import html
import io
import json
import math
import os
import stat
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

from crowdnav.evaluation.intervals import wilson
from crowdnav.evaluation.track import Track, TrackError, check_version

from crowdnav.suggest import did_you_mean

REFERENCE_FILE = "reference.json"
"""A reference folder's index: the track, the commit, and one entry per baseline CSV."""
CEILING = "ceiling"
"""The kind of the privileged planner that knows the future: listed apart from the ranks."""
HOLM = "Holm p"
"""The column of McNemar's p adjusted for the number of rows compared with the challenger."""
BASELINE_SPEC = "baseline:"
PRIVILEGED_KIND, ONBOARD_KIND = "scripted, privileged", "scripted, onboard"
"""The kinds of the other scripted baselines: those that read the simulator's state, and ``onboard`` (the robot's own sensing)."""


def baseline_kind(name: str) -> str:
    """The kind of scripted baseline ``name`` (:data:`crowdnav.evaluation.baselines.BASELINES`) in a track's rankings."""
    from crowdnav.evaluation.baselines import ONBOARD_BASELINES

    return CEILING if name == "oracle" else ONBOARD_KIND if name in ONBOARD_BASELINES else PRIVILEGED_KIND


@dataclass
class Entry:
    """One ranked policy: its per-episode outcomes by test seed."""

    name: str
    label: str
    kind: str
    """``policy`` (a user's result), ``scripted, privileged``, ``scripted, onboard`` or :data:`CEILING`."""
    observations: str
    source: Path
    outcomes: dict[int, str]
    hits: dict[int, str] = field(default_factory=dict)
    """Per seed, what a collision hit (``human`` / ``static``; empty otherwise)."""
    reference: bool = False

    def rate(self, outcome: str, seeds: Iterable[int] | None = None) -> float:
        chosen = list(self.outcomes) if seeds is None else list(seeds)
        return sum(self.outcomes[seed] == outcome for seed in chosen) / len(chosen) if chosen else float("nan")


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar p-value for ``b`` and ``c`` discordant pairs (binomial with p = 1/2)."""
    n = b + c
    if n == 0:
        return 1.0
    low = sum(math.comb(n, k) for k in range(min(b, c) + 1))
    return min(1.0, float(Fraction(2 * low, 2 ** n)))  # exact integers: no overflow at thousands of episodes


MAX_TABLE_BYTES = 64 * 2 ** 20
"""A per-episode table read for a leaderboard, at most (10,000 episodes take a few MB)."""
MAX_INDEX_BYTES = 4 * 2 ** 20
"""A ``reference.json`` or ``meta.json``, at most."""
_INDEX_FIELDS = ("name", "label", "kind", "observations", "file")


def read_bounded(path: Path, limit: int) -> str:
    """The UTF-8 text of ``path``: a regular file (no link, FIFO or device) of at most ``limit`` bytes; one TrackError line otherwise."""
    try:  # O_NONBLOCK: a FIFO opens at once (and is refused below) instead of waiting for a writer
        handle = os.open(path, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0))
    except OSError as error:
        reason = "a symbolic link, which a leaderboard does not follow" if error.errno == errno.ELOOP else error.strerror or str(error)
        raise TrackError(f"{path}: cannot read it ({reason})") from None
    with os.fdopen(handle, "rb") as stream:
        info = os.fstat(handle)
        if not stat.S_ISREG(info.st_mode):
            raise TrackError(f"{path}: not a regular file (a FIFO, device or folder); a leaderboard reads only files")
        data = stream.read(limit + 1) if info.st_size <= limit else b""
    if info.st_size > limit or len(data) > limit:
        raise TrackError(f"{path}: more than {limit:,} bytes; not a file a leaderboard reads")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise TrackError(f"{path}: not UTF-8 text (byte {error.start})") from None


def read_index(path: Path) -> Any:
    """A ``reference.json`` or ``meta.json``: bounded, a regular file, JSON; one TrackError line otherwise."""
    try:
        return json.loads(read_bounded(path, MAX_INDEX_BYTES))
    except json.JSONDecodeError as error:
        raise TrackError(f"{path}: not JSON ({error.msg}, line {error.lineno})") from None


def _read_rows(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(read_bounded(path, MAX_TABLE_BYTES), newline="")))


def member(folder: Path, name: str) -> Path:
    """A file a reference index names: a plain name in its own folder (never a path elsewhere, ``..``, or ``/dev/zero``)."""
    if name in ("", ".", "..") or Path(name).name != name or "\\" in name:
        raise TrackError(f"{folder / REFERENCE_FILE}: names the file {name[:80]!r}; a reference index names files of its own folder")
    return folder / name


def _entry_from_rows(track: Track, rows: Sequence[Mapping[str, str]], where: Path, **fields: Any) -> Entry:
    try:
        outcomes = {int(row["test_seed"]): row["outcome"] for row in rows}
        hits = {int(row["test_seed"]): row.get("collision_kind", "") for row in rows}
    except (KeyError, ValueError, TypeError) as error:
        raise TrackError(f"{where}: not a per-episode table with test_seed and outcome ({type(error).__name__}: {error})") from None
    if len(rows) != len(outcomes) or sorted(outcomes) != track.seeds:  # another test set is another ranking
        raise TrackError(f"{where}: played {len(rows)} episodes of seeds {min(outcomes, default='-')}-{max(outcomes, default='-')}; "
                         f"track {track.label} is {track.test_episodes} episodes, seeds {track.seeds[0]}-{track.seeds[-1]}, each once")
    return Entry(outcomes=outcomes, hits=hits, source=where, **fields)


def _check_setting(track: Track, meta: Mapping[str, Any], where: Path) -> None:
    """Refuse a result whose recorded scenario, overrides, time limit or observations are not the track's (a forged copy's)."""
    env: dict[str, Any] = meta["env"] if isinstance(meta.get("env"), dict) else {}
    expected: dict[str, Any] = track.env_options()["overrides"]
    if env.get("scenario") != track.scenario or env.get("overrides") != expected:
        played: dict[str, Any] = env["overrides"] if isinstance(env.get("overrides"), dict) else {}
        differ = [key for key in sorted({*played, *expected}, key=str) if played.get(key) != expected.get(key)]
        raise TrackError(f"{where}: played {env.get('scenario')!r} with "
                         + (", ".join(f"{key}={json.dumps(played.get(key))}" for key in differ[:3]) or "other overrides")
                         + f"; track {track.label} fixes {track.scenario} with "
                         + (", ".join(f"{key}={json.dumps(expected.get(key))}" for key in differ[:3]) or "its overrides")
                         + ": a modified copy of the track is never ranked on it")
    declared = meta.get("observations")
    if isinstance(declared, list):
        try:
            track.check_observations([str(key) for key in declared])
        except TrackError as error:
            raise TrackError(f"{where}: {error}") from None


def _once(entries: Iterable[Entry]) -> list[Entry]:
    """The same entry found twice (a folder named twice, or inside another named one) counts once."""
    seen: dict[tuple[str, bool], Entry] = {}
    for entry in entries:
        seen.setdefault((entry.name, entry.reference), entry)
    return list(seen.values())


def read_entries(track: Track, paths: Iterable[str | Path], *, require: bool = False, skipped: list[str] | None = None) -> list[Entry]:
    """Every entry of ``track`` below ``paths``; refuses (one line) an entry of another version, fingerprint or setting of the track.

    ``require``: a folder holding no entry of the track is refused in one line, naming what it holds;
    ``skipped`` collects what was passed over (results of other tracks, or of no track).
    """
    entries: list[Entry] = []
    for root in paths:
        root = Path(root)
        if not root.exists():
            raise TrackError(f"{root}: no such folder")
        others: list[str] = []
        found = _entries_below(track, root, others)
        if require and not found:
            holds = f" (it holds {_counted(others)})" if others else ""
            raise TrackError(f"{root} holds no result of track {track.label}{holds}: evaluate a policy on it with "
                             f"`crowdnav evaluate POLICY --track {track.name} --out {root}`")
        if skipped is not None and others:
            skipped.append(f"{root}: {_counted(others)}")
        entries += found
    return _once(entries)


def _counted(what: list[str]) -> str:
    return ", ".join(f"{kind} ({count})" for kind, count in sorted(Counter(what).items()))


def _entries_below(track: Track, root: Path, others: list[str]) -> list[Entry]:
    from crowdnav.evaluation.baselines import BASELINE_PREFIX, BASELINES
    from crowdnav.evaluation.storage import META_FILE, TEST_FILE

    entries: list[Entry] = []
    for index in sorted(root.rglob(REFERENCE_FILE)) if root.is_dir() else []:
        document = read_index(index)
        recorded: dict[str, Any] = document["track"] if isinstance(document, dict) and isinstance(document.get("track"), dict) else {}
        if recorded.get("name") != track.name:
            others.append(f"reference results of track {recorded.get('name')}")
            continue
        check_version(track, recorded, str(index.parent))
        items = document.get("entries")
        if not isinstance(items, list) or not all(isinstance(item, dict) and all(isinstance(item.get(key), str) for key in _INDEX_FIELDS)
                                                  for item in items):
            raise TrackError(f"{index}: not a reference index (entries with {', '.join(_INDEX_FIELDS)}, as crowdnav track reference writes)")
        for item in items:
            path = member(index.parent, item["file"])
            entries.append(_entry_from_rows(track, _read_rows(path), path, name=item["name"], label=item["label"], kind=item["kind"],
                                            observations=item["observations"], reference=True))
    for meta_path in sorted(root.rglob(META_FILE)) if root.is_dir() else []:
        if any(part.startswith(".") for part in meta_path.relative_to(root).parts):
            continue  # a result being written or set aside, never a result
        meta = read_index(meta_path)
        meta_track = meta.get("track") if isinstance(meta, dict) else None
        if not isinstance(meta_track, dict) or meta_track.get("name") != track.name:
            others.append(f"results of track {meta_track.get('name')}" if isinstance(meta_track, dict) else "results of no track")
            continue
        if meta.get("status") != "complete":
            others.append(f"unfinished results of track {track.name}")
            continue
        check_version(track, meta_track, str(meta_path.parent))
        _check_setting(track, meta, meta_path.parent)
        configuration = str(meta.get("configuration", meta_path.parent.name)).split("--")[0]
        baseline = str(meta.get("policy", "")).removeprefix("baseline:").replace("-", "_")
        kind = "policy"
        if configuration.startswith(BASELINE_PREFIX) and baseline in BASELINES:
            kind = baseline_kind(baseline)
        observations = meta.get("observations", "")
        entries.append(_entry_from_rows(track, _read_rows(meta_path.parent / TEST_FILE), meta_path.parent, name=configuration,
                                        label=str(meta.get("label", configuration)), kind=kind,
                                        observations=", ".join(map(str, observations)) if isinstance(observations, list) else str(observations)))
    return entries


@dataclass(frozen=True)
class Ranked:
    """A track's leaderboard: the rows in order and the challenger the paired columns compare with."""

    track: Track
    rows: list[Entry]
    challenger: Entry | None
    chosen: str = ""
    """Why this challenger: named, or how the default picked it (the markdown's note says it)."""


def rank(track: Track, entries: Sequence[Entry], challenger: str | None = None) -> Ranked:
    """The entries in leaderboard order (ceiling first, then by success) and the challenger.

    A user's evaluation of a reference baseline with the reference's very outcomes is the same
    row, shown once (the reference's). ``challenger`` names an entry (its name or label); by
    default the best user entry that is not a scripted baseline, else the best user entry, else
    the best ranked one.
    """
    if not entries:
        raise TrackError(f"nothing to rank on track {track.label}: evaluate a policy with `crowdnav evaluate POLICY --track {track.name}` "
                         "and name its results folder (reference results: crowdnav track reference)")
    published = {entry.name: (entry.outcomes, entry.hits) for entry in entries if entry.reference}
    kept = [entry for entry in _once(entries) if entry.reference or entry.kind == "policy"
            or published.get(entry.name) != (entry.outcomes, entry.hits)]
    order = sorted(kept, key=lambda e: (e.kind != CEILING, -e.rate("success"), e.rate("collision"), e.label, e.reference))
    if challenger is not None:
        named = [entry for entry in order if challenger in (entry.name, entry.label, entry.name.replace(BASELINE_SPEC, "baseline_", 1))]
        if not named:
            names = [entry.name for entry in order]
            raise TrackError(f"--challenger: no entry {challenger!r} on track {track.label}'s leaderboard{did_you_mean(challenger, names)}; "
                             f"expected one of: {', '.join(names)}")
        return Ranked(track, order, min(named, key=lambda entry: entry.reference), "named")
    ranked = [entry for entry in order if entry.kind != CEILING]
    for chosen, pool in (("your best entry that is not a scripted baseline", [e for e in ranked if not e.reference and e.kind == "policy"]),
                         ("your best entry", [e for e in ranked if not e.reference]), ("the best ranked entry", ranked)):
        if pool:
            return Ranked(track, order, pool[0], chosen)
    return Ranked(track, order, None)


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjustment of ``p_values`` (same order): controls the chance of any false difference among them."""
    m = len(p_values)
    adjusted, running = [1.0] * m, 0.0
    for place, at in enumerate(sorted(range(m), key=lambda k: p_values[k])):
        running = max(running, min(1.0, (m - place) * p_values[at]))
        adjusted[at] = running
    return adjusted


def paired(challenger: Entry, other: Entry) -> tuple[int, float, float]:
    """(shared episodes, challenger's success minus ``other``'s on them, McNemar's exact p)."""
    shared = sorted(set(challenger.outcomes) & set(other.outcomes))
    mine = [challenger.outcomes[seed] == "success" for seed in shared]
    theirs = [other.outcomes[seed] == "success" for seed in shared]
    b = sum(m and not t for m, t in zip(mine, theirs, strict=True))
    c = sum(t and not m for m, t in zip(mine, theirs, strict=True))
    return len(shared), ((b - c) / len(shared)) if shared else float("nan"), mcnemar_exact(b, c)


def _percent(rate: float) -> str:
    return "-" if rate != rate else f"{100 * rate:.0f}%"


def table_rows(board: Ranked) -> list[dict[str, str]]:
    """The leaderboard's cells, one dict per row (markdown, CSV and HTML all use these)."""
    out = []
    p_values: list[float] = []
    place = 0
    for entry in board.rows:
        n = len(entry.outcomes)
        wins = sum(outcome == "success" for outcome in entry.outcomes.values())
        low, high = wilson(wins, n)
        if entry.kind != CEILING:
            place += 1
        row = {"rank": CEILING if entry.kind == CEILING else str(place), "entry": entry.label + ("" if entry.reference else " *"),
               "kind": entry.kind, "observations": entry.observations or "-",
               "success [95% CI]": f"{_percent(wins / n)} [{_percent(low)}, {_percent(high)}]",
               "collision (human / static)": f"{_percent(entry.rate('collision'))} ({sum(h == 'human' for h in entry.hits.values())} / "
                                             f"{sum(h == 'static' for h in entry.hits.values())})",
               "out of bounds": _percent(entry.rate("out_of_bounds")), "timeout": _percent(entry.rate("truncated")), "episodes": str(n)}
        if board.challenger is not None and entry is not board.challenger:
            shared, delta, p = paired(board.challenger, entry)
            row["Δ success (challenger - row)"] = f"{100 * delta:+.0f} pts"
            row["McNemar p"] = f"{p:.3g}"
            p_values.append(p)
            row["shared"] = str(shared)
        else:
            row["Δ success (challenger - row)"], row["McNemar p"], row["shared"] = "challenger", "-", str(n)
        out.append(row)
    adjusted = iter(holm(p_values))
    for row in out:  # after the shared column: the tables before it keep their columns
        row[HOLM] = "-" if row["McNemar p"] == "-" else f"{next(adjusted):.3g}"
    return out


def note(board: Ranked) -> str:
    """What the columns mean, in plain text (the markdown and the HTML page escape it), after "* not a reference result."."""
    compared = len(board.rows) - (board.challenger is not None)
    challenger = "-" if board.challenger is None else f"{board.challenger.label} ({board.chosen}; --challenger NAME names another)"
    return (f"Challenger: {challenger}. Δ success and McNemar p are paired on the episodes both played (the same seeds): McNemar's "
            "exact test (two-sided binomial test on the episodes where exactly one of the two succeeded). Multiple comparisons: the "
            f"challenger is compared with {compared} rows, so a McNemar p below 0.05 somewhere is likely by chance alone; {HOLM} is "
            "McNemar p adjusted by Holm's step-down method (family-wise error rate), the one to read when asking whether the challenger "
            "differs from any row. 95% CI: Wilson score interval. The ceiling knows the humans' future (privileged) and is not ranked.")


def markdown_cell(text: str) -> str:
    """``text`` safe in a markdown table cell: no HTML, no column break, no code span, one line."""
    escaped = html.escape(text.replace("\\", "\\\\"), quote=False).replace("|", "\\|").replace("`", "\\`")
    return " ".join(escaped.split())  # newlines and tabs: one line


def to_markdown(board: Ranked) -> str:
    """The leaderboard as GitHub markdown: a title naming the track and version, the table, what the columns mean."""
    rows = table_rows(board)
    header = list(rows[0])
    track = board.track
    lines = [f"## Track {markdown_cell(track.label)}: {markdown_cell(track.description)}", "",
             f"Test set: {track.test_episodes} episodes, seeds {track.seeds[0]}-{track.seeds[-1]}; "
             f"time limit {track.time_limit_steps} steps; fingerprint {markdown_cell(track.fingerprint)}.", "",
             "| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    lines += ["| " + " | ".join(markdown_cell(row[column]) for column in header) + " |" for row in rows]
    lines += ["", f"\\* not a reference result. {markdown_cell(note(board))}"]
    return "\n".join(lines) + "\n"


def to_csv(board: Ranked) -> str:
    import io

    rows = table_rows(board)
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=["track", "version", *rows[0]], lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({"track": board.track.name, "version": board.track.version, **row})
    return buffer.getvalue()


def default_reference(track: Track) -> Path | None:
    """The repository's reference results of ``track`` (``docs/results/tracks/<name>``), when crowdnav runs from a clone."""
    folder = Path(__file__).resolve().parents[1] / "docs" / "results" / "tracks" / track.name
    return folder if (folder / REFERENCE_FILE).is_file() else None
