"""`crowdnav track`, `crowdnav evaluate --track` and `crowdnav leaderboard --track` from the command line."""

from __future__ import annotations

import shutil
import subprocess

import pytest
from crowdnav.evaluation.track import load_track, shipped_tracks

from crowdnav.cli import main


def test_track_list_and_show_say_what_a_track_fixes(capsys):
    assert main(["track", "list"]) == 0
    listed = capsys.readouterr().out.splitlines()
    assert len(listed) == len(shipped_tracks()) and any(line.startswith("figure4 v") for line in listed)
    assert main(["track", "show", "figure4"]) == 0
    shown = capsys.readouterr().out
    assert "room_furniture (overrides: humans.count=5, humans.preferred_speed=[0.5, 1.2])" in shown
    assert "100 episodes, seeds 0-99" in shown and "time limit:   150 steps" in shown and "any (declared" in shown
    assert main(["track", "show", "figure5"]) == 1
    assert capsys.readouterr().err.count("\n") == 1


def test_evaluate_refuses_what_a_track_fixes_and_the_keys_it_does_not_allow(capsys, tmp_path):
    assert main(["evaluate", "baseline:straight", "--track", "figure4", "--episodes", "5", "--out", str(tmp_path)]) == 1
    assert capsys.readouterr().err == "crowdnav: error: --episodes: a track fixes its test episodes and scenario; leave it out\n"
    argv = ["evaluate", "crowdnav.planning.scripted:StraightToGoal", "--track", "robots_crossing_hall", "--modalities", "goal,humans",
            "--out", str(tmp_path)]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.endswith("humans is not allowed\n") and err.count("\n") == 1


def test_evaluate_then_leaderboard_on_a_track_with_a_page(capsys, tmp_path, monkeypatch):
    """The whole route on a shortened copy of figure4 (a track file), against reference results written by `track reference`."""
    source = load_track("figure4").source
    short = tmp_path / "short.yaml"
    short.write_text(open(source, encoding="utf-8").read().replace("test_episodes: 100", "test_episodes: 4"), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert main(["track", "reference", str(short), "--out", "ref", "--allow-dirty"]) == 0
    assert main(["evaluate", "baseline:straight", "--track", str(short), "--name", "mine", "--out", "res", "--no-progress"]) == 0
    assert "rank with: crowdnav leaderboard --track figure4 res" in capsys.readouterr().out
    assert main(["leaderboard", "--track", str(short), "--reference", "ref/figure4", "res", "--html", "page.html"]) == 0
    out = capsys.readouterr().out
    assert "## Track figure4 v" in out and "| 1 |" in out and "mine *" in out and "wrote page.html" in out
    assert (tmp_path / "res" / "leaderboard_figure4.csv").is_file()


def test_track_reference_plays_only_the_baselines_named_and_keeps_the_others(capsys, tmp_path, monkeypatch):
    source = load_track("figure4").source
    short = tmp_path / "short.yaml"
    short.write_text(open(source, encoding="utf-8").read().replace("test_episodes: 100", "test_episodes: 2"), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert main(["track", "reference", str(short), "--out", "ref", "--allow-dirty", "--baseline", "straight"]) == 0
    assert main(["track", "reference", str(short), "--out", "ref", "--allow-dirty", "--baseline", "onboard"]) == 0
    out = capsys.readouterr().out
    assert "baseline_straight kept" in out and "baseline_onboard success" in out and "baseline_oracle" not in out
    assert sorted(path.name for path in (tmp_path / "ref" / "figure4").glob("*.csv")) == ["baseline_onboard.csv", "baseline_straight.csv"]
    assert main(["track", "reference", str(short), "--out", "ref", "--baseline", "onboard", "--agents", "x"]) == 1
    assert capsys.readouterr().err.count("\n") == 1


def test_the_leaderboard_needs_a_track_for_its_track_options(capsys):
    assert main(["leaderboard", "--html", "x.html", "somewhere"]) == 1
    assert "add --track NAME" in capsys.readouterr().err


def test_track_check_passes_on_the_shipped_figure4_track(capsys):
    assert main(["track", "check", "figure4"]) == 0
    assert "unchanged" in capsys.readouterr().out


CHROMIUM = next((shutil.which(name) for name in ("chromium", "chromium-browser", "google-chrome") if shutil.which(name)), None)


@pytest.mark.skipif(CHROMIUM is None, reason="no headless browser (apt-get install -y chromium)")
def test_the_leaderboard_page_opens_in_a_real_browser_without_console_errors(tmp_path, capsys):
    """The page is self-contained: a headless Chromium without network loads it, logs no console error, and shows every entry."""
    from crowdnav.evaluation.track_leaderboard import Entry, rank
    from crowdnav.evaluation.track_page import write_page

    track = load_track("figure4")
    entries = [Entry("baseline_straight", "straight to goal (scripted)", "scripted, privileged", "-", tmp_path, {0: "collision", 1: "success"},
                     reference=True),
               Entry("baseline_oracle", "oracle (ceiling)", "ceiling", "-", tmp_path, {0: "success", 1: "success"}, reference=True),
               Entry("mine", "my policy", "policy", "goal", tmp_path, {0: "success", 1: "collision"})]
    page = write_page(rank(track, entries), tmp_path / "page.html")
    done = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--enable-logging=stderr", "--v=0",
                           "--virtual-time-budget=5000", f"--user-data-dir={tmp_path / 'profile'}", "--proxy-server=127.0.0.1:9",
                           "--dump-dom", page.resolve().as_uri()], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    console = [line for line in done.stderr.splitlines() if "CONSOLE" in line]
    assert not console, console
    dom = done.stdout
    assert 'data-frames-loaded="3"' in dom and dom.count("<tr>") == 1 + len(entries)
    for label in ("straight to goal (scripted)", "oracle (ceiling)", "my policy *"):
        assert f"<td>{label}</td>" in dom
