"""Rendering through the environments and the `crowdnav render` command."""

from __future__ import annotations

import re

import gymnasium as gym
import imageio.v3 as iio
import numpy as np
import pytest
from gymnasium.wrappers import RecordVideo

import crowdnav
from crowdnav.cli import main


def test_gymnasium_env_renders_rgb_frames_and_declares_its_render_modes():
    env = gym.make("crowdnav/RoomFurniture-v0", render_mode="rgb_array", modalities=["goal", "lidar", "leog"])
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert set(env.metadata["render_modes"]) == {"human", "rgb_array"}
    assert env.metadata["render_fps"] == pytest.approx(1 / env.unwrapped.scenario.time_step)
    env.step(env.action_space.sample())
    assert env.render().shape == frame.shape
    env.close()


def test_parallel_env_renders_rgb_frames():
    env = crowdnav.parallel_env("open_space", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape[2] == 3


def test_human_mode_draws_a_window_with_the_dummy_video_driver(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    env = crowdnav.CrowdNavEnv("empty_room", render_mode="human")
    env.reset(seed=0)
    env.step(np.zeros(2, dtype=np.float32))
    assert env.render() is None
    env.close()


def test_unknown_render_mode_or_render_option_is_a_clear_error():
    with pytest.raises(ValueError, match="render_mode='ascii'"):
        crowdnav.CrowdNavEnv("empty_room", render_mode="ascii")
    with pytest.raises(ValueError, match="unknown render_options"):
        crowdnav.CrowdNavEnv("empty_room", render_mode="rgb_array", render_options={"lidr": True})


def test_record_video_writes_a_file_from_a_registered_id(tmp_path):
    env = gym.make("crowdnav/EmptyRoom-v0", render_mode="rgb_array")
    env = RecordVideo(env, video_folder=str(tmp_path / "videos"), episode_trigger=lambda episode: True, disable_logger=True)
    env.reset(seed=0)
    for _ in range(5):  # standing still in an empty room: five steps without the episode ending
        env.step(np.zeros(2, dtype=np.float32))
    env.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert len(videos) == 1
    assert iio.imread(videos[0]).shape[0] >= 5


def test_render_command_writes_one_video_per_episode_and_says_where(tmp_path, capsys):
    status = main(["render", "empty_room", "--policy", "straight", "--episodes", "2", "--format", "gif",
                   "--out", str(tmp_path), "--no-progress"])
    assert status == 0
    written = sorted(tmp_path.glob("*.gif"))
    outcome = "(success|collision|out_of_bounds|truncated)"  # videos are named by how the episode ended
    assert [bool(re.fullmatch(rf"empty_room_straight_seed{k}_{outcome}\.gif", p.name)) for k, p in enumerate(written)] == [True, True]
    out = capsys.readouterr().out
    assert all(str(p) in out for p in written)
    assert iio.imread(written[0]).shape[0] >= 2


@pytest.mark.parametrize(
    "argv, message",
    [
        (["render", "empty_room", "--policy", "nope"], "neither a scripted policy"),
        (["render", "no_such_scenario"], "no such file or library scenario"),
        (["render", "empty_room", "--episodes", "0"], "at least 1"),
    ],
)
def test_render_command_reports_bad_input_in_one_line(argv, message, capsys):
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_render_command_says_clearly_when_a_checkpoint_cannot_be_loaded(tmp_path, capsys):
    bogus = tmp_path / "model.zip"
    bogus.write_bytes(b"not a checkpoint")
    assert main(["render", "empty_room", "--policy", str(bogus), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "model.zip: cannot read it as a zip" in err and len(err.strip().splitlines()) == 1


def test_a_frame_renders_with_every_overlay_switched_off_even_without_any_sensor_to_draw():
    options = {"lidar": False, "leog": False, "closest_obstacle": False}
    env = crowdnav.CrowdNavEnv("room_furniture", modalities=["goal"], render_mode="rgb_array", render_options=options)
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3
    env.close()
    parallel = crowdnav.parallel_env("room_furniture", render_mode="rgb_array", render_options=options)
    parallel.reset(seed=0)
    assert parallel.render().shape == frame.shape
    parallel.close()


def test_crowdnav_render_hides_the_named_overlays_and_names_an_unknown_one(tmp_path, capsys):
    from crowdnav.cli import main

    assert main(["render", "empty_room", "--episodes", "1", "--hide", "lidar,leog,closest_obstacle", "--out", str(tmp_path),
                 "--no-progress"]) == 0
    assert len(list(tmp_path.glob("*.mp4"))) == 1
    assert main(["render", "empty_room", "--hide", "lidr", "--out", str(tmp_path)]) == 1
    assert "did you mean 'lidar'" in capsys.readouterr().err


def test_render_takes_either_spelling_of_a_scripted_policy(tmp_path):
    from crowdnav.cli import main

    for spelling in ("social-force", "social_force"):
        assert main(["render", "open_space", "--policy", spelling, "--episodes", "1", "--format", "gif",
                     "--out", str(tmp_path / spelling), "--no-progress"]) == 0
    assert [p.name.endswith("_success.gif") for p in tmp_path.rglob("*.gif")] == [True, True]
