"""Recorded crowds from the command line: ``crowdnav scenario from-recording`` on recordings the tests write (each format),
then validate, render, evaluate and export trajectories of the scenario it writes (no data ships)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from crowdnav.cli import main
from crowdnav.crowd.recording import read_recording
from crowdnav.crowd.replay import PARKING
from crowdnav.sim.simulator import Simulator

WALKERS = {  # id: (first s, last s, start, end): a flow along x both ways, one person crossing it late
    1: (0.0, 12.0, -6 - 1j, 6 - 1j),
    2: (2.0, 14.0, 6 + 1j, -6 + 1j),
    3: (4.0, 16.0, -6 + 0j, 6 + 0.5j),
    4: (9.0, 20.0, 6 - 2j, -6 - 1.5j),
    5: (14.0, 22.0, 0.5 - 3j, 0.5 + 3j),
}


def write_recording(path, fmt: str, walkers=WALKERS) -> None:
    """``walkers`` at 2.5 Hz (frames every 10) in ``fmt``: obsmat (frame id x z y vx vz vy), frames (frame id x y) or trajnet."""
    rows = []
    for person, (t0, t1, a, b) in walkers.items():
        for k in range(round(t0 / 0.4), round(t1 / 0.4) + 1):
            where = a + (b - a) * (k * 0.4 - t0) / (t1 - t0)
            rows.append((k * 10, person, round(where.real, 4), round(where.imag, 4)))
    rows.sort()
    if fmt == "obsmat":
        text = "".join(f"{f:.7e} {p:.7e} {x:.7e} 0.0000000e+00 {y:.7e} 0 0 0\n" for f, p, x, y in rows)
    elif fmt == "frames":
        text = "".join(f"{f}\t{p}\t{x}\t{y}\n" for f, p, x, y in rows)
    else:
        scene = json.dumps({"scene": {"id": 0, "p": 1, "s": rows[0][0], "e": rows[-1][0], "fps": 2.5}})
        text = scene + "\n" + "".join(json.dumps({"track": {"f": f // 10, "p": p, "x": x, "y": y}}) + "\n" for f, p, x, y in rows)
    path.write_text(text)


@pytest.mark.parametrize("fmt,name", [("obsmat", "obsmat.txt"), ("frames", "zara.txt"), ("trajnet", "scene.ndjson")])
def test_from_recording_writes_a_scenario_that_validates_and_replays_the_file(tmp_path, capsys, fmt, name):
    recording = tmp_path / name
    write_recording(recording, fmt)
    out = tmp_path / "recorded.yaml"
    assert main(["scenario", "from-recording", str(recording), "--out", str(out)]) == 0
    assert main(["scenario", "validate", str(out)]) == 0
    scenario = yaml.safe_load(out.read_text())
    humans, world = scenario["humans"], scenario["world"]
    assert humans["model"] == "replay" and humans["replay"] == {"file": name, "format": fmt, "annotation_step": 0.4}
    assert humans["count"] == 4  # at most 3 at once (people 2, 3, 4 at 9-14 s), one more as places stay empty a step
    points = read_recording(recording).positions
    assert world["min"] == [round(points.real.min() - 1, 3), round(points.imag.min() - 1, 3)]
    assert world["max"] == [round(points.real.max() + 1, 3), round(points.imag.max() + 1, 3)]
    # people walk along x: the robot crosses from low y to high y, and people enter on the left and right sides
    assert scenario["robot"]["start"]["max"][1] < -2 and scenario["robot"]["goal"]["min"][1] > 2
    assert any(area["max"][0] < -5 for area in humans["spawn"]) and any(area["min"][0] > 5 for area in humans["spawn"])
    sim = Simulator(str(out))
    sim.reset(seed=0)
    shown = np.abs(sim.human_positions - PARKING) > 1e6
    assert shown.any() and (np.abs(sim.human_positions[shown].real) <= 6.0 + 1e-9).all()


def test_a_flow_along_y_gives_a_robot_route_along_x_and_react_within_is_written(tmp_path, capsys):
    recording = tmp_path / "walk.txt"
    write_recording(recording, "frames", {k: (t0, t1, a * 1j, b * 1j) for k, (t0, t1, a, b) in WALKERS.items()})
    assert main(["scenario", "from-recording", str(recording), "--react-within", "1.5"]) == 0
    scenario = yaml.safe_load(capsys.readouterr().out)
    assert scenario["robot"]["start"]["max"][0] < -2 and scenario["robot"]["goal"]["min"][0] > 2
    assert scenario["humans"]["replay"]["react_within"] == 1.5
    assert scenario["humans"]["replay"]["file"] == str(recording.resolve())  # printed: named by its absolute path


def test_from_recording_refuses_bad_input_in_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.txt"
    bad.write_text("0 1 2.0 3.0\n10 1 x 3.0\n")
    out = tmp_path / "s.yaml"
    assert main(["scenario", "from-recording", str(bad), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.txt:2: a column is not a number" in err
    out.write_text("kept\n")
    good = tmp_path / "good.txt"
    write_recording(good, "frames")
    assert main(["scenario", "from-recording", str(good), "--out", str(out)]) == 1
    assert "exists" in capsys.readouterr().err and out.read_text() == "kept\n"
    assert main(["scenario", "from-recording", str(good), "--time-step", "0"]) == 1
    assert capsys.readouterr().err.count("\n") == 1


def test_the_recorded_scenario_renders_evaluates_and_exports_only_present_people(tmp_path, capsys):
    recording = tmp_path / "walk.txt"
    write_recording(recording, "frames")
    scenario = tmp_path / "recorded.yaml"
    assert main(["scenario", "from-recording", str(recording), "--out", str(scenario), "--max-steps", "40"]) == 0
    assert main(["render", str(scenario), "--episodes", "1", "--format", "gif", "--out", str(tmp_path / "video"), "--no-progress"]) == 0
    assert len(list((tmp_path / "video").glob("*.gif"))) == 1
    assert main(["evaluate", "baseline:straight", "--scenario", str(scenario), "--episodes", "3", "--out", str(tmp_path / "eval")]) == 0
    capsys.readouterr()
    assert main(["trajectories", "baseline:straight", "--scenario", str(scenario), "--episodes", "3", "--out", str(tmp_path / "traj")]) == 0
    csv = next((tmp_path / "traj").rglob("*.csv"))
    ndjson = next((tmp_path / "traj").rglob("*.ndjson"))
    import pandas as pd

    table = pd.read_csv(csv)
    assert (table[["x", "y"]].abs() < 50).all().all()  # no empty (parked) place is exported
    exported = read_recording(ndjson)
    dt = 0.2
    for person in np.unique(exported.people):  # every track is one person: consecutive frames, no jump
        mine = exported.people == person
        times, where = exported.times[mine], exported.positions[mine]
        assert np.allclose(np.diff(times), dt)
        fastest = 1.0 if person % 1000 == 0 else 2.0  # the robot's track (k = 0), people's (at most ~1.5 m/s here)
        assert (np.abs(np.diff(where)) <= fastest * dt + 1e-3).all()
    humans = table[table["agent"] != "robot"]
    assert humans["track"].nunique() >= 4  # people of the windows, each its own track


def test_the_recording_commands_offer_exactly_the_formats_the_reader_takes():
    from typing import get_args

    from crowdnav.cli.common import RECORDING_FORMATS
    from crowdnav.crowd.recording import RecordingFormat

    assert RECORDING_FORMATS == get_args(RecordingFormat)
