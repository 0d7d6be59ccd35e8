"""Rate intervals (evaluation/intervals.py): Wilson for one run, a two-stage bootstrap for several."""

from __future__ import annotations

import numpy as np
import pytest
from crowdnav.evaluation.intervals import hierarchical_bootstrap, rate_interval, wilson


def test_wilson_matches_the_textbook_values_and_is_never_a_point_for_18_of_20():
    low, high = wilson(18, 20)
    assert (low, high) == (pytest.approx(0.6990, abs=1e-4), pytest.approx(0.9721, abs=1e-4))
    assert wilson(0, 10)[0] == 0.0 and wilson(0, 10)[1] == pytest.approx(0.2775, abs=1e-4)
    assert wilson(10, 10)[1] == 1.0 and wilson(10, 10)[0] == pytest.approx(0.7225, abs=1e-4)
    assert all(np.isnan(wilson(0, 0)))


def test_one_run_uses_wilson_and_several_runs_the_bootstrap_that_keeps_episode_noise():
    one = rate_interval([np.r_[np.ones(18), np.zeros(2)]])
    assert one[2] == "wilson" and one[:2] == wilson(18, 20)
    low, high, method = rate_interval([np.r_[np.ones(18), np.zeros(2)]] * 2)
    assert method == "bootstrap" and low < 0.85 and high > 0.95  # two identical runs: still 20-episode noise
    assert rate_interval([])[2] == "none"


def test_the_bootstrap_is_seeded_and_widens_with_the_spread_between_runs():
    calm = [np.r_[np.ones(50), np.zeros(50)]] * 4
    spread = [np.ones(100), np.zeros(100), np.ones(100), np.zeros(100)]
    assert hierarchical_bootstrap(calm) == hierarchical_bootstrap(calm)
    calm_width = np.subtract(*hierarchical_bootstrap(calm)[::-1])
    spread_width = np.subtract(*hierarchical_bootstrap(spread)[::-1])
    assert spread_width > 2 * calm_width
