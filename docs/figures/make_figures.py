"""Regenerate the pictures in the README and docs.

    python docs/figures/make_figures.py

Writes docs/figures/room_furniture_lidar.png: the furniture room after a few steps of the
social-force robot, with the LIDAR rays, the closest-obstacle point and the LEOG inset.
"""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio

from crowdnav import CrowdNavEnv
from crowdnav.policies import SocialForceRobot

HERE = Path(__file__).parent


def room_furniture_lidar(path: Path, seed: int = 3, steps: int = 20) -> Path:
    env = CrowdNavEnv(
        "room_furniture",
        modalities=["goal", "lidar", "leog", "closest_obstacle"],
        render_mode="rgb_array",
        render_options={"human_goals": True},
    )
    env.reset(seed=seed)
    policy = SocialForceRobot()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(policy(env.simulator))
        if terminated or truncated:
            break
    iio.imwrite(path, env.render())
    env.close()
    return path


if __name__ == "__main__":
    print(f"wrote {room_furniture_lidar(HERE / 'room_furniture_lidar.png')}")
