"""Learning curves as in the paper's Figure 4: success, collision, out-of-bounds and truncated rates along training.

For each run (configuration, seed), the test episodes are put in order (evaluation, then test
episode) and each outcome's rate is a sliding mean over the last ``window`` test episodes
(fewer at the start). Test episode ``j`` (of ``m``) of the evaluation after ``N_k`` training
episodes is placed at ``x = N_{k-1} + (j + 1) / m * (N_k - N_{k-1})`` (``N_{-1} = 0``), so the
curve advances one test episode at a time and reaches ``N_k`` with that evaluation's last
episode. The figure shows the mean over seeds and a band, clipped to [0, 1]: one standard
deviation (the paper's style, the default) or a 95% bootstrap interval of the mean. Scripted
baselines (:mod:`crowdnav.evaluation.baselines`) are grey horizontal lines at their rate on the same
test episodes. One panel per outcome of :data:`crowdnav.sim.simulator.OUTCOMES`; results written
before ``out_of_bounds`` existed draw a zero rate there. With a protocol in env steps the x axis
is ``training_steps`` (training env steps) instead of ``training_episodes``, the same way.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.evaluation.protocol import AXIS_LABELS, POINT_COLUMNS, protocol_unit

from crowdnav.files import replacing
from crowdnav.sim.simulator import OUTCOMES

RUN_KEYS = ["experiment", "configuration", "label", "seed"]


def results_unit(tests: Any) -> str:
    """The unit of a results table's evaluation points: ``steps`` if it has ``training_steps`` values, else ``episodes``
    (the only unit of results written before budgets in env steps existed)."""
    return "steps" if "training_steps" in tests.columns and tests["training_steps"].notna().any() else "episodes"


def rate_curves(tests: Any, window: int, unit: str = "episodes") -> Any:
    """Long table of the sliding rates: run columns, x (``training_episodes``, or ``training_steps`` for
    ``unit="steps"``), ``metric`` (outcome), ``rate``."""
    import pandas as pd

    column = POINT_COLUMNS[unit]
    frames = []
    for _, run in tests.groupby(RUN_KEYS, sort=True):
        run = run.sort_values(["evaluation", "test_episode"])
        points = run.groupby("evaluation", sort=True)[column].first()
        previous = pd.Series(np.concatenate([[0], points.to_numpy()[:-1]]), index=points.index)
        size = run.groupby("evaluation")["test_episode"].transform("size").to_numpy()
        position = run.groupby("evaluation").cumcount().to_numpy() + 1
        start = previous.loc[run["evaluation"]].to_numpy()
        end = run[column].to_numpy()
        x = start + position / size * (end - start)
        for outcome in OUTCOMES:
            hit = (run["outcome"] == outcome).astype(float)
            rate = hit.rolling(window, min_periods=1).mean().to_numpy()
            frame = run[RUN_KEYS].copy()
            frame[column], frame["metric"], frame["rate"] = x, outcome, rate
            frames.append(frame)
    return pd.concat(frames, ignore_index=True)


BANDS = ("std", "ci")
"""Band around the mean over seeds: ``std`` (one standard deviation, the paper's style) or ``ci``
(95% percentile bootstrap interval of the mean over seeds)."""
CI_RESAMPLES = 1000
# Line style and marker per configuration, so overlapping lines stay apart without colour; the
# baselines' dashed and dotted styles are kept for the baselines.
STYLES = [("-", "o"), ("-.", "s"), ("-", "^"), ("-.", "D"), ("-", "v"), ("-.", "P"), ("-", "X"), ("-.", "*")]


def seed_band(rates: Any, band: str = "std", seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean, low, high) over the columns (seeds) of ``rates`` (x by seed), the band clipped to [0, 1]."""
    values = np.asarray(rates, dtype=float)
    mean = values.mean(axis=1)
    if values.shape[1] < 2:
        low = high = mean
    elif band == "std":
        spread = values.std(axis=1, ddof=1)
        low, high = mean - spread, mean + spread
    elif band == "ci":
        pick = np.random.default_rng(seed).integers(0, values.shape[1], size=(CI_RESAMPLES, values.shape[1]))
        means = values[:, pick].mean(axis=2)  # (x, resamples)
        low, high = np.percentile(means, [2.5, 97.5], axis=1)
    else:
        raise ValueError(f"unknown band {band!r}; expected one of {', '.join(BANDS)}")
    # rates live in [0, 1]: a band beyond them would show impossible rates
    return mean, np.clip(low, 0.0, 1.0), np.clip(high, 0.0, 1.0)


def curves_figure(tests: Any, window: int, title: str | None = None, band: str = "std", unit: str | None = None) -> Any:
    """A matplotlib Figure: one panel per outcome, one line per configuration (mean over seeds and a band).

    ``band``: see :data:`BANDS`. Lines differ by colour, style and a marker at each evaluation;
    the legend sits below the panels, where it hides no curve. ``unit``: of the x axis,
    ``episodes`` or ``steps`` (None: :func:`results_unit` of ``tests``).
    """
    import seaborn as sns
    from crowdnav.evaluation.baselines import is_baseline
    from matplotlib.figure import Figure

    if band not in BANDS:
        raise ValueError(f"unknown band {band!r}; expected one of {', '.join(BANDS)}")
    unit = unit or results_unit(tests)
    column = POINT_COLUMNS[unit]
    if column not in tests.columns:  # policies evaluated without training (crowdnav evaluate) have no training_steps
        tests = tests.assign(**{column: 0})
    # reference lines: the scripted baselines, and policies evaluated without training (crowdnav evaluate)
    untrained = tests[column].fillna(0).groupby(tests["configuration"]).transform("max") == 0
    scripted = tests["configuration"].map(is_baseline) | untrained
    baselines, tests = tests[scripted], tests[~scripted]
    if not len(tests):  # nothing was trained: no training axis to draw lines along, one bar per policy instead
        return _bars_figure(baselines, title)
    curves = rate_curves(tests, window, unit)
    labels = list(dict.fromkeys(tests.sort_values(["configuration"])["label"]))
    evaluation_points = set(tests[column].unique())
    figure = Figure(figsize=(4.2 * len(OUTCOMES), 4.2), layout="constrained")
    axes = figure.subplots(1, len(OUTCOMES), sharex=True, sharey=True)
    palette = dict(zip(labels, sns.color_palette("colorblind", len(labels)), strict=True))
    for axis, outcome in zip(axes, OUTCOMES, strict=True):
        for k, label in enumerate(labels if curves is not None else []):
            rows = curves[(curves["metric"] == outcome) & (curves["label"] == label)]
            rates = rows.pivot_table(index=column, columns="seed", values="rate", aggfunc="mean")
            mean, low, high = seed_band(rates.to_numpy(), band)
            x = rates.index.to_numpy()
            linestyle, marker = STYLES[k % len(STYLES)]
            marks = [i for i, value in enumerate(x) if value in evaluation_points]
            axis.plot(x, mean, color=palette[label], linestyle=linestyle, marker=marker, markevery=marks, markersize=4, linewidth=1.4, label=label)
            axis.fill_between(x, low, high, color=palette[label], alpha=0.18, linewidth=0)
        # a scripted baseline plays the same test episodes at every evaluation: one rate, a horizontal line
        evaluated = [label for label, frame in baselines.groupby("label", sort=True) if not is_baseline(frame["configuration"].iloc[0])]
        for label, frame in baselines.groupby("label", sort=True):
            style = _baseline_style(frame, tests, palette, evaluated.index(label) if label in evaluated else 0)
            axis.axhline(float((frame["outcome"] == outcome).mean()), label=label, linewidth=1.2, **style)
        axis.set_title(f"{outcome.replace('_', ' ')} rate")
        axis.set_xlabel(AXIS_LABELS[unit])
        axis.set_ylabel(f"rate (sliding window of {window} test episodes)" if axis is axes[0] else "")
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
    handles, names = axes[0].get_legend_handles_labels()
    if handles:
        shown = "mean over seeds, band: " + ("one standard deviation" if band == "std" else "95% bootstrap CI of the mean")
        figure.legend(handles, names, loc="outside lower center", ncols=min(len(handles), 5), fontsize="small", frameon=False, title=shown,
                      title_fontsize="small")
    if title:
        figure.suptitle(title)
    return figure


EVALUATED_STYLES = [("-.", "C3"), ((0, (5, 1, 1, 1, 1, 1)), "C4"), ((0, (1, 1)), "C5"), ((0, (8, 2)), "C6"), ("-.", "C8"), ((0, (3, 1, 1, 1)), "C9")]
"""Line style and colour of the k-th policy evaluated without training: each its own."""
HATCHES = ["", "//", "..", "xx", "\\\\", "oo", "--", "++"]


BASELINE_LINESTYLES: dict[str, Any] = {
    "straight": "--", "social_force": ":", "orca": (0, (3, 1, 1, 1)), "onboard": "-.", "predictive": (0, (6, 2, 1, 2, 1, 2)),
    "oracle": (0, (10, 3)), "straight_shield": (0, (2, 2)), "social_force_shield": (0, (1, 3)),
}
"""Line style of each scripted baseline (:data:`crowdnav.evaluation.baselines.BASELINES`): grey lines told apart by their dashes."""


def _baseline_style(baseline: Any, tests: Any, palette: dict[str, Any], k: int = 0) -> dict[str, Any]:
    """The baseline's own dashes (:data:`BASELINE_LINESTYLES`); grey, or the colour of the configuration whose
    environment it shares when an experiment has several (``baseline_<name>_<configuration>``); the k-th
    policy evaluated without training gets the k-th of :data:`EVALUATED_STYLES`."""
    from crowdnav.evaluation.baselines import baseline_name, is_baseline

    configuration = str(baseline["configuration"].iloc[0])
    if not is_baseline(configuration):  # an evaluated policy: a style of its own
        linestyle, color = EVALUATED_STYLES[k % len(EVALUATED_STYLES)]
        return {"linestyle": linestyle, "color": color}
    linestyle = BASELINE_LINESTYLES.get(baseline_name(configuration), "--")
    for name, label in tests[["configuration", "label"]].drop_duplicates().itertuples(index=False):
        if configuration.endswith(f"_{name}") and label in palette:
            return {"linestyle": linestyle, "color": palette[label]}
    return {"linestyle": linestyle, "color": "0.35"}


def _bars_figure(results: Any, title: str | None) -> Any:
    """Policies without training (scripted baselines, crowdnav evaluate): per outcome, one bar per policy with
    its 95% interval (:func:`crowdnav.evaluation.intervals.rate_interval`), each policy its own colour and hatch."""
    import seaborn as sns
    from crowdnav.evaluation.intervals import rate_interval
    from matplotlib.figure import Figure

    groups = list(results.groupby("label", sort=True))
    colours = sns.color_palette("colorblind", len(groups))
    figure = Figure(figsize=(max(4.2, 0.9 * len(groups) + 1.5) * len(OUTCOMES) / 1.6, 4.6), layout="constrained")
    axes = figure.subplots(1, len(OUTCOMES), sharey=True)
    for axis, outcome in zip(axes, OUTCOMES, strict=True):
        for k, (label, frame) in enumerate(groups):
            runs = [(group["outcome"] == outcome).to_numpy(dtype=float) for _, group in frame.groupby("seed")]
            rate = float(np.mean([run.mean() for run in runs]))
            low, high, _ = rate_interval(runs)
            axis.bar(k, rate, color=colours[k], hatch=HATCHES[k % len(HATCHES)], edgecolor="0.2", label=label,
                     yerr=[[rate - low], [high - rate]], capsize=3)
        axis.set_xticks(range(len(groups)), [label for label, _ in groups], rotation=30, ha="right", fontsize="small")
        axis.set_title(f"{outcome.replace('_', ' ')} rate")
        axis.set_ylabel("rate over the test episodes" if axis is axes[0] else "")
        axis.set_ylim(0.0, 1.02)
        axis.grid(alpha=0.3, axis="y")
    figure.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncols=min(len(groups), 5), fontsize="small",
                  frameon=False, title="no training: one bar per policy, 95% interval (Wilson for one run)", title_fontsize="small")
    if title:
        figure.suptitle(title)
    return figure


