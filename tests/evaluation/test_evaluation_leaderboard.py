"""Leaderboard and curves: known values on a hand-made results table, byte-identical regeneration, commands."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pandas as pd
import pytest
from crowdnav.evaluation.benchmark import describe_outcome
from crowdnav.evaluation.curves import curves_figure, rate_curves
from crowdnav.evaluation.intervals import wilson
from crowdnav.evaluation.leaderboard import bootstrap_iqm, interquartile_mean, leaderboard_table, to_csv, to_markdown, write_leaderboard
from crowdnav.evaluation.metrics import METRIC_COLUMNS

from crowdnav.cli import main
from crowdnav.sim.simulator import OUTCOMES
from tests.evaluation.evaluation_tiny import tiny_results

# configuration a: seed 0 always succeeds; seed 1 collides in evaluations 0-1 then succeeds; seed 2 is always truncated.
# configuration b: always collides.
_OUTCOMES = {("a", 0): ["success"] * 4, ("a", 1): ["collision", "collision", "success", "success"], ("a", 2): ["truncated"] * 4,
             ("b", 0): ["collision"] * 4}


def synthetic_results(test_episodes: int = 4, eval_every: int = 10):
    rows, metas = [], []
    for (configuration, seed), outcomes in _OUTCOMES.items():
        for evaluation, outcome in enumerate(outcomes):
            for episode in range(test_episodes):
                row = {"experiment": "x", "configuration": configuration, "label": configuration.upper(), "seed": seed,
                       "training_episodes": eval_every * (evaluation + 1), "evaluation": evaluation, "test_episode": episode,
                       "test_seed": episode, "outcome": outcome, "collision_kind": "", "return": 0.0}
                row.update({metric: 1.0 for metric in METRIC_COLUMNS})
                row["time_to_goal"] = 5.0 if outcome == "success" else math.nan
                row["spl"] = 0.8 if outcome == "success" else 0.0
                rows.append(row)
        metas.append({"experiment": "x", "configuration": configuration, "seed": seed, "wall_time_s": 10.0 * (seed + 1),
                      "env_steps": {"total": 1000 * (seed + 1)}, "protocol": {"final_evaluations": 2, "window": 2}})
    return pd.DataFrame(rows), metas


def test_leaderboard_values_on_hand_made_results():
    tests, metas = synthetic_results()
    table = leaderboard_table(tests, metas)
    assert list(table["configuration"]) == ["a", "b"]  # best final success first
    a = table.iloc[0]
    assert a["seeds"] == 3
    assert a["final_success_mean"] == pytest.approx(2 / 3) and a["final_success_std"] == pytest.approx(math.sqrt(1 / 3))
    assert a["final_collision_mean"] == 0.0 and a["final_truncated_mean"] == pytest.approx(1 / 3)
    assert a["final_out_of_bounds_mean"] == 0.0  # no out_of_bounds episode (e.g. results written before it existed): rate 0
    assert a["success_iqm"] == pytest.approx(2 / 3) and a["success_iqm_low"] <= 2 / 3 <= a["success_iqm_high"]
    assert a["success_auc_mean"] == pytest.approx(0.5) and a["success_auc_std"] == pytest.approx(0.5)  # per seed 1, 0.5, 0
    assert a["time_to_goal"] == 5.0  # successful episodes only
    assert a["spl"] == pytest.approx(0.8 * 2 / 3)
    assert a["env_steps"] == 2000.0 and a["wall_time_s"] == 20.0
    b = table.iloc[1]
    assert b["final_collision_mean"] == 1.0 and b["final_success_std"] == 0.0 and math.isnan(b["time_to_goal"])
    markdown = to_markdown(table)
    assert markdown.splitlines()[0].startswith("| configuration | seeds | success [95% CI] | collision [95% CI] | out_of_bounds [95% CI] |")
    low, high = a["final_success_low"], a["final_success_high"]
    assert a["interval"] == "bootstrap" and 0.0 <= low < 2 / 3 < high <= 1.0  # runs and episodes resampled: wide with 3 runs
    assert markdown.splitlines()[2].startswith(f"| A | 3 | 0.667 [{low:.3f}, {high:.3f}] | 0.000 [0.000, 0.000] |")
    assert "95% CI: two-stage bootstrap over runs, then their final test episodes; Wilson score interval" in markdown


def test_one_run_shows_a_wilson_interval_and_no_spread_that_one_run_cannot_have():
    tests, metas = synthetic_results()
    table = leaderboard_table(tests, metas).set_index("configuration")
    b = table.loc["b"]
    assert b["interval"] == "wilson" and (b["final_success_low"], b["final_success_high"]) == (0.0, pytest.approx(0.3244, abs=1e-4))
    row = next(line for line in to_markdown(table.reset_index()).splitlines() if line.startswith("| B |"))
    assert "±" not in row and "| B | 1 | 0.000 [0.000, 0.324] | 1.000 [0.676, 1.000] |" in row
    assert row.split(" | ")[7] == "-"  # no IQM interval from one run


def test_rows_measured_on_different_test_sets_are_ranked_in_separate_tables():
    tests, metas = synthetic_results()
    for meta in metas:
        meta["env"] = {"scenario": "open_space" if meta["configuration"] == "a" else "room_furniture", "overrides": {}}
    markdown = to_markdown(leaderboard_table(tests, metas))
    assert markdown.startswith("2 test sets: rows measured on different scenarios or test episodes are ranked in separate tables.")
    assert "### open_space: 20 episodes, seeds 0-19" in markdown and "### room_furniture: 20 episodes, seeds 0-19" in markdown
    assert markdown.count("| configuration |") == 2


def test_leaderboard_and_curves_count_out_of_bounds_episodes():
    tests, metas = synthetic_results()
    # configuration b leaves the world in its last two evaluations instead of colliding
    tests.loc[(tests["configuration"] == "b") & (tests["evaluation"] >= 2), "outcome"] = "out_of_bounds"
    table = leaderboard_table(tests, metas).set_index("configuration")
    assert table.loc["b", "final_out_of_bounds_mean"] == 1.0 and table.loc["b", "final_collision_mean"] == 0.0
    assert table.loc["a", "final_out_of_bounds_mean"] == 0.0
    for name in OUTCOMES:  # every outcome's mean and std, in the CSV and the markdown
        assert f"final_{name}_mean" in to_csv(table.reset_index()).splitlines()[0]
    assert "| B | 1 | 0.000 [0.000, 0.324] | 0.000 [0.000, 0.324] | 1.000 [0.676, 1.000] | 0.000 [0.000, 0.324] |" in to_markdown(table.reset_index())
    curves = rate_curves(tests, window=2)
    assert set(curves["metric"]) == set(OUTCOMES)
    b = curves[(curves["configuration"] == "b") & (curves["metric"] == "out_of_bounds")]
    np.testing.assert_allclose(b["rate"], [0.0] * 8 + [0.5] + [1.0] * 7)
    figure = curves_figure(tests, window=2)
    assert [axis.get_title() for axis in figure.axes] == ["success rate", "collision rate", "out of bounds rate", "truncated rate"]


def test_results_written_before_out_of_bounds_existed_still_load_and_rank(tmp_path_factory, tmp_path):
    old = tmp_path / "old"
    shutil.copytree(tiny_results(tmp_path_factory), old)
    for meta_path in old.rglob("meta.json"):  # what such a run wrote: no out_of_bounds rate, no out_of_bounds episode
        meta = json.loads(meta_path.read_text())
        meta["final"].pop("out_of_bounds")
        meta_path.write_text(json.dumps(meta))
        episodes = meta_path.parent / "test_episodes.csv"
        episodes.write_text(episodes.read_text().replace(",out_of_bounds,", ",truncated,"))
    table, written = write_leaderboard([old], tmp_path / "board")
    assert (table["final_out_of_bounds_mean"] == 0.0).all() and (table["final_out_of_bounds_std"] == 0.0).all()
    assert "out_of_bounds" in written[0].read_text().splitlines()[0]
    assert main(["plot", str(old), "--out", str(tmp_path / "curves")]) == 0
    summary = {"experiment": "tiny", "configuration": "lidar", "seed": 0, "status": "skipped", "final_success": 0.5,
               "final_collision": 0.25, "final_truncated": 0.25, "env_steps": 100, "wall_time_s": 3.0}
    assert "success 50%, collision 25%, out_of_bounds 0%, truncated 25%" in describe_outcome(summary)


def test_interquartile_mean_drops_a_quarter_at_each_end():
    assert interquartile_mean(np.arange(1, 9)) == pytest.approx(4.5)
    assert interquartile_mean(np.array([0.0, 1.0, 100.0, 2.0, 3.0])) == pytest.approx(2.0)  # n=5: one dropped each side
    assert interquartile_mean(np.array([3.0])) == 3.0


def test_bootstrap_interval_is_seeded_and_brackets_the_iqm():
    values = np.array([0.2, 0.5, 0.55, 0.6, 0.9])
    first, second = bootstrap_iqm(values), bootstrap_iqm(values)
    assert first == second
    iqm, low, high = first
    assert low <= iqm <= high and low < high
    assert bootstrap_iqm(np.array([0.4, 0.4, 0.4])) == pytest.approx((0.4, 0.4, 0.4))


def test_rate_curves_slide_over_test_episodes_placed_along_training():
    tests, _ = synthetic_results()
    curves = rate_curves(tests, window=2)
    seed1 = curves[(curves["configuration"] == "a") & (curves["seed"] == 1) & (curves["metric"] == "success")]
    # 4 evaluations x 4 test episodes at x = 10 k + 2.5 (j + 1); outcomes switch to success at evaluation 2
    np.testing.assert_allclose(seed1["training_episodes"], 2.5 * np.arange(1, 17))
    np.testing.assert_allclose(seed1["rate"], [0.0] * 8 + [0.5] + [1.0] * 7)


def test_leaderboard_regenerates_byte_for_byte(tmp_path_factory, tmp_path):
    results = tiny_results(tmp_path_factory)
    _, first = write_leaderboard([results], tmp_path / "one")
    copy = tmp_path / "copy"
    shutil.copytree(results, copy)
    _, second = write_leaderboard([copy], tmp_path / "two")
    for a, b in zip(first, second, strict=True):
        assert a.read_bytes() == b.read_bytes()
    table = pd.read_csv(first[1])
    learned = table[table["kind"] == "learned"]
    assert sorted(learned["configuration"]) == ["closest", "lidar"] and (learned["seeds"] == 2).all()
    assert sorted(table.loc[table["kind"] == "baseline", "configuration"]) == ["baseline_onboard", "baseline_oracle", "baseline_predictive",
                                                                              "baseline_social_force", "baseline_straight"]
    # a baseline's one play is repeated at every evaluation: its interval counts each test episode once
    baseline = table[table["configuration"] == "baseline_straight"].iloc[0]
    played = pd.read_csv(next(results.rglob("baseline_straight/*/test_episodes.csv")))
    assert played["evaluation"].nunique() > 1 and baseline["test_episodes"] == played["test_episode"].nunique()
    wins = round(baseline["final_success_mean"] * baseline["test_episodes"])
    assert (baseline["final_success_low"], baseline["final_success_high"]) == pytest.approx(wilson(wins, baseline["test_episodes"]))


def test_plot_and_leaderboard_commands_write_their_files(tmp_path_factory, capsys):
    results = tiny_results(tmp_path_factory)
    assert main(["plot", str(results)]) == 0
    assert main(["leaderboard", str(results)]) == 0
    out = capsys.readouterr().out
    for name in ("curves.png", "curves.pdf", "leaderboard.md", "leaderboard.csv"):
        assert f"wrote {results / name}" in out and (results / name).stat().st_size > 0
    assert (results / "curves.png").read_bytes().startswith(b"\x89PNG")


def test_seed_bands_stay_inside_zero_one_for_std_and_bootstrap_ci():
    from crowdnav.evaluation.curves import seed_band

    rates = np.array([[0.0, 0.0, 1.0], [1.0, 1.0, 0.0], [0.5, 0.5, 0.5]])  # x by seed
    for band in ("std", "ci"):
        mean, low, high = seed_band(rates, band)
        np.testing.assert_allclose(mean, [1 / 3, 2 / 3, 0.5])
        assert (low >= 0).all() and (high <= 1).all() and (low <= mean).all() and (mean <= high).all()
    _, low, high = seed_band(rates, "std")
    assert low[0] == 0.0 and high[1] == 1.0  # mean -+ std would leave [0, 1] here: clipped
    _, low, high = seed_band(rates, "ci")
    assert low[2] == high[2] == 0.5  # identical seeds: no uncertainty
    with pytest.raises(ValueError, match="unknown band"):
        seed_band(rates, "sem")


def test_curves_differ_by_style_and_marker_and_the_legend_sits_outside_the_panels(tmp_path_factory):
    from crowdnav.evaluation.storage import load_results

    tests, _, _ = load_results([tiny_results(tmp_path_factory)])
    configurations = tests.loc[~tests["configuration"].str.startswith("baseline_"), "label"].nunique()
    for band in ("std", "ci"):
        figure = curves_figure(tests, window=2, band=band)
        for axis in figure.axes:
            marked = [line for line in axis.get_lines() if line.get_marker() not in (None, "None", "")]
            assert len({(line.get_linestyle(), line.get_marker()) for line in marked}) == len(marked) == configurations >= 2
            assert axis.get_legend() is None
        expected = {"std": "one standard deviation", "ci": "95% bootstrap CI of the mean"}[band]
        assert len(figure.legends) == 1 and figure.legends[0].get_title().get_text().endswith(expected)
