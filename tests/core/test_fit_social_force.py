"""benchmarks/fit_social_force.py on synthetic obsmat recordings the tests write (no data ships): the fit finds the
preferred speed the synthetic walkers were simulated with, and the table has every statistic."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.fit_social_force import DEFAULT, Params, constant_velocity, cut_windows, errors, fit, main, rollout, write_synthetic_obsmat


@pytest.fixture(scope="module")
def walkers(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fit")
    paths = {}
    for speed in (0.7, 1.3):
        paths[speed] = folder / f"walkers_{speed}.txt"
        write_synthetic_obsmat(paths[speed], walkers=24, seed=1, preferred_speed=speed)
    return paths


@pytest.mark.parametrize("speed", [0.7, 1.3])
def test_the_fit_finds_the_preferred_speed_the_walkers_were_simulated_with(walkers, speed):
    windows = cut_windows(walkers[speed], horizon=4.8)
    best, best_ade = fit(windows)
    assert abs(best.preferred_speed - speed) <= 0.2 + 1e-9
    assert best_ade < errors(windows, rollout(windows, DEFAULT))[0]
    assert best_ade < errors(windows, constant_velocity(windows))[0]


def test_a_rollout_starts_from_the_recorded_state_and_leaves_the_others_as_recorded(walkers):
    windows = cut_windows(walkers[1.3], horizon=2.4)
    out = rollout(windows, Params(1.3, 0.5, 2.0))
    assert np.array_equal(out[:, :2], windows.positions[:, :2], equal_nan=True)
    others = ~windows.simulated
    assert np.array_equal(out[np.broadcast_to(others[:, None], out.shape)],
                          windows.positions[np.broadcast_to(others[:, None], out.shape)], equal_nan=True)
    assert np.isfinite(out[np.broadcast_to(windows.simulated[:, None], out.shape)]).all()


def test_the_command_writes_the_table_and_refuses_a_too_short_recording_in_one_line(walkers, tmp_path, capsys):
    out = tmp_path / "table.md"
    assert main([str(walkers[1.3]), "--out", str(out)]) == 0
    table = out.read_text()
    for row in ("speed median", "speed IQR", "closest distance median", "straightness median", "ADE (m)", "FDE (m)"):
        assert f"| {row}" in table
    assert "Fit (least ADE on the grid): preferred_speed" in table
    short = tmp_path / "short.txt"
    short.write_text("0 1 0.0 0.0\n10 1 0.4 0.0\n")
    assert main([str(short)]) == 1
    assert capsys.readouterr().err.count("\n") == 1
