"""CI: the core install alone (``pip install .``, no extras) runs the environments.

Run in a fresh virtual environment holding only crowdnav's core dependencies. It steps a
Gymnasium env and a PettingZoo env, renders an ``rgb_array`` frame, runs ``crowdnav --help``,
evaluates a scripted baseline and a numpy ``module:function`` policy on a track, ranks them
(``crowdnav leaderboard --track``) and renders a scripted policy's video, and checks that none of the
extras' packages were installed or imported on the way.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tempfile
from pathlib import Path

EXTRAS = ("torch", "stable_baselines3", "pandas", "matplotlib", "seaborn", "ray")

missing_on_purpose = [name for name in EXTRAS if importlib.util.find_spec(name) is None]
assert missing_on_purpose == list(EXTRAS), f"the core install pulled extras: {sorted(set(EXTRAS) - set(missing_on_purpose))}"

import gymnasium as gym  # noqa: E402

import crowdnav  # noqa: E402,F401  (registers crowdnav/<Scenario>-v0)
from crowdnav.envs import CrowdNavParallelEnv  # noqa: E402

env = gym.make("crowdnav/RoomFurniture-v0", render_mode="rgb_array")
obs, _ = env.reset(seed=0)
env.action_space.seed(0)  # the same actions on every CI run
for _ in range(5):
    obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
    if terminated or truncated:
        obs, _ = env.reset()
frame = env.render()
assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0, "rgb_array frame is empty"
env.close()

parallel = CrowdNavParallelEnv("open_space")
observations, _ = parallel.reset(seed=0)
for step in range(5):
    if not parallel.agents:
        observations, _ = parallel.reset(seed=step)
    observations, rewards, terminations, truncations, _ = parallel.step({agent: parallel.action_space(agent).sample() for agent in parallel.agents})
parallel.close()

loaded = sorted(name for name in EXTRAS if name in sys.modules)
assert not loaded, f"imported extras: {loaded}"
subprocess.run(["crowdnav", "--help"], check=True, capture_output=True)
# a command of an extra names the extra to install, in one line, instead of a traceback
hint = subprocess.run(["crowdnav", "benchmark"], capture_output=True, text=True)
assert hint.returncode == 1 and hint.stderr.strip().endswith('pip install -e ".[bench]" in crowdnav\'s clone'), hint.stderr
# scripted policies evaluate, rank and render without torch or pandas (the numpy callable: docs/evaluate.md's)
work = Path(tempfile.mkdtemp())
(work / "my_policies.py").write_text("import numpy as np\n\n\ndef toward_goal(observation):\n    distance, sin, cos = observation['goal']\n"
                                     "    return np.array([cos, sin], dtype=np.float32)\n")
for policy, reads in (("baseline:straight", []), ("my_policies:toward_goal", ["--modalities", "goal"])):  # a baseline reads the simulator
    done = subprocess.run(["crowdnav", "evaluate", policy, "--track", "figure4", *reads, "--out", "results", "--no-progress"],
                          cwd=work, capture_output=True, text=True)
    assert done.returncode == 0 and "success 23%" in done.stdout and "100 test episodes of track figure4" in done.stdout, (policy, done.stderr)
board = subprocess.run(["crowdnav", "leaderboard", "--track", "figure4", "results"], cwd=work, capture_output=True, text=True)
assert board.returncode == 0 and "## Track figure4 v" in board.stdout and "my_policies:toward_goal *" in board.stdout, board.stderr
video = subprocess.run(["crowdnav", "render", "room_furniture", "--policy", "straight", "--episodes", "1", "--out", "videos", "--no-progress"],
                       cwd=work, capture_output=True, text=True)
assert video.returncode == 0 and list((work / "videos").glob("*.mp4")), video.stderr
print(f"core install: Gymnasium env, PettingZoo env ({len(observations)} agents) and an rgb_array frame {frame.shape}; scripted policies "
      f"evaluated, ranked on a track and rendered; without {', '.join(EXTRAS)}")