def plot_curves(paths: Iterable[str | Path], out: str | Path | None = None, band: str = "std") -> list[Path]:
    """One figure (PNG and PDF) per experiment found below ``paths``; returns the files written.

    Written to ``out`` + ``.png``/``.pdf`` if given (one experiment only), else to
    ``<experiment folder>/curves.png`` and ``.pdf``.
    """
    from crowdnav.evaluation.storage import ResultsError, experiment_of, finished_runs, load_results

    paths = list(paths)
    tests, _, metas = load_results(paths)
    folders: dict[str, Path] = {}
    for run, meta in zip(finished_runs(paths), metas, strict=True):
        folders.setdefault(meta["experiment"], experiment_of(run))
    windows = {meta["experiment"]: meta["protocol"]["window"] for meta in metas}
    # every run of an experiment shares its protocol (the results folder refuses another); older ones: episodes
    units = {meta["experiment"]: protocol_unit(meta["protocol"]) for meta in metas if meta.get("kind") != "evaluated"}
    experiments = sorted(tests["experiment"].unique())
    if out is not None and len(experiments) > 1:
        raise ResultsError(f"--out names one figure, but the results hold {len(experiments)} experiments: {', '.join(experiments)}")
    written = []
    for experiment in experiments:
        figure = curves_figure(tests[tests["experiment"] == experiment], windows[experiment], title=experiment, band=band,
                               unit=units.get(experiment, "episodes"))
        stem = Path(out) if out is not None else folders.get(experiment, Path(paths[0])) / "curves"
        stem.parent.mkdir(parents=True, exist_ok=True)
        for suffix in (".png", ".pdf"):
            path = stem.with_name(stem.name + suffix)
            # no creation date: the same results give the same file; renamed over ``path``: a link there is replaced
            with replacing(path, suffix=suffix) as temporary:
                figure.savefig(temporary, dpi=150, metadata={"CreationDate": None} if suffix == ".pdf" else {"Software": None})
            written.append(path)
    return written
