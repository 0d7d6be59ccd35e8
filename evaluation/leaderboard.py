"""The leaderboard: one row per configuration, from any results folders, as markdown and CSV.

Columns (definitions in docs/evaluation.md):

* scenario and test set: the environment the rows were measured in (the scenario's name, with a
  short hash when it had overrides) and its held-out episodes (count and seeds). Rows measured on
  different test sets are never ranked together: the markdown has one table per test set;
* final success / collision / out_of_bounds / truncated (:data:`crowdnav.sim.simulator.OUTCOMES`):
  per run, the rate over the test episodes of the last ``final_evaluations`` evaluations; mean
  and standard deviation (ddof 1; 0 with one seed) over seeds, and a 95% interval
  (:mod:`crowdnav.evaluation.intervals`: Wilson for one run, a two-stage bootstrap over runs and episodes
  for several). Rates are counted from the episodes' ``outcome`` column, so results written
  before ``out_of_bounds`` existed rank with 0; collisions are also split by what was hit
  (``collision_human``, ``collision_static``);
* IQM of final success: interquartile mean over runs, with a 95% percentile confidence
  interval from a stratified bootstrap (Agarwal et al. 2021; one stratum per configuration,
  2000 resamples, seeded); shown for two runs or more;
* success AUC: per run, the mean of the success rate of each evaluation (area under the
  success curve divided by its length: sample efficiency); mean and std over seeds;
* social metrics: over the final test episodes of all seeds: mean SPL, STL, path length, time to
  goal (successful episodes), minimum human distance, intimate and personal zone shares,
  personal-space compliance, mean jerk and cumulative social force; median minimum time to
  collision (results written before STL and PSC existed show ``-`` there);
* seeds: the runs ranked; ``seeds_expected`` (CSV) also counts the runs the experiment plans that
  are not finished or whose tables are missing or damaged (the markdown says ``1 of 2`` and names
  each such run under the table: a missing seed is never left out silently);
* env steps and wall time: mean per run;
* budget: the learned runs' training budget in their protocol's unit, ``700 episodes`` or
  ``2,000,000 env steps`` (``-`` for the scripted baselines and untrained policies). The markdown
  says it once under the table (``budget: 700 episodes per run``) when every learned row shares it, else in a column.

Scripted baselines (:mod:`crowdnav.evaluation.baselines`, ``kind`` baseline) are ranked with the learned
configurations, on the same test episodes; their one deterministic run counts as one seed.

Regenerating from the same results writes the same bytes: rows sorted by final success
(then experiment and configuration), fixed float formats, nothing time-dependent.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.evaluation.baselines import is_baseline
from crowdnav.evaluation.evaluate import scenario_key
from crowdnav.evaluation.intervals import rate_interval
from crowdnav.evaluation.protocol import Protocol, describe_budget
from crowdnav.evaluation.storage import MissingRun

from crowdnav.sim.simulator import OUTCOMES

BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
SOCIAL_MEANS = ("spl", "stl", "path_length", "time_to_goal", "min_human_distance", "intimate_share", "personal_share", "psc",
                "mean_jerk", "social_force", "group_intrusions")
"""Metrics averaged over the final test episodes (time_to_goal over the successful ones)."""


def interquartile_mean(values: np.ndarray, axis: int = -1) -> np.ndarray:
    """Mean of the middle half: drop ``floor(n / 4)`` values at each end (``scipy.stats.trim_mean(x, 0.25)``)."""
    ordered = np.sort(np.asarray(values, dtype=float), axis=axis)
    n = ordered.shape[axis]
    cut = n // 4
    return np.take(ordered, range(cut, n - cut), axis=axis).mean(axis=axis)


def bootstrap_iqm(values: np.ndarray, *, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED,
                  confidence: float = 0.95) -> tuple[float, float, float]:
    """(IQM, low, high): the IQM of ``values`` (one per run) and its percentile bootstrap interval.

    Runs are resampled with replacement within the configuration (the stratum), ``resamples``
    times, from ``numpy.random.default_rng(seed)``.
    """
    values = np.asarray(values, dtype=float)
    rng = np.random.default_rng(seed)
    samples = values[rng.integers(0, len(values), size=(resamples, len(values)))]
    estimates = interquartile_mean(samples, axis=1)
    tail = (1.0 - confidence) / 2.0 * 100.0
    low, high = np.percentile(estimates, [tail, 100.0 - tail])
    return float(interquartile_mean(values)), float(low), float(high)


def _std(values: np.ndarray) -> float:
    return float(np.std(values, ddof=1)) if len(values) > 1 else 0.0


def measured_on(meta: dict[str, Any]) -> tuple[str, str]:
    """(scenario key, held-out episodes) a run was measured on, e.g. ``("room_furniture-1a2b3c4d", "20 episodes, seeds 0-19")``."""
    env = meta.get("env") or meta.get("config") or {}
    scenario = str(env.get("scenario", "?"))
    protocol = Protocol(**meta["protocol"])  # older files leave defaults out
    first, count = protocol.test_seed_base, protocol.test_episodes
    return scenario_key(scenario, dict(env.get("overrides") or {})), f"{count} episodes, seeds {first}-{first + count - 1}"


def leaderboard_table(tests: Any, metas: list[dict[str, Any]], missing: Sequence[MissingRun] = ()) -> Any:
    """The leaderboard as a DataFrame (numbers unformatted), one row per (experiment, configuration).

    ``missing``: the runs left out (:func:`crowdnav.evaluation.storage.load_results`); ``seeds_expected``
    counts them with the ranked ones, and the table's ``attrs["missing"]`` keeps them for the notes.
    """
    import pandas as pd

    absent = Counter((gap.experiment, gap.configuration) for gap in missing)

    final_count = {meta["experiment"]: meta["protocol"]["final_evaluations"] for meta in metas}
    run_meta = {(meta["experiment"], meta["configuration"], meta["seed"]): meta for meta in metas}
    rows = []
    for (experiment, configuration), frame in tests.groupby(["experiment", "configuration"], sort=True):
        last = frame.groupby("seed")["evaluation"].transform("max")
        final = frame[frame["evaluation"] > last - final_count[experiment]]
        # a shared robot policy's rows: one per robot per test episode (evaluation/robot_rollout.py); rates average over robots
        per_robot = "robot" in final and final["robot"].notna().any() and bool((final["robot"] != "").any())
        if is_baseline(configuration):  # one deterministic play, its rows repeated per evaluation: count each episode once
            final = final.drop_duplicates(["seed", "test_episode", "robot"] if per_robot else ["seed", "test_episode"])
        row: dict[str, Any] = {"experiment": experiment, "configuration": configuration, "label": frame["label"].iloc[0],
                               "kind": "baseline" if is_baseline(configuration) else "learned", "seeds": int(frame["seed"].nunique())}
        row["seeds_expected"] = row["seeds"] + absent[(experiment, configuration)]
        sets = {measured_on(run_meta[(experiment, configuration, seed)]) for seed in frame["seed"].unique()
                if (experiment, configuration, seed) in run_meta}
        row["scenario"], row["test_set"] = sorted(sets)[0] if len(sets) == 1 else ("mixed", "mixed")
        row["test_episodes"] = int(final.groupby("seed").size().iloc[0])  # per run, over the final evaluations
        if per_robot:  # robot episodes: one row per robot per test episode
            row["test_episodes"] //= int(final["robot"].nunique())
        kinds = final["collision_kind"].fillna("") if "collision_kind" in final else None
        for outcome in (*OUTCOMES, "collision_human", "collision_static"):
            hits = final["outcome"] == outcome if outcome in OUTCOMES else (final["outcome"] == "collision") & (kinds == outcome[10:])
            runs = [group.to_numpy(dtype=float) for _, group in hits.groupby(final["seed"])]
            rates = np.array([run.mean() for run in runs])
            row[f"final_{outcome}_mean"], row[f"final_{outcome}_std"] = float(rates.mean()), _std(rates)
            row[f"final_{outcome}_low"], row[f"final_{outcome}_high"], row["interval"] = rate_interval(runs)
            if outcome == "success":
                row["success_iqm"], row["success_iqm_low"], row["success_iqm_high"] = bootstrap_iqm(rates)
        auc = (frame.assign(hit=frame["outcome"] == "success").groupby(["seed", "evaluation"])["hit"].mean()
               .groupby("seed").mean().to_numpy())
        row["success_auc_mean"], row["success_auc_std"] = float(auc.mean()), _std(auc)
        for metric in SOCIAL_MEANS:
            present = metric in final and final[metric].notna().any()
            row[metric] = float(np.nanmean(final[metric])) if present else float("nan")
        if "min_human_distance" in final:
            row["min_human_distance"] = met_mean(final["min_human_distance"].to_numpy(dtype=float))
        row["min_time_to_collision"] = float(np.median(final["min_time_to_collision"]))
        metas_here = [run_meta[(experiment, configuration, seed)] for seed in sorted(frame["seed"].unique())
                      if (experiment, configuration, seed) in run_meta]
        row["env_steps"] = float(np.mean([m["env_steps"]["total"] for m in metas_here])) if metas_here else float("nan")
        row["wall_time_s"] = float(np.mean([m["wall_time_s"] for m in metas_here])) if metas_here else float("nan")
        trained = [m for m in metas_here if m.get("kind") not in ("baseline", "evaluated") and not is_baseline(configuration)]
        row["budget"] = ", ".join(sorted({describe_budget(m["protocol"]) for m in trained})) or "-"
        rows.append(row)
    table = pd.DataFrame(rows).sort_values(["final_success_mean", "experiment", "configuration"], ascending=[False, True, True],
                                           ignore_index=True)
    table.attrs["missing"] = list(missing)
    return table


def met_mean(distances: np.ndarray) -> float:
    """The mean ``min_human_distance`` over the episodes that met someone: an episode nobody was present in (``inf``, e.g. a
    recorded crowd's quiet window) has no distance to average; ``inf`` when no episode met anyone, NaN without episodes."""
    met = distances[np.isfinite(distances)]
    if len(met):
        return float(met.mean())
    return float("inf") if np.isinf(distances).any() else float("nan")


def _number(value: float, digits: int = 3) -> str:
    if value != value:  # NaN
        return "-"
    if np.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.{digits}f}"


