"""Sentences of the docs that state a figure the code can check: the check runs, so a stale number turns CI red."""

from __future__ import annotations

import re

import pytest
from crowdnav.evaluation.baselines import scripted_policy
from crowdnav.evaluation.experiment import load_experiment
from crowdnav.evaluation.rollout import HeldOutEpisodes
from crowdnav.evaluation.track import load_track

from crowdnav.scenario import load_scenario
from tests.paths import REPO


def _text(file: str) -> str:
    return " ".join((REPO / file).read_text(encoding="utf-8").split())


def test_the_figure4_baseline_rates_in_evaluation_md_are_what_the_track_gives():
    sentence = re.search(r"On `figure4` v(\d+) the scripted baselines score, on its (\d+) episodes: straight-to-goal (\d+)%, the "
                         r"social-force robot (\d+)%", _text("docs/evaluation.md"))
    assert sentence, "docs/evaluation.md lost its sentence on the figure4 baselines"
    version, episodes, straight, social = (int(group) for group in sentence.groups())
    track = load_track("figure4")
    assert (version, episodes) == (track.version, track.test_episodes)
    for name, stated in (("straight", straight), ("social_force", social)):
        played = HeldOutEpisodes(track.env_options(["goal"]), track.seeds)
        try:
            rows = played.run(scripted_policy(name), privileged=True)
        finally:
            played.close()
        assert round(100 * sum(row["outcome"] == "success" for row in rows) / len(rows)) == stated, name


@pytest.mark.parametrize(("name", "count", "low", "high"), [("open_space", 5, 0.3, 0.7), ("crowded_open_space", 10, 0.8, 1.2)])
def test_the_library_table_states_the_crowd_each_scenario_has(name, count, low, high):
    row = next(line for line in (REPO / "docs/scenarios.md").read_text(encoding="utf-8").splitlines() if line.startswith(f"| `{name}` |"))
    assert re.search(rf"\b{count} humans[^|]*\(?{low}-{high} m/s", row), row
    humans = load_scenario(name).humans
    assert humans.count == count and list(humans.preferred_speed) == [low, high]


def test_the_main_job_crowd_stated_in_agents_md_is_the_experiment_s():
    stated = re.search(r"today's main job crosses (\d+) humans at ([\d.]+)-([\d.]+) m/s", _text("docs/agents.md"))
    assert stated, "docs/agents.md lost its sentence on the main job's crowd"
    overrides = load_experiment("default").configurations[0].train["overrides"]
    assert (int(stated[1]), [float(stated[2]), float(stated[3])]) == (overrides["humans.count"], overrides["humans.preferred_speed"])
