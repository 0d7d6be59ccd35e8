"""A symbolic link planted where crowdnav writes never makes it write elsewhere: per file it writes, the link is refused in one
line (locks, appended tables) or replaced (whole files), and the file it points to stays as it was."""

from __future__ import annotations

import errno
import fcntl
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from crowdnav.agents import pretrain_encoder, train
from crowdnav.agents.imitation.demonstrations import REPORT_FILE as DEMONSTRATIONS_REPORT
from crowdnav.agents.networks.dataset import GridDataset, load_dataset, save_dataset
from crowdnav.agents.networks.pretrain import load_encoder
from crowdnav.agents.runs.episode_log import DISCARDED_SUFFIX, HEADER, EpisodeLogWriter, prepare_log
from crowdnav.agents.runs.folder import LOCK_FILE, RunBusyError, hold_lock
from crowdnav.evaluation.jobs import write_error_log
from crowdnav.evaluation.rollout import HeldOutEpisodes
from crowdnav.evaluation.storage import atomic_write_csv, atomic_write_json
from crowdnav.evaluation.trajectories import write_trajectories
from crowdnav.evaluation.validation_choice import choose_on_validation

from crowdnav.cli import main
from crowdnav.files import LinkedFileError, atomic_write_bytes, open_for_write
from crowdnav.planning.scripted import StraightToGoal
from crowdnav.rendering.video import VideoWriter, write_video
from tests.agents.agents_tiny import tiny_config

VICTIM_TEXT = "the victim's own content\n"


def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "elsewhere" / "victim.txt"
    victim.parent.mkdir(exist_ok=True)
    victim.write_text(VICTIM_TEXT)
    return victim


def _plant(link: Path, target: Path) -> Path:
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(target)
    return link


def _one_line_error(capsys: pytest.CaptureFixture[str], *says: str) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("crowdnav: error:"), lines
    assert all(word in lines[0] for word in says), lines[0]
    return lines[0]


# --------------------------------------------------------------------------- the primitives


def test_open_for_write_refuses_a_link_and_leaves_its_target(tmp_path):
    victim = _victim(tmp_path)
    link = _plant(tmp_path / "out" / "file", victim)
    with pytest.raises(LinkedFileError, match="is a symbolic link"):
        open_for_write(link)
    assert victim.read_text() == VICTIM_TEXT


def test_open_for_write_refuses_a_dangling_link_without_creating_its_target(tmp_path):
    absent = tmp_path / "elsewhere" / "absent.txt"
    with pytest.raises(LinkedFileError):
        open_for_write(_plant(tmp_path / "out" / "file", absent))
    assert not absent.exists()


def test_an_atomic_write_replaces_a_link_and_leaves_its_target(tmp_path):
    victim = _victim(tmp_path)
    link = _plant(tmp_path / "out" / "file", victim)
    atomic_write_bytes(link, b"new")
    assert not link.is_symlink() and link.read_bytes() == b"new"
    assert victim.read_text() == VICTIM_TEXT
    assert sorted(path.name for path in link.parent.iterdir()) == ["file"]  # no temporary left


# --------------------------------------------------------------------------- crowdnav evaluate: its lock and its result


EVALUATE = ["evaluate", "baseline:straight", "--scenario", "open_space", "--episodes", "2", "--out", "out", "--no-progress"]
RESULT = Path("out", "evaluate", "baseline_straight--open_space", "seeds_0-1")


def test_evaluate_refuses_a_linked_result_lock_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    victim = _victim(tmp_path)
    _plant(tmp_path / RESULT.parent / f".{RESULT.name}.lock", victim)
    assert main(EVALUATE) == 1
    _one_line_error(capsys, "symbolic link", f".{RESULT.name}.lock")
    assert victim.read_text() == VICTIM_TEXT
    assert not (tmp_path / RESULT).exists()


def test_evaluate_refuses_a_link_in_its_result_folders_place_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    victim = _victim(tmp_path)
    _plant(tmp_path / RESULT, victim.parent)
    assert main(EVALUATE) == 1
    _one_line_error(capsys, "outside the output folder")
    assert sorted(path.name for path in victim.parent.iterdir()) == ["victim.txt"] and victim.read_text() == VICTIM_TEXT


def test_a_file_system_without_flock_is_refused_in_one_line_naming_the_folder(tmp_path, capsys, monkeypatch):
    def no_locks(*_: object) -> None:
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(fcntl, "flock", no_locks)
    assert main(EVALUATE) == 1
    _one_line_error(capsys, str(RESULT.parent), "cannot lock files")
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").rglob("*.lock"))


