"""The statistics and verdict rules of benchmarks/figure4_claims.py (the claims page of docs/results)."""

from __future__ import annotations

import numpy as np

from benchmarks import figure4_claims as claims


def runs(success: list[list[float]], truncated: list[list[float]] | None = None) -> object:
    success = np.array(success, dtype=float)
    truncated = np.zeros_like(success) if truncated is None else np.array(truncated, dtype=float)
    rates = {"success": success, "truncated": truncated, "collision": 1 - success - truncated, "out_of_bounds": 0 * success}
    return claims.Runs(np.arange(1, success.shape[1] + 1) * 50, rates)


def test_probability_of_improvement_is_one_half_for_equal_runs_and_one_for_disjoint_runs():
    same = np.array([0.2, 0.4, 0.6])
    assert claims.improvement(same, same)[0] == 0.5
    value, low, high = claims.improvement(np.array([0.9, 0.8, 0.95]), np.array([0.1, 0.2, 0.3]))
    assert value == low == high == 1.0
    assert claims.beats(np.array([0.9, 0.8]), np.array([0.1, 0.2])) and not claims.beats(same, same)


def test_modalities_claims_are_judged_by_their_stated_rules():
    early_fast = [[0.5] * 6 + [0.9] * 8, [0.6] * 6 + [0.9] * 8]
    slow = [[0.0] * 6 + [0.88] * 8, [0.1] * 6 + [0.89] * 8]
    verdicts = dict(claims.modalities({"leog": runs(slow), "lidar": runs(early_fast), "closest_obstacle": runs(early_fast)}))
    assert verdicts["(b) all inputs converge to similar performance"][0] == "reproduced"
    assert verdicts["(b) LIDAR and closest obstacle are better early (than LEOG)"][0] == "reproduced"
    assert verdicts["(b) LEOG ends with the smallest std"][0] == "not reproduced"  # 0.007 vs 0.0


def test_a_truncation_spike_counts_runs_and_evaluations_at_or_above_a_quarter_after_the_first():
    spiky = runs([[0.5, 0.5, 0.5]], truncated=[[0.9, 0.25, 0.1]])
    assert spiky.spikes() == 1


def test_seeds_evaluated_a_few_episodes_late_are_aligned_by_evaluation_index(tmp_path):
    """Older on-policy runs were evaluated at 601 instead of 600 episodes: the seed still counts."""
    path = tmp_path / "evaluation_rates.csv"
    lines = ["experiment,configuration,seed,evaluation,training_episodes,success,collision,out_of_bounds,truncated"]
    for seed in range(3):
        for k in range(3):
            episodes = (k + 1) * 50 + (1 if seed == 2 and k == 1 else 0)
            lines.append(f"paradigms,a2c,{seed},{k},{episodes},0.5,0.5,0,0")
    path.write_text("\n".join(lines) + "\n")
    runs = claims.load(path)["a2c"]
    assert runs.rates["success"].shape == (3, 3) and list(runs.episodes) == [50, 100, 150]


def test_an_env_step_budget_scales_every_span_to_the_same_fraction_as_700_episodes(tmp_path):
    """Early = episodes 50-300 of 700 becomes 1/14-3/7 of a 2 M-step budget: the evaluations at 0.2-0.8 M."""
    path = tmp_path / "evaluation_rates.csv"
    lines = ["experiment,configuration,seed,evaluation,training_episodes,training_steps,success,collision,out_of_bounds,truncated"]
    for seed in range(2):
        for k in range(10):
            lines.append(f"modalities_steps,lidar,{seed},{k},0,{(k + 1) * 200_000},{k / 10},{1 - k / 10},0,0")
    path.write_text("\n".join(lines) + "\n")
    lidar = claims.load(path)["lidar"]
    assert lidar.budget == 2_000_000 and lidar.scaled(*claims.EARLY) == (2_000_000 / 14, 2_000_000 * 3 / 7)
    assert np.allclose(lidar.span(*claims.EARLY), np.mean([0.0, 0.1, 0.2, 0.3]))
    assert np.allclose(lidar.final(), np.mean([0.7, 0.8, 0.9]))