def to_markdown(table: Any) -> str:
    """GitHub markdown with the main columns (all of them are in the CSV): one table per test set.

    Rows measured on different scenarios or held-out episodes are not comparable, so each test set
    gets its own table under a line naming it. The budget is one line under a table when its
    learned rows share it (``budget: 700 episodes per run``), a column when they differ.
    """
    groups = list(table.groupby(["scenario", "test_set"], sort=True)) if len(table) else []
    parts = []
    if len(groups) > 1:
        parts.append(f"{len(groups)} test sets: rows measured on different scenarios or test episodes are ranked in separate tables.\n")
    for (scenario, episodes), rows in groups:
        if len(groups) > 1:
            parts.append(f"### {scenario}: {episodes}\n")
        parts.append(_one_table(rows))
    missing = table.attrs.get("missing", [])
    if missing:
        lines = [f"{len(missing)} run(s) missing, not ranked (run `crowdnav benchmark` on the experiment again: it resumes "
                 "unfinished runs and rebuilds damaged ones from what they kept):", ""]
        lines += [f"- {gap.describe()}" for gap in missing]
        parts.append("\n".join(lines) + "\n")
    return "\n".join(parts)


def _rate(row: dict[str, Any], outcome: str) -> str:
    """``0.900 [0.699, 0.972]``: the mean rate and its 95% interval (Wilson for one run, bootstrap for several)."""
    return f"{_number(row[f'final_{outcome}_mean'])} [{_number(row[f'final_{outcome}_low'])}, {_number(row[f'final_{outcome}_high'])}]"