# --------------------------------------------------------------------------- crowdnav train --resume: lock, config, checkpoint


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished 2-episode tiny run (trained once; each test resumes a copy of it to 3 episodes)."""
    folder = tmp_path_factory.mktemp("trained")
    config = tiny_config(folder / "run", algo="ppo", episodes=2, max_steps=20)
    (folder / "train.yaml").write_text(yaml.safe_dump(config))
    assert main(["train", "--config", str(folder / "train.yaml")]) == 0
    return folder / "run"


def _resume(trained: Path, tmp_path: Path, plant: str, target: Path) -> tuple[int, Path]:
    run = tmp_path / "run"
    shutil.copytree(trained, run)
    (run / plant).unlink(missing_ok=True)
    _plant(run / plant, target)
    config = tiny_config(run, algo="ppo", episodes=3, max_steps=20)
    (tmp_path / "train.yaml").write_text(yaml.safe_dump(config))
    return main(["train", "--config", str(tmp_path / "train.yaml"), "--resume"]), run


def test_train_resume_refuses_a_linked_writer_lock_in_one_line(trained, tmp_path, capsys):
    victim = _victim(tmp_path)
    capsys.readouterr()
    status, run = _resume(trained, tmp_path, LOCK_FILE, victim)
    assert status == 1
    _one_line_error(capsys, "symbolic link", LOCK_FILE)
    assert victim.read_text() == VICTIM_TEXT
    assert json.loads((run / "checkpoint" / "policy.json").read_text())["episodes"] == 2  # nothing trained


def test_train_resume_replaces_a_linked_config_yaml(trained, tmp_path):
    victim = _victim(tmp_path)
    status, run = _resume(trained, tmp_path, "config.yaml", victim)
    assert status == 0 and victim.read_text() == VICTIM_TEXT
    assert not (run / "config.yaml").is_symlink() and yaml.safe_load((run / "config.yaml").read_text())["episodes"] == 3


def test_train_resume_removes_a_linked_checkpoint_staging_folder_without_following_it(trained, tmp_path):
    victim = _victim(tmp_path)
    status, run = _resume(trained, tmp_path, "checkpoint.partial", victim.parent)
    assert status == 0 and json.loads((run / "checkpoint" / "policy.json").read_text())["episodes"] == 3
    assert sorted(path.name for path in victim.parent.iterdir()) == ["victim.txt"] and victim.read_text() == VICTIM_TEXT
    assert not (run / "checkpoint.partial").exists() and not (run / "checkpoint.partial").is_symlink()


# --------------------------------------------------------------------------- the episode log


def test_the_episode_logs_discarded_rows_are_not_appended_through_a_link(tmp_path):
    victim = _victim(tmp_path)
    log = tmp_path / "run" / "episodes.csv"
    log.parent.mkdir()
    log.write_text(HEADER + "\n" + "".join(f"{k},{k},success,1.0,5,5,0.1\n" for k in range(3)))
    _plant(log.with_name(log.name + DISCARDED_SUFFIX), victim)
    with pytest.raises(LinkedFileError):
        prepare_log(log, 1)  # episode 2 is after the checkpoint: its row would be set aside
    assert victim.read_text() == VICTIM_TEXT


def test_the_episode_log_is_replaced_not_written_through_and_its_writer_refuses_a_link(tmp_path):
    victim = tmp_path / "elsewhere" / "empty.csv"
    victim.parent.mkdir()
    victim.write_text("")
    log = _plant(tmp_path / "run" / "episodes.csv", victim)
    with pytest.raises(LinkedFileError):
        EpisodeLogWriter(log)
    prepare_log(log, 0)  # an empty log gets its header: in a new file in the link's place
    assert not log.is_symlink() and log.read_text() == HEADER + "\n" and victim.read_text() == ""


# --------------------------------------------------------------------------- result tables, trajectories, error log


def test_result_tables_and_json_replace_links(tmp_path):
    import pandas as pd

    victim = _victim(tmp_path)
    table = atomic_write_csv(pd.DataFrame({"seed": [1]}), _plant(tmp_path / "run" / "test_episodes.csv", victim))
    meta = atomic_write_json(_plant(tmp_path / "run" / "meta.json", victim), {"a": 1})
    assert table.read_text() == "seed\n1\n" and json.loads(meta.read_text()) == {"a": 1}
    assert not table.is_symlink() and not meta.is_symlink() and victim.read_text() == VICTIM_TEXT


def test_trajectories_replace_links(tmp_path):
    victim = _victim(tmp_path)
    recorded = HeldOutEpisodes({"scenario": "open_space", "modalities": ["goal"], "overrides": {"max_steps": 5}}, [0]).run(
        StraightToGoal(), privileged=True, record=True)
    stem = tmp_path / "out" / "trajectories"
    _plant(stem.with_name("trajectories.csv"), victim)
    _plant(stem.with_name("trajectories.ndjson"), victim)
    written = write_trajectories(recorded, stem)
    assert all(not path.is_symlink() and path.stat().st_size > 0 for path in written) and victim.read_text() == VICTIM_TEXT


def test_the_error_log_replaces_a_link(tmp_path):
    victim = _victim(tmp_path)
    log = write_error_log(_plant(tmp_path / "run" / "error.log", victim).parent, "Traceback ...\n")
    assert not log.is_symlink() and log.read_text() == "Traceback ...\n" and victim.read_text() == VICTIM_TEXT


# --------------------------------------------------------------------------- validation tables


def _experiment(tmp_path: Path) -> tuple[Path, Path]:
    """An experiment with one run whose one evaluation point is stored in its validation table (nothing left to play)."""
    run = tmp_path / "experiment" / "config" / "seed_0"
    run.mkdir(parents=True)
    (run / "spec.json").write_text(json.dumps({"configuration": "config", "seed": 0,
                                               "protocol": {"test_seed_base": 0, "test_episodes": 2}}))
    (run / "test_episodes.csv").write_text("training_episodes,outcome\n10,success\n10,collision\n")
    return run.parent.parent, run / "validation_500000_2.csv"


def test_a_linked_validation_table_is_neither_read_nor_appended_to(tmp_path):
    victim = _victim(tmp_path)
    experiment, table = _experiment(tmp_path)
    _plant(table, victim)
    with pytest.raises(LinkedFileError):
        choose_on_validation(experiment, episodes=2, log=lambda line: None)
    assert victim.read_text() == VICTIM_TEXT


def test_a_dangling_validation_table_link_creates_nothing(tmp_path):
    absent = tmp_path / "elsewhere" / "absent.csv"
    experiment, table = _experiment(tmp_path)
    _plant(table, absent)
    with pytest.raises(LinkedFileError):
        choose_on_validation(experiment, episodes=2, log=lambda line: None)
    assert not absent.exists()


def test_a_second_writer_of_a_validation_table_is_refused_at_once(tmp_path):
    experiment, table = _experiment(tmp_path)
    table.write_text("training_episodes,episodes,success,collision,out_of_bounds,truncated\n10,2,2,0,0,0\n")
    with hold_lock(table.with_name(f".{table.name}.lock"), lambda holder: "held"), \
            pytest.raises(RunBusyError, match="is being written by another process"):
        choose_on_validation(experiment, episodes=2, log=lambda line: None)
    assert choose_on_validation(experiment, episodes=2, log=lambda line: None)[0].chosen == 10  # free again: read, nothing played


# --------------------------------------------------------------------------- videos


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_a_video_replaces_a_link(tmp_path, suffix):
    if suffix == ".mp4":
        pytest.importorskip("imageio_ffmpeg")
    victim = _victim(tmp_path)
    video = _plant(tmp_path / "videos" / f"episode{suffix}", victim)
    write_video([np.zeros((16, 16, 3), np.uint8)] * 2, video, fps=5)
    assert not video.is_symlink() and video.stat().st_size > 0 and victim.read_text() == VICTIM_TEXT
    assert sorted(path.name for path in video.parent.iterdir()) == [video.name]


def test_a_video_whose_episode_raised_leaves_nothing(tmp_path):
    video = tmp_path / "videos" / "episode.gif"
    with pytest.raises(RuntimeError), VideoWriter(video) as writer:
        writer.append(np.zeros((16, 16, 3), np.uint8))
        raise RuntimeError("the policy failed")
    assert list(video.parent.iterdir()) == []


def test_a_rendered_episode_that_raised_keeps_a_users_file_of_the_videos_name(tmp_path):
    from crowdnav.rendering.episodes import render_episodes

    kept = tmp_path / "videos" / "open_space_broken_seed0.gif"
    kept.parent.mkdir()
    kept.write_text(VICTIM_TEXT)

    def broken(env, observation):
        raise RuntimeError("the policy failed")

    with pytest.raises(RuntimeError):
        render_episodes("open_space", broken, label="broken", episodes=1, out=tmp_path / "videos", video_format="gif", progress=False)
    assert kept.read_text() == VICTIM_TEXT and sorted(path.name for path in kept.parent.iterdir()) == [kept.name]


# --------------------------------------------------------------------------- pre-training, datasets, demonstrations, ONNX


def test_a_grid_dataset_replaces_a_link(tmp_path):
    victim = _victim(tmp_path)
    path = _plant(tmp_path / "data" / "grids.npz", victim)
    save_dataset(GridDataset(np.ones((2, 1, 4, 4), np.uint8)), path)
    assert not path.is_symlink() and load_dataset(path).grids.shape == (2, 1, 4, 4) and victim.read_text() == VICTIM_TEXT
    assert sorted(p.name for p in path.parent.iterdir()) == ["grids.npz"]  # numpy wrote the temporary's own name, no other


def test_a_pretrained_encoders_weights_summary_and_plot_replace_links(tmp_path):
    pytest.importorskip("matplotlib")
    victim = _victim(tmp_path)
    out = tmp_path / "encoder"
    names = ("encoder.pt", "encoder.json", "loss.png")
    for name in names:
        _plant(out / name, victim)
    grids = (np.random.default_rng(0).random((16, 1, 30, 30)) < 0.1).astype(np.uint8)
    pretrain_encoder(grids, out, channels=[4], kernels=[5], strides=[5], latent=4, epochs=1)
    assert all(not (out / name).is_symlink() and (out / name).stat().st_size > 0 for name in names)
    assert load_encoder(out)[1]["format"] and victim.read_text() == VICTIM_TEXT
    assert sorted(p.name for p in out.iterdir()) == sorted(names)


def test_the_demonstrations_report_replaces_a_link(tmp_path):
    victim = _victim(tmp_path)
    run = tmp_path / "run"
    _plant(run / DEMONSTRATIONS_REPORT, victim)
    train(tiny_config(run, algo="ppo", episodes=1, max_steps=10, demonstrations={"episodes": 1, "epochs": 1}))
    report = run / DEMONSTRATIONS_REPORT
    assert not report.is_symlink() and json.loads(report.read_text())["episodes"] == 1 and victim.read_text() == VICTIM_TEXT


def test_an_onnx_export_replaces_a_link_given_force_and_creates_nothing_through_a_dangling_one(trained, tmp_path):
    pytest.importorskip("onnx")
    victim = _victim(tmp_path)
    graph = _plant(tmp_path / "out" / "policy.onnx", victim)
    assert main(["export", str(trained), "--out", str(graph), "--force"]) == 0
    assert not graph.is_symlink() and graph.stat().st_size > 0 and victim.read_text() == VICTIM_TEXT
    absent = tmp_path / "elsewhere" / "absent.onnx"
    dangling = _plant(tmp_path / "out" / "other.onnx", absent)
    assert main(["export", str(trained), "--out", str(dangling)]) == 0
    assert not dangling.is_symlink() and not absent.exists()
    assert sorted(p.name for p in graph.parent.iterdir()) == ["other.onnx", "policy.onnx"]


# --------------------------------------------------------------------------- scenario from-recording, schema, benchmark scripts


def test_scenario_from_recording_refuses_a_dangling_link_as_out_in_one_line(tmp_path, capsys):
    from tests.cli.test_recording_cli import write_recording

    recording = tmp_path / "obsmat.txt"
    write_recording(recording, "obsmat")
    absent = tmp_path / "elsewhere" / "absent.yaml"
    out = _plant(tmp_path / "out" / "recorded.yaml", absent)
    assert main(["scenario", "from-recording", str(recording), "--out", str(out)]) == 1
    _one_line_error(capsys, "--out", "exists")
    assert not absent.exists() and out.is_symlink()


@pytest.mark.parametrize("command", [["schema", "train"], ["scenario", "schema"]])
def test_a_schema_written_to_a_file_replaces_a_link(tmp_path, command):
    victim = _victim(tmp_path)
    out = _plant(tmp_path / "out" / "schema.json", victim)
    assert main([*command, "--output", str(out)]) == 0
    assert not out.is_symlink() and "$schema" in json.loads(out.read_text()) and victim.read_text() == VICTIM_TEXT


def test_the_fit_commands_synthetic_recording_and_table_replace_links(tmp_path):
    victim = _victim(tmp_path)
    recording = _plant(tmp_path / "out" / "walkers.txt", victim)
    table = _plant(tmp_path / "out" / "table.md", victim)
    assert main(["scenario", "fit", "--synthetic", str(recording), "--max-rollouts", "20", "--out", str(table)]) == 0
    assert not recording.is_symlink() and not table.is_symlink() and "| ADE (m)" in table.read_text()
    assert victim.read_text() == VICTIM_TEXT


def test_the_learning_curves_figures_replace_links(tmp_path_factory, tmp_path):
    from tests.evaluation.evaluation_tiny import tiny_results

    victim = _victim(tmp_path)
    stem = tmp_path / "figures" / "curves"
    for suffix in (".png", ".pdf"):
        _plant(stem.with_name(stem.name + suffix), victim)
    assert main(["plot", str(tiny_results(tmp_path_factory)), "--out", str(stem)]) == 0
    assert (stem.with_name("curves.png")).read_bytes().startswith(b"\x89PNG") and victim.read_text() == VICTIM_TEXT
    assert sorted(p.name for p in stem.parent.iterdir()) == ["curves.pdf", "curves.png"]
    assert not any(p.is_symlink() for p in stem.parent.iterdir())
