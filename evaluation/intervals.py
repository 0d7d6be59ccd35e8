"""Confidence intervals for outcome rates: what a leaderboard's ``[low, high]`` means.

A rate measured on the held-out test episodes carries two sources of uncertainty: which
episodes were drawn (finite test set) and which training seeds were run. The interval follows
what was measured:

* **one run** (one seed): the Wilson score interval of ``k`` successes in ``n`` episodes
  (Wilson 1927; Brown, Cai and DasGupta 2001 recommend it over the normal approximation, which
  gives ``[0.9, 0.9]`` for 18 of 20 and nonsense near 0 and 1);
* **several runs**: a two-stage (hierarchical) bootstrap: resample the runs with replacement,
  then each drawn run's episodes with replacement, and take the mean over runs of the runs'
  rates; the 2.5 and 97.5 percentiles of that statistic over :data:`RESAMPLES` draws from
  ``numpy.random.default_rng(SEED)``. Resampling both stages keeps the seed-to-seed spread and
  the episode noise in the interval (a bootstrap over runs alone calls 2 runs that both
  scored 0.9 on 20 episodes "exactly 0.9").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

Z95 = 1.959963984540054
"""The standard normal's 97.5% quantile."""
RESAMPLES = 2000
SEED = 0


def wilson(successes: int, trials: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a proportion; ``(nan, nan)`` without trials."""
    if trials <= 0:
        return float("nan"), float("nan")
    p = successes / trials
    denominator = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z * np.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denominator
    # at k = 0 or k = n one end is exactly 0 or 1 (rounding would leave 1 - 1e-16)
    low = 0.0 if successes == 0 else max(0.0, float(centre - half))
    high = 1.0 if successes == trials else min(1.0, float(centre + half))
    return low, high


def hierarchical_bootstrap(runs: Sequence[np.ndarray], resamples: int = RESAMPLES, seed: int = SEED) -> tuple[float, float]:
    """95% percentile interval of the mean over runs of each run's rate, runs and episodes resampled.

    ``runs``: one 0/1 (or boolean) array per run, its test episodes' outcomes.
    """
    rng = np.random.default_rng(seed)
    arrays = [np.asarray(run, dtype=float) for run in runs]
    picks = rng.integers(0, len(arrays), (resamples, len(arrays)))
    means = np.empty(resamples)
    for b in range(resamples):  # per draw: a handful of runs, each a vectorized episode resample
        rates = [arrays[i][rng.integers(0, len(arrays[i]), len(arrays[i]))].mean() for i in picks[b]]
        means[b] = np.mean(rates)
    low, high = np.percentile(means, [2.5, 97.5])
    return float(low), float(high)


def rate_interval(runs: Sequence[np.ndarray]) -> tuple[float, float, str]:
    """``(low, high, method)`` for the mean rate of ``runs`` (per-run 0/1 outcome arrays).

    One run: Wilson; several: the two-stage bootstrap; ``method`` names which (``wilson`` or
    ``bootstrap``) so a table can say it.
    """
    runs = [np.asarray(run, dtype=float) for run in runs if len(run)]
    if not runs:
        return float("nan"), float("nan"), "none"
    if len(runs) == 1:
        low, high = wilson(int(runs[0].sum()), len(runs[0]))
        return low, high, "wilson"
    low, high = hierarchical_bootstrap(runs)
    return low, high, "bootstrap"
