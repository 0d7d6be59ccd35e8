"""docs/results/tracks/README.md's table says what the shipped reference.json files hold."""

from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TRACKS = ROOT / "docs" / "results" / "tracks"
BASELINES = ("straight", "social_force", "orca", "onboard", "predictive", "oracle", "straight_shield", "social_force_shield")


def _percent(rate: float) -> str:
    return f"{round(rate * 100, 1):.1f}".rstrip("0").rstrip(".") + "%"


def _row(folder: Path) -> str:
    document = json.loads((folder / "reference.json").read_text(encoding="utf-8"))
    entries = {entry["name"]: entry for entry in document["entries"]}
    cells = [_percent(entries[f"baseline_{name}"]["success"]) if f"baseline_{name}" in entries else "refused" for name in BASELINES]
    agents: dict[str, list[dict]] = {}
    for entry in document["entries"]:
        if entry["kind"] == "policy":
            chosen = ", snapshot chosen on validation" if "validation_choice" in entry else ""  # reported apart from the final
            agents.setdefault(f"{entry['experiment']}/{entry['configuration']}{chosen}", []).append(entry)
    seeds = "; ".join(f"`{key}`: " + " / ".join(_percent(e["success"]) for e in sorted(group, key=lambda e: e["seed"]))
                      for key, group in agents.items())
    return f"| {document['track']['name']} ({document['test_episodes']}) | " + " | ".join(cells) + f" | {seeds} |"


def test_track_results_table_matches_the_shipped_reference_files():
    text = (TRACKS / "README.md").read_text(encoding="utf-8")
    table = text.split("<!-- TRACK TABLE -->")[1].split("<!-- /TRACK TABLE -->")[0].strip().splitlines()[2:]
    shipped = {folder.name: _row(folder) for folder in TRACKS.iterdir() if (folder / "reference.json").is_file()}
    assert {line.split(" (")[0].strip("| ") for line in table} == set(shipped)
    for line in table:
        assert line == shipped[line.split(" (")[0].strip("| ")]


def test_every_shipped_track_has_reference_results_with_three_seeds_of_a_reference_agent():
    from crowdnav.evaluation.track import shipped_tracks

    assert {folder.name for folder in TRACKS.iterdir() if (folder / "reference.json").is_file()} == set(shipped_tracks())
    for folder in TRACKS.iterdir():
        if (folder / "reference.json").is_file():
            document = json.loads((folder / "reference.json").read_text(encoding="utf-8"))
            seeds = [entry["seed"] for entry in document["entries"] if entry["kind"] == "policy"]
            assert len(seeds) >= 3, folder.name
