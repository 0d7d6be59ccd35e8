"""Time to render a 200-step episode of the furniture room to MP4 at the default frame size.

    python benchmarks/bench_render.py [--steps 200] [--repeats 3]

Reports drawing (env.render) and encoding separately, median over repeats.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from crowdnav import CrowdNavEnv
from crowdnav.planning.scripted import RandomPolicy
from crowdnav.rendering import VideoWriter


def one_episode(steps: int, folder: Path) -> tuple[float, float]:
    env = CrowdNavEnv("room_furniture", modalities=["goal", "lidar", "leog"], render_mode="rgb_array",
                      overrides={"max_steps": steps})
    policy = RandomPolicy(seed=0)
    env.reset(seed=0)
    frames, draw = [env.render()], 0.0
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(policy(env.simulator))
        start = time.perf_counter()
        frames.append(env.render())
        draw += time.perf_counter() - start
        if terminated or truncated:
            env.reset()
    start = time.perf_counter()
    with VideoWriter(folder / "episode.mp4", fps=env.metadata["render_fps"]) as writer:
        for frame in frames:
            writer.append(frame)
    return draw, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        runs = [one_episode(args.steps, Path(folder)) for _ in range(args.repeats)]
    draw = statistics.median(d for d, _ in runs)
    encode = statistics.median(e for _, e in runs)
    print(f"{args.steps} steps: draw {draw:.2f} s + encode {encode:.2f} s = {draw + encode:.2f} s (median of {args.repeats})")


if __name__ == "__main__":
    main()