def _one_table(table: Any) -> str:
    several = table["experiment"].nunique() > 1
    budgets = sorted({budget for budget in table["budget"] if budget != "-"}) if "budget" in table else []
    column = len(budgets) > 1
    header = (["experiment"] if several else []) + [
        "configuration", "seeds", *(["budget"] if column else []), *(f"{o} [95% CI]" for o in OUTCOMES),
        "hit a human / an obstacle", "success IQM [95% CI]", "success AUC", "SPL", "STL", "PSC", "min human dist. (m)",
        "social force", "group intrusions", "env steps", "wall time (s)",
    ]
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] * len(header)) + "|"]
    for row in table.to_dict("records"):
        runs = row["seeds"] > 1  # a spread over runs and an IQM interval need two runs at least
        cells = ([row["experiment"]] if several else []) + [
            row["label"], _seeds(row), *([row["budget"]] if column else []),
            *(_rate(row, o) for o in OUTCOMES),
            f"{_number(row['final_collision_human_mean'])} / {_number(row['final_collision_static_mean'])}",
            f"{_number(row['success_iqm'])} [{_number(row['success_iqm_low'])}, {_number(row['success_iqm_high'])}]" if runs else "-",
            f"{_number(row['success_auc_mean'])} ± {_number(row['success_auc_std'])}" if runs else _number(row["success_auc_mean"]),
            _number(row["spl"]), _number(row["stl"]), _number(row["psc"]), _number(row["min_human_distance"]),
            _number(row["social_force"]), _number(row.get("group_intrusions", float("nan"))),  # "-" in tables made before the metric
            _number(row["env_steps"], 0), _number(row["wall_time_s"], 0),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    intervals = sorted(set(table["interval"]))
    lines += ["", "95% CI: " + "; ".join({"wilson": "Wilson score interval of the one run's final test episodes",
                                          "bootstrap": "two-stage bootstrap over runs, then their final test episodes",
                                          "none": "none (no episodes)"}[kind] for kind in intervals)]
    if len(budgets) == 1:
        lines += ["", f"budget: {budgets[0]} per run"]
    return "\n".join(lines) + "\n"


def _seeds(row: dict[str, Any]) -> str:
    expected = row.get("seeds_expected", row["seeds"])
    return str(row["seeds"]) if expected == row["seeds"] else f"{row['seeds']} of {expected}"


def to_csv(table: Any) -> str:
    return table.to_csv(index=False, lineterminator="\n", float_format="%.6f", na_rep="nan")


def evaluation_rates(tests: Any) -> Any:
    """Per run and evaluation: the outcome rates over its test episodes (the numbers behind the curves)."""
    keys = ["experiment", "configuration", "seed", "evaluation", "training_episodes"]
    if "training_steps" in tests.columns:  # a protocol in env steps; runs in episodes next to it have none (nan)
        keys.append("training_steps")
    rates = tests.groupby(keys, sort=True, dropna=False)["outcome"].value_counts(normalize=True).unstack(fill_value=0.0)
    return rates.reindex(columns=list(OUTCOMES), fill_value=0.0).reset_index()


def write_leaderboard(paths: Iterable[str | Path], out: str | Path) -> tuple[Any, list[Path]]:
    """Build the leaderboard of every finished run below ``paths``; write ``out``.md and ``out``.csv, and the
    per-evaluation rates of every run next to them (``evaluation_rates.csv``); with shared robot policies, each robot's
    final rates (``out``_robots.csv)."""
    from crowdnav.evaluation.robot_rollout import robot_rates
    from crowdnav.evaluation.storage import atomic_write_text, load_results

    missing: list[MissingRun] = []
    tests, _, metas = load_results(paths, missing)
    table = leaderboard_table(tests, metas, missing)
    out = Path(out)
    written = [atomic_write_text(out.with_name(out.name + ".md"), to_markdown(table)),
               atomic_write_text(out.with_name(out.name + ".csv"), to_csv(table)),
               atomic_write_text(out.with_name("evaluation_rates.csv"), to_csv(evaluation_rates(tests)))]
    robots = robot_rates(tests)
    if len(robots):  # shared robot policies and their baselines: the final rates of each robot (``<out>_robots.csv``)
        written.append(atomic_write_text(out.with_name(out.name + "_robots.csv"), robots.to_csv(index=False)))
    return table, written
