"""Regenerate the pictures in the README and docs.

    python docs/figures/make_figures.py

Writes docs/figures/room_furniture_lidar.png (the README's picture), cafe.png and corridor.png
(docs/rendering.md), l_hallway.png (docs/scenarios.md, from the YAML shown there), station_hall.png
(docs/scenarios.md, human groups): a few steps of the social-force robot, with the LIDAR rays, the
closest-obstacle point, the LEOG inset, the legend and the scale bar.
"""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio

from crowdnav import CrowdNavEnv
from crowdnav.planning.scripted import SocialForceRobot

HERE = Path(__file__).parent


def frame(scenario: str | dict, path: Path, seed: int = 3, steps: int = 20) -> Path:
    env = CrowdNavEnv(
        scenario,
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
    print(f"wrote {frame('room_furniture', HERE / 'room_furniture_lidar.png')}")
    print(f"wrote {frame('cafe', HERE / 'cafe.png', seed=1, steps=15)}")
    print(f"wrote {frame('corridor', HERE / 'corridor.png', seed=1, steps=10)}")
    print(f"wrote {frame('station_hall', HERE / 'station_hall.png', seed=0, steps=25)}")
    import re

    import yaml

    hallway = re.search(r"A polygon world.*?```yaml\n(.*?)```", (HERE.parent / "scenarios.md").read_text(), re.S)[1]
    print(f"wrote {frame(yaml.safe_load(hallway), HERE / 'l_hallway.png', seed=0, steps=12)}")
