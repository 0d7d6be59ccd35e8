"""crowdnav.crowd.fit (``crowdnav scenario fit``) on synthetic obsmat recordings the tests write (no data ships): the fit
recovers the parameters the recording's walkers were simulated with, reports on held-out windows, and warns at a bound.

Recovery tolerances (docs/simulator.md#fitting-the-social-force-to-people): relaxation time, human strength and human
range within 25% of the truth, anisotropy lambda within 0.2, the slowest preferred speed within 0.1 m/s and the fastest
within 0.25 m/s (ranking people by recorded speed is noisy, which narrows the fitted spread)."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav.cli import main
from crowdnav.crowd.fit import SPACE, Fit, fit, write_synthetic_obsmat
from crowdnav.crowd.fit_model import DEFAULT, Params, constant_velocity, cut_windows, errors, rollout, split

TRUTH = Params(speed_low=0.9, speed_width=0.6, relaxation_time=0.8, human_strength=1.5, human_range=0.5, anisotropy=0.4)


def assert_recovered(found: Params, truth: Params) -> None:
    for name in ("relaxation_time", "human_strength", "human_range"):
        assert abs(getattr(found, name) / getattr(truth, name) - 1) <= 0.25, (name, getattr(found, name))
    assert abs(found.anisotropy - truth.anisotropy) <= 0.2
    assert abs(found.speed_low - truth.speed_low) <= 0.1
    assert abs(found.speed_low + found.speed_width - truth.speed_low - truth.speed_width) <= 0.25


def recorded(tmp_path, truth: Params, seed: int, walkers: int = 48):
    path = tmp_path / f"walkers_{seed}.txt"
    write_synthetic_obsmat(path, walkers=walkers, seed=seed, params=truth, speeds=(truth.speed_low, truth.speed_low + truth.speed_width))
    return cut_windows(path, horizon=4.8)


def test_the_fit_recovers_the_parameters_an_anisotropic_crowd_was_simulated_with(tmp_path):
    train, test = split(recorded(tmp_path, TRUTH, seed=1), 0.3)
    result = fit(train)
    assert_recovered(result.params, TRUTH)
    held_out = errors(test, rollout(test, result.params))[0]
    assert held_out < errors(test, rollout(test, DEFAULT))[0] and held_out < errors(test, constant_velocity(test))[0]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3])
@pytest.mark.parametrize("truth", [TRUTH, Params(speed_low=1.0, speed_width=0.4, relaxation_time=0.4, human_strength=3.0,
                                                  human_range=0.3, anisotropy=0.9)])
def test_the_fit_recovers_the_parameters_on_other_seeds_and_crowds(tmp_path, truth, seed):
    train, _ = split(recorded(tmp_path, truth, seed), 0.3)
    assert_recovered(fit(train, max_evaluations=600).params, truth)


def test_training_and_held_out_windows_share_no_recorded_step(tmp_path):
    windows = recorded(tmp_path, TRUTH, seed=1, walkers=16)
    train, test = split(windows, 0.3)
    length = windows.positions.shape[1]
    assert len(train.start) and len(test.start) and (train.start + length).max() <= test.start.min()
    with pytest.raises(ValueError, match="between 0 and 1"):
        split(windows, 1.0)


def test_a_value_on_a_bound_gets_a_warning_line_and_an_inner_one_does_not():
    names = tuple(SPACE)
    on_edge = Fit(Params(speed_low=0.9, speed_width=0.0, relaxation_time=4.99, human_strength=1.0, human_range=0.3, anisotropy=0.5),
                  0.1, 10, names)
    lines = on_edge.warnings()
    assert [line.split()[1] for line in lines] == ["speed_width", "relaxation_time"]
    assert "lower bound 0" in lines[0] and "upper bound 5" in lines[1]
    assert Fit(TRUTH, 0.1, 10, names).warnings() == []


def test_a_rollout_starts_from_the_recorded_state_and_leaves_the_others_as_recorded(tmp_path):
    windows = recorded(tmp_path, TRUTH, seed=1, walkers=16)
    out = rollout(windows, TRUTH)
    assert np.array_equal(out[:, :2], windows.positions[:, :2], equal_nan=True)
    others = np.broadcast_to(~windows.simulated[:, None], out.shape)
    assert np.array_equal(out[others], windows.positions[others], equal_nan=True)
    assert np.isfinite(out[np.broadcast_to(windows.simulated[:, None], out.shape)]).all()


def test_the_command_prints_the_held_out_table_from_any_folder_and_refuses_bad_input_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the recipe runs from any folder, not only the clone's root
    assert main(["scenario", "fit", "--synthetic", "walkers.txt", "--isotropic", "--max-rollouts", "60", "--out", "table.md"]) == 0
    table = (tmp_path / "table.md").read_text()
    for row in ("speed median", "speed IQR", "closest distance median", "straightness median", "ADE (m)", "FDE (m)"):
        assert f"| {row}" in table
    assert "held-out windows" in table and "fixed: anisotropy 1" in table and "humans.preferred_speed [" in table
    capsys.readouterr()
    short = tmp_path / "short.txt"
    short.write_text("0 1 0.0 0.0\n10 1 0.4 0.0\n")
    assert main(["scenario", "fit", str(short)]) == 1
    assert main(["scenario", "fit", "walkers.txt", "--held-out", "1.5"]) == 1
    assert capsys.readouterr().err.count("\n") == 2
