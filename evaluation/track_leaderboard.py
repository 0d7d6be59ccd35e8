"""A track's leaderboard: a user's policies ranked among the reference results, paired on the shared episodes.

``crowdnav leaderboard --track NAME RESULTS...`` reads two kinds of entries, and nothing else:

* ``crowdnav evaluate POLICY --track NAME`` results below RESULTS (``meta.json`` whose ``track``
  names the track; results of other tracks or of plain ``--scenario`` evaluations are skipped);
* reference folders written by ``crowdnav track reference`` (``reference.json`` and one small CSV
  per scripted baseline; by default the repository's ``docs/results/tracks/<name>/``).

Every entry must carry the track's current version: one of another version is refused in one
line (:func:`crowdnav.evaluation.track.check_version`), never ranked beside the others.

Rows are sorted by success rate (then fewer collisions, then name); the privileged ceiling
(``baseline:oracle``, which knows the humans' future) is listed apart, above the ranks. Rates carry
a 95% Wilson interval. The paired statistics compare every row with one *challenger*: the best
entry that is not a reference result (the user's policy), or the best ranked reference when there
is none. On the episodes both played (the same seeds: the same episodes), ``Δ success`` is the
challenger's success rate minus the row's, and ``p`` is **McNemar's exact test**: under the null
hypothesis that both policies succeed equally often, the episodes where exactly one of them
succeeded split like a fair coin, so with ``b`` and ``c`` such episodes,
``p = min(1, 2 * P[Binomial(b + c, 1/2) <= min(b, c)])`` (two-sided; 1 when ``b + c = 0``).

Nothing here needs pandas or torch: the core install ranks scripted policies.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

from crowdnav.evaluation.intervals import wilson
from crowdnav.evaluation.track import Track, TrackError, check_version

REFERENCE_FILE = "reference.json"
"""A reference folder's index: the track, the commit, and one entry per baseline CSV."""
CEILING = "ceiling"
"""The kind of the privileged planner that knows the future: listed apart from the ranks."""
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


def _read_rows(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8", newline="") as file:
        return list(csv.DictReader(file))


def _entry_from_rows(rows: Sequence[Mapping[str, str]], where: Path, **fields: Any) -> Entry:
    try:
        outcomes = {int(row["test_seed"]): row["outcome"] for row in rows}
        hits = {int(row["test_seed"]): row.get("collision_kind", "") for row in rows}
    except (KeyError, ValueError) as error:
        raise TrackError(f"{where}: not a per-episode table with test_seed and outcome ({type(error).__name__}: {error})") from None
    return Entry(outcomes=outcomes, hits=hits, source=where, **fields)


def read_entries(track: Track, paths: Iterable[str | Path]) -> list[Entry]:
    """Every entry of ``track`` below ``paths``; refuses (one line) an entry of another version of the track."""
    from crowdnav.evaluation.baselines import BASELINE_PREFIX, BASELINES
    from crowdnav.evaluation.storage import META_FILE, TEST_FILE, read_json

    entries: list[Entry] = []
    for root in paths:
        root = Path(root)
        if not root.exists():
            raise TrackError(f"{root}: no such folder")
        for index in sorted(root.rglob(REFERENCE_FILE)) if root.is_dir() else []:
            document = read_json(index)
            if (document.get("track") or {}).get("name") != track.name:
                continue  # another track's reference results
            check_version(track, document.get("track"), str(index.parent))
            for item in document["entries"]:
                entries.append(_entry_from_rows(_read_rows(index.parent / item["file"]), index.parent / item["file"], name=item["name"],
                                                label=item["label"], kind=item["kind"], observations=item["observations"], reference=True))
        for meta_path in sorted(root.rglob(META_FILE)) if root.is_dir() else []:
            if any(part.startswith(".") for part in meta_path.relative_to(root).parts):
                continue  # a result being written or set aside, never a result
            meta = read_json(meta_path)
            recorded = meta.get("track")
            if not recorded or recorded.get("name") != track.name or meta.get("status") != "complete":
                continue
            check_version(track, recorded, str(meta_path.parent))
            configuration = str(meta.get("configuration", meta_path.parent.name)).split("--")[0]
            baseline = str(meta.get("policy", "")).removeprefix("baseline:").replace("-", "_")
            kind = "policy"
            if configuration.startswith(BASELINE_PREFIX) and baseline in BASELINES:
                kind = baseline_kind(baseline)
            observations = meta.get("observations", "")
            entries.append(_entry_from_rows(_read_rows(meta_path.parent / TEST_FILE), meta_path.parent, name=configuration,
                                            label=str(meta.get("label", configuration)), kind=kind,
                                            observations=", ".join(observations) if isinstance(observations, list) else str(observations)))
    seen: dict[tuple[str, bool], Entry] = {}
    for entry in entries:  # a user's own run of a baseline stands beside the shipped one; the same entry twice counts once
        seen.setdefault((entry.name, entry.reference), entry)
    return list(seen.values())


@dataclass(frozen=True)
class Ranked:
    """A track's leaderboard: the rows in order and the challenger the paired columns compare with."""

    track: Track
    rows: list[Entry]
    challenger: Entry | None


def rank(track: Track, entries: Sequence[Entry]) -> Ranked:
    """The entries in leaderboard order (ceiling first, then by success) and the challenger."""
    if not entries:
        raise TrackError(f"nothing to rank on track {track.label}: evaluate a policy with `crowdnav evaluate POLICY --track {track.name}` "
                         "and name its results folder (reference results: crowdnav track reference)")
    order = sorted(entries, key=lambda e: (e.kind != CEILING, -e.rate("success"), e.rate("collision"), e.label, e.reference))
    ranked = [entry for entry in order if entry.kind != CEILING]
    users = [entry for entry in ranked if not entry.reference]
    challenger = users[0] if users else (ranked[0] if ranked else None)
    return Ranked(track, order, challenger)


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
            row["shared"] = str(shared)
        else:
            row["Δ success (challenger - row)"], row["McNemar p"], row["shared"] = "challenger", "-", str(n)
        out.append(row)
    return out


def to_markdown(board: Ranked) -> str:
    """The leaderboard as GitHub markdown: a title naming the track and version, the table, what the columns mean."""
    rows = table_rows(board)
    header = list(rows[0])
    lines = [f"## Track {board.track.label}: {board.track.description}", "",
             f"Test set: {board.track.test_episodes} episodes, seeds {board.track.seeds[0]}-{board.track.seeds[-1]}; "
             f"time limit {board.track.time_limit_steps} steps; fingerprint {board.track.fingerprint}.", "",
             "| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    lines += ["| " + " | ".join(row[column] for column in header) + " |" for row in rows]
    challenger = board.challenger.label if board.challenger is not None else "-"
    lines += ["", f"\\* not a reference result. Challenger: {challenger}. Δ success and McNemar p are paired on the episodes both "
              "played (the same seeds): McNemar's exact test (two-sided binomial test on the episodes where exactly one of the two "
              "succeeded). 95% CI: Wilson score interval. The ceiling knows the humans' future (privileged) and is not ranked."]
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
