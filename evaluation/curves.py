"""Learning curves as in the paper's Figure 4: success, collision, out-of-bounds and truncated rates along training.

For each run (configuration, seed), the test episodes are put in order (evaluation, then test
episode) and each outcome's rate is a sliding mean over the last ``window`` test episodes
(fewer at the start). Test episode ``j`` (of ``m``) of the evaluation after ``N_k`` training
episodes is placed at ``x = N_{k-1} + (j + 1) / m * (N_k - N_{k-1})`` (``N_{-1} = 0``), so the
curve advances one test episode at a time and reaches ``N_k`` with that evaluation's last
episode. The figure shows the mean over seeds and a band of one standard deviation. Scripted
baselines (:mod:`evaluation.baselines`) are grey horizontal lines at their rate on the same
test episodes. One panel per outcome of :data:`crowdnav.simulator.OUTCOMES`; results written
before ``out_of_bounds`` existed draw a zero rate there.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.simulator import OUTCOMES

RUN_KEYS = ["experiment", "configuration", "label", "seed"]


def rate_curves(tests: Any, window: int) -> Any:
    """Long table of the sliding rates: run columns, ``training_episodes`` (x), ``metric`` (outcome), ``rate``."""
    import pandas as pd

    frames = []
    for _, run in tests.groupby(RUN_KEYS, sort=True):
        run = run.sort_values(["evaluation", "test_episode"])
        points = run.groupby("evaluation", sort=True)["training_episodes"].first()
        previous = pd.Series(np.concatenate([[0], points.to_numpy()[:-1]]), index=points.index)
        size = run.groupby("evaluation")["test_episode"].transform("size").to_numpy()
        position = run.groupby("evaluation").cumcount().to_numpy() + 1
        start = previous.loc[run["evaluation"]].to_numpy()
        end = run["training_episodes"].to_numpy()
        x = start + position / size * (end - start)
        for outcome in OUTCOMES:
            hit = (run["outcome"] == outcome).astype(float)
            rate = hit.rolling(window, min_periods=1).mean().to_numpy()
            frame = run[RUN_KEYS].copy()
            frame["training_episodes"], frame["metric"], frame["rate"] = x, outcome, rate
            frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def curves_figure(tests: Any, window: int, title: str | None = None) -> Any:
    """A matplotlib Figure: one panel per outcome, one line per configuration (mean over seeds, +-1 std band)."""
    import seaborn as sns
    from crowdnav.evaluation.baselines import is_baseline
    from matplotlib.figure import Figure

    scripted = tests["configuration"].map(is_baseline)
    baselines, tests = tests[scripted], tests[~scripted]
    curves = rate_curves(tests, window) if len(tests) else None
    labels = list(dict.fromkeys(tests.sort_values(["configuration"])["label"]))
    figure = Figure(figsize=(4.2 * len(OUTCOMES), 3.6), layout="constrained")
    axes = figure.subplots(1, len(OUTCOMES), sharex=True, sharey=True)
    palette = dict(zip(labels, sns.color_palette("colorblind", len(labels)), strict=True))
    for axis, outcome in zip(axes, OUTCOMES, strict=True):
        if curves is not None:
            sns.lineplot(data=curves[curves["metric"] == outcome], x="training_episodes", y="rate", hue="label", hue_order=labels,
                         palette=palette, estimator="mean", errorbar="sd", ax=axis, legend=axis is axes[-1])
        # a scripted baseline plays the same test episodes at every evaluation: one rate, a horizontal line
        for label, frame in baselines.groupby("label", sort=True):
            axis.axhline(float((frame["outcome"] == outcome).mean()), label=label, linewidth=1.2, **_baseline_style(frame, tests, palette))
        axis.set_title(f"{outcome.replace('_', ' ')} rate")
        axis.set_xlabel("training episodes")
        axis.set_ylabel(f"rate (sliding window of {window} test episodes)" if axis is axes[0] else "")
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
    if len(labels) or len(baselines):
        axes[-1].legend(title=None, loc="best", fontsize="small")
    if title:
        figure.suptitle(title)
    return figure


def _baseline_style(baseline: Any, tests: Any, palette: dict) -> dict[str, Any]:
    """Dashed for straight-to-goal, dotted for social force; grey, or the colour of the configuration whose
    environment it shares when an experiment has several (``baseline_<name>_<configuration>``)."""
    configuration = str(baseline["configuration"].iloc[0])
    linestyle = ":" if "social_force" in configuration else "--"
    for name, label in tests[["configuration", "label"]].drop_duplicates().itertuples(index=False):
        if configuration.endswith(f"_{name}") and label in palette:
            return {"linestyle": linestyle, "color": palette[label]}
    return {"linestyle": linestyle, "color": "0.35"}


def plot_curves(paths: Iterable[str | Path], out: str | Path | None = None) -> list[Path]:
    """One figure (PNG and PDF) per experiment found below ``paths``; returns the files written.

    Written to ``out`` + ``.png``/``.pdf`` if given (one experiment only), else to
    ``<experiment folder>/curves.png`` and ``.pdf``.
    """
    from crowdnav.evaluation.storage import ResultsError, finished_runs, load_results

    paths = list(paths)
    tests, _, metas = load_results(paths)
    folders = {}
    for run, meta in zip(finished_runs(paths), metas, strict=True):  # runs live in <experiment>/<configuration>/<seed>
        folders.setdefault(meta["experiment"], run.parent.parent)
    windows = {meta["experiment"]: meta["protocol"]["window"] for meta in metas}
    experiments = sorted(tests["experiment"].unique())
    if out is not None and len(experiments) > 1:
        raise ResultsError(f"--out names one figure, but the results hold {len(experiments)} experiments: {', '.join(experiments)}")
    written = []
    for experiment in experiments:
        figure = curves_figure(tests[tests["experiment"] == experiment], windows[experiment], title=experiment)
        stem = Path(out) if out is not None else folders.get(experiment, Path(paths[0])) / "curves"
        stem.parent.mkdir(parents=True, exist_ok=True)
        for suffix in (".png", ".pdf"):
            path = stem.with_name(stem.name + suffix)
            # no creation date: the same results give the same file
            figure.savefig(path, dpi=150, metadata={"CreationDate": None} if suffix == ".pdf" else {"Software": None})
            written.append(path)
    return written
