"""Rendering: frames, pixels where the world says, and video files read back."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.rendering import Overlays, Renderer, write_video
from crowdnav.scenario.library import library_names


@pytest.mark.parametrize("name", library_names())
def test_frames_are_uint8_rgb_of_the_renderer_size_for_every_library_scenario(name):
    sim = Simulator(name)
    sim.reset(seed=0)
    renderer = Renderer(sim)
    renderer.record()
    sim.step(np.zeros(2))
    renderer.record()
    frame = renderer.frame(Overlays(human_goals=True), hud="step 1")
    width, height = renderer.size
    assert frame.dtype == np.uint8 and frame.shape == (height, width, 3)
    assert width % 16 == 0 and height % 16 == 0 and max(width, height) <= 640 + 8


def test_furniture_is_drawn_where_the_world_puts_it():
    scenario = {
        "description": "one box",
        "world": {"min": [-5, -5], "max": [5, 5]},
        "furniture": [{"type": "rectangle", "center": [2.0, -1.0], "size": [1.0, 1.0]}],
        "robot": {"start": {"type": "points", "points": [[-4, 4]]}, "goal": {"type": "points", "points": [[-4, -4]]}},
    }
    sim = Simulator(scenario)
    sim.reset(seed=0)
    renderer = Renderer(sim)
    frame = renderer.frame()
    inside = renderer.to_pixels(2.0 - 1.0j).astype(int)  # the box's centre
    outside = renderer.to_pixels(0.5 - 1.0j).astype(int)  # 1 m left of the box's left face
    furniture, background = renderer.palette.furniture, renderer.palette.background
    assert tuple(frame[inside[1], inside[0]]) == furniture
    assert tuple(frame[outside[1], outside[0]]) == background
    # the box's left edge lies between x = 1.45 m and 1.55 m in pixels
    row = frame[inside[1]]
    left = renderer.to_pixels(1.45 - 1.0j)[0]
    right = renderer.to_pixels(1.55 - 1.0j)[0]
    first_furniture_column = int(np.flatnonzero((row == furniture).all(axis=1))[0])
    assert left <= first_furniture_column <= right


def _five_frames() -> list[np.ndarray]:
    sim = Simulator("room_furniture")
    sim.reset(seed=1)
    renderer = Renderer(sim)
    frames = []
    for _ in range(5):
        renderer.record()
        frames.append(renderer.frame(hud="test"))
        sim.step(np.array([0.5, 0.0]))
    return frames


@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_a_five_step_episode_written_to_video_reads_back_with_its_frames_and_size(tmp_path, suffix):
    frames = _five_frames()
    path = write_video(frames, tmp_path / f"episode{suffix}", fps=10)
    video = iio.imread(path)
    assert video.shape[0] == 5
    assert video.shape[1:3] == frames[0].shape[:2]


def test_unknown_video_format_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="unsupported video format"):
        write_video(_five_frames(), tmp_path / "episode.avi")


@pytest.mark.parametrize("name", ["room_furniture", "corridor", "cafe"])
def test_panel_beside_or_below_the_map_never_covers_it_and_the_goal_is_drawn_on_top(name):
    sim = Simulator(name)
    sim.reset(seed=0)
    renderer = Renderer(sim)
    renderer.record()
    grid = np.zeros((60, 60))
    lidar = (np.linspace(-np.pi, np.pi, 90, endpoint=False), np.full(90, 30.0), 30.0)  # rays across the whole map
    frame = renderer.frame(Overlays(leog=grid, lidar=lidar, closest_point=0.5 + 0j), hud="x" * 500)
    assert not renderer._map_rect.colliderect(renderer._panel_rect)
    assert renderer._map_rect.union(renderer._panel_rect).height + renderer._bar == frame.shape[0]
    x, y = renderer.to_pixels(sim.robot_goal).astype(int)
    assert tuple(frame[y, x]) in {renderer.palette.goal, renderer.palette.goal_fill}
    if name == "corridor":
        assert renderer._panel_rect.top >= renderer._map_rect.bottom  # a wide world: the panel goes below
    else:
        assert renderer._panel_rect.left >= renderer._map_rect.right
