"""Trajectories of test episodes: a tidy per-step table (CSV) and TrajNet++ ndjson.

Episodes come from :meth:`crowdnav.evaluation.rollout.HeldOutEpisodes.run` with ``record=True``
(``frames``: positions, velocities and goals of the robot and every human at each step, the
reset state first). :func:`replay_evaluation` plays an evaluation of a finished run again from
its saved policy snapshot (test episodes are deterministic) and checks that every outcome
matches the one the run recorded, so an exported trajectory is the episode that was scored.

**Tidy table**, one row per agent and step, world frame, metres, m/s and seconds:

================  =============================================================
column            meaning
================  =============================================================
``test_episode``  index of the held-out episode; ``test_seed`` its reset seed
``outcome``       how the episode ended (success, collision, out_of_bounds, truncated)
``step``          0 for the reset state, then one per env step; ``time_s`` = step * dt
``agent``         ``robot`` or ``human_<i>``
``group``         the human's group (``crowd`` for a file without ``humans.groups``); ``robot`` for the robot
``x, y``          centre
``vx, vy``        velocity
``goal_x, goal_y`` current goal (a human's goal changes when it reaches one)
================  =============================================================

**TrajNet++ ndjson** (https://github.com/vita-epfl/trajnetplusplusdataset, "scene" and "track"
lines): one scene per test episode with the robot as its primary agent. Track ids are
``1000 * test_episode + agent`` (robot 0, human i as i + 1) and frames run on across episodes,
so one file holds every episode without id clashes. Positions in metres.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

TIDY_COLUMNS = ("test_episode", "test_seed", "outcome", "step", "time_s", "agent", "group", "x", "y", "vx", "vy", "goal_x", "goal_y")
TRACK_ID_STRIDE = 1000


def agent_names(count: int) -> list[str]:
    """``robot``, then ``human_0`` ... for ``count`` agents in all."""
    return ["robot", *(f"human_{i}" for i in range(count - 1))]


def tidy_table(episodes: Iterable[Mapping[str, Any]]) -> Any:
    """The per-step table of recorded episodes (pandas DataFrame with :data:`TIDY_COLUMNS`)."""
    import pandas as pd

    frames = []
    for episode in episodes:
        states = episode["frames"]
        positions, velocities, goals = states["positions"], states["velocities"], states["goals"]
        steps, agents = positions.shape
        frames.append(pd.DataFrame({
            "test_episode": episode["test_episode"], "test_seed": episode["test_seed"], "outcome": episode["outcome"],
            "step": np.repeat(np.arange(steps), agents), "time_s": np.repeat(np.arange(steps) * states["dt"], agents),
            "agent": np.tile(agent_names(agents), steps),
            "group": np.tile(states.get("groups", ["robot", *["crowd"] * (agents - 1)]), steps),
            "x": positions.real.ravel(), "y": positions.imag.ravel(), "vx": velocities.real.ravel(), "vy": velocities.imag.ravel(),
            "goal_x": goals.real.ravel(), "goal_y": goals.imag.ravel(),
        }))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=list(TIDY_COLUMNS))


def trajnet_lines(episodes: Iterable[Mapping[str, Any]]) -> list[str]:
    """TrajNet++ ndjson lines: per episode its scene line, then its track lines frame by frame."""
    lines, first_frame = [], 0
    for episode in episodes:
        states = episode["frames"]
        positions = states["positions"]
        steps, agents = positions.shape
        k = int(episode["test_episode"])
        scene = {"id": k, "p": TRACK_ID_STRIDE * k, "s": first_frame, "e": first_frame + steps - 1, "fps": round(1.0 / states["dt"], 6)}
        lines.append(json.dumps({"scene": scene}))
        for step in range(steps):
            for agent in range(agents):
                z = positions[step, agent]
                track = {"f": first_frame + step, "p": TRACK_ID_STRIDE * k + agent, "x": round(float(z.real), 4), "y": round(float(z.imag), 4)}
                lines.append(json.dumps({"track": track}))
        first_frame += steps
    return lines


def write_trajectories(episodes: list[Mapping[str, Any]], stem: str | Path) -> list[Path]:
    """``stem``.csv (tidy table) and ``stem``.ndjson (TrajNet++); returns both paths."""
    from crowdnav.evaluation.storage import atomic_write_csv, atomic_write_text

    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    csv = atomic_write_csv(tidy_table(episodes), stem.with_name(stem.name + ".csv"))
    ndjson = atomic_write_text(stem.with_name(stem.name + ".ndjson"), "\n".join(trajnet_lines(episodes)) + "\n")
    return [csv, ndjson]


class ReplayMismatchError(RuntimeError):
    """A replayed test episode ended differently from the one the run recorded."""


def replay_evaluation(run_dir: str | Path, evaluation: int | None = None) -> list[dict[str, Any]]:
    """The test episodes of evaluation ``evaluation`` (default: the last) of a finished run, recorded.

    ``run_dir``: ``<experiment>/<configuration>/seed_<n>`` (a learned run: its policy snapshot for
    that evaluation is played) or ``<experiment>/baseline_<name>/baseline`` (a scripted baseline,
    the same at every evaluation). Raises :class:`ReplayMismatchError` unless every episode's
    outcome matches the run's recorded one.
    """
    import pandas as pd
    from crowdnav.evaluation.baselines import scripted_policy
    from crowdnav.evaluation.protocol import Protocol
    from crowdnav.evaluation.rollout import HeldOutEpisodes
    from crowdnav.evaluation.storage import ResultsError, read_json

    run_dir = Path(run_dir)
    meta = read_json(run_dir / "meta.json") if (run_dir / "meta.json").is_file() else None
    if meta is None:
        raise ResultsError(f"{run_dir}: not a finished run (no meta.json)")
    protocol = Protocol(**meta["protocol"])
    recorded = pd.read_csv(run_dir / "test_episodes.csv", keep_default_na=False, na_values=["nan"])
    if meta.get("kind") == "baseline":
        episodes = HeldOutEpisodes(meta["env"], protocol.test_seeds)
        rows = episodes.run(scripted_policy(meta["policy"]), privileged=True, record=True)
        expected = recorded.drop_duplicates("test_episode").set_index("test_episode")["outcome"]
    else:
        from crowdnav.agents import load_policy
        from crowdnav.agents.run_folder import policy_snapshots

        k = protocol.evaluations - 1 if evaluation is None else evaluation
        if not 0 <= k < protocol.evaluations:
            raise ResultsError(f"{run_dir}: evaluation {k} does not exist; expected 0 to {protocol.evaluations - 1}")
        this = recorded[recorded["evaluation"] == k]
        unit = "steps" if "training_steps" in this.columns else "episodes"  # the protocol's points, as the columns name them
        point = int(this["training_steps" if unit == "steps" else "training_episodes"].iloc[0])
        folder = policy_snapshots(run_dir / "train", unit).get(point)
        if folder is None:
            raise ResultsError(f"{run_dir}: no policy snapshot after {point} {'env steps' if unit == 'steps' else 'episodes'} to replay")
        policy = load_policy(folder)
        episodes = HeldOutEpisodes(policy.env_options, protocol.test_seeds)
        rows = episodes.run(policy, record=True)
        expected = this.set_index("test_episode")["outcome"]
    episodes.close()
    replayed = {row["test_episode"]: row["outcome"] for row in rows}
    differ = {k: (expected[k], replayed[k]) for k in expected.index if replayed.get(k) != expected[k]}
    if differ:
        raise ReplayMismatchError(f"{run_dir}: replayed outcomes differ from the recorded ones (episode: recorded, replayed): {differ}")
    return rows
