"""Trajectories of test episodes: a tidy per-step table (CSV) and TrajNet++ ndjson.

Episodes come from :meth:`crowdnav.evaluation.rollout.HeldOutEpisodes.run` with ``record=True``
(``frames``: positions, velocities and goals of the robot and every human at each step, the
reset state first, and how often each human respawned so far). Two ways to get them:

* :func:`replay_evaluation` plays the test episodes of a finished result again: a benchmark run
  (from its saved policy snapshot for that evaluation), a scripted baseline, or a
  ``crowdnav evaluate`` result (its POLICY loaded again). Test episodes are deterministic, and
  every replayed outcome is checked against the recorded one, so an exported trajectory is the
  episode that was scored;
* :func:`record_policy` plays any POLICY (every form ``crowdnav evaluate`` takes) on a
  scenario's test episodes.

**Tracks.** A human of a group with ``on_goal: respawn`` that reaches its goal reappears at a
spawn point: for a trajectory predictor that is a new pedestrian, not a jump. Each life of a
human is its own track (TrajNet++'s convention): no track moves further in one step than its
agent's speed allows. A recorded crowd (``humans.model: replay``) holds its people in places
that wait empty, parked far outside the world, between two people: an empty place has no row and
no track line, and a person entering a place starts a new track (``respawned`` True on its first row).

**Tidy table**, one row per agent and step, world frame, metres, m/s and seconds:

================  =============================================================
column            meaning
================  =============================================================
``test_episode``  index of the held-out episode; ``test_seed`` its reset seed
``outcome``       how the episode ended (success, collision, out_of_bounds, truncated)
``step``          0 for the reset state, then one per env step; ``time_s`` = step * dt
``agent``         ``robot`` or ``human_<i>`` (the simulator's slot: one slot holds every life of a respawning human);
                  several robots: each robot's name, the first robot's rows first, the others' after the humans
                  (x, y, vx, vy NaN once a robot has left the world)
``track``         the track id, the ``p`` of the TrajNet++ file: one per robot, per human and per respawn
``respawned``     True on the first row of a track that starts with a respawn (its previous row of
                  the same ``agent`` is the other track's last)
``group``         the human's group (``crowd`` for a file without ``humans.groups``); ``robot`` for the robot
``x, y``          centre
``vx, vy``        velocity (0 on the respawn row)
``goal_x, goal_y`` current goal (a human's goal changes when it reaches one)
================  =============================================================

**TrajNet++ ndjson** (https://github.com/vita-epfl/trajnetplusplusdataset, "scene" and "track"
lines): one scene per test episode with the robot as its primary agent. Track ids are
``stride * test_episode + k``: the robot k = 0, human i's first life k = i + 1, then each respawn
(in order of time, then human) the next k; ``stride`` is 1000, or the next power of ten when an
episode has more tracks. Frames run on across episodes, so one file holds every episode without
id clashes. Positions in metres.
"""

from __future__ import annotations

import json
import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.crowd.replay import empty_places
from crowdnav.errors import CrowdNavError

TIDY_COLUMNS = ("test_episode", "test_seed", "outcome", "step", "time_s", "agent", "track", "respawned", "group",
                "x", "y", "vx", "vy", "goal_x", "goal_y")
TRACK_ID_STRIDE = 1000
"""The smallest track id stride: ids of test episode k start at ``stride * k``."""


def agent_names(count: int) -> list[str]:
    """``robot``, then ``human_0`` ... for ``count`` agents in all."""
    return ["robot", *(f"human_{i}" for i in range(count - 1))]


def _respawn_steps(states: Mapping[str, Any]) -> np.ndarray:
    """(steps, agents) bool: True where an agent's new life starts by a respawn, or by a recorded person entering an empty place
    (the robot never respawns)."""
    steps, agents = states["positions"].shape
    counts = np.asarray(states.get("respawns", np.zeros((steps, agents - 1), dtype=np.int64)))
    out = np.zeros((steps, agents), dtype=bool)
    out[1:, 1 : 1 + counts.shape[1]] = np.diff(counts, axis=0) > 0  # at most one respawn per human and step (other robots: never)
    empty = empty_places(states["positions"])
    out[1:] |= empty[:-1] & ~empty[1:]
    return out


def track_stride(episodes: Sequence[Mapping[str, Any]]) -> int:
    """:data:`TRACK_ID_STRIDE`, or the next power of ten when an episode has more tracks than that."""
    most = max((episode["frames"]["positions"].shape[1] + int(_respawn_steps(episode["frames"]).sum()) for episode in episodes), default=0)
    return TRACK_ID_STRIDE if most <= TRACK_ID_STRIDE else 10 ** math.ceil(math.log10(most))


def track_ids(states: Mapping[str, Any], test_episode: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """(steps, agents) track ids of one recorded episode, and where a track starts by a respawn (see the module doc)."""
    respawned = _respawn_steps(states)
    steps, agents = respawned.shape
    base = stride * int(test_episode)
    new_ids = np.zeros((steps, agents), dtype=np.int64)
    new_ids[0] = base + np.arange(agents)
    new_ids[respawned] = base + agents + np.arange(int(respawned.sum()))  # row-major: by step, then agent
    # every row takes the id of its agent's latest start (step 0 or a respawn)
    start = np.where(respawned, np.arange(steps)[:, None], 0)
    latest = np.maximum.accumulate(start, axis=0)
    return new_ids[latest, np.arange(agents)], respawned


def tidy_table(episodes: Iterable[Mapping[str, Any]]) -> Any:
    """The per-step table of recorded episodes (pandas DataFrame with :data:`TIDY_COLUMNS`)."""
    import pandas as pd

    episodes = list(episodes)
    stride = track_stride(episodes)
    frames = []
    for episode in episodes:
        states = episode["frames"]
        positions, velocities, goals = states["positions"], states["velocities"], states["goals"]
        steps, agents = positions.shape
        tracks, respawned = track_ids(states, episode["test_episode"], stride)
        table = pd.DataFrame({
            "test_episode": episode["test_episode"], "test_seed": episode["test_seed"], "outcome": episode["outcome"],
            "step": np.repeat(np.arange(steps), agents), "time_s": np.repeat(np.arange(steps) * states["dt"], agents),
            "agent": np.tile(states.get("agents", agent_names(agents)), steps), "track": tracks.ravel(), "respawned": respawned.ravel(),
            "group": np.tile(states.get("groups", ["robot", *["crowd"] * (agents - 1)]), steps),
            "x": positions.real.ravel(), "y": positions.imag.ravel(), "vx": velocities.real.ravel(), "vy": velocities.imag.ravel(),
            "goal_x": goals.real.ravel(), "goal_y": goals.imag.ravel(),
        })
        empty = empty_places(positions).ravel()
        frames.append(table[~empty].reset_index(drop=True) if empty.any() else table)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=list(TIDY_COLUMNS))


def trajnet_lines(episodes: Iterable[Mapping[str, Any]]) -> list[str]:
    """TrajNet++ ndjson lines: per episode its scene line, then its track lines frame by frame."""
    episodes = list(episodes)
    stride = track_stride(episodes)
    lines, first_frame = [], 0
    for episode in episodes:
        states = episode["frames"]
        positions = states["positions"]
        steps, agents = positions.shape
        k = int(episode["test_episode"])
        tracks, _ = track_ids(states, k, stride)
        scene = {"id": k, "p": stride * k, "s": first_frame, "e": first_frame + steps - 1, "fps": round(1.0 / states["dt"], 6)}
        lines.append(json.dumps({"scene": scene}))
        xs, ys = np.round(positions.real, 4).tolist(), np.round(positions.imag, 4).tolist()
        ids = tracks.tolist()
        # a robot that left the world (several robots) has no more track lines, an empty place of a recorded crowd none
        there = (np.isfinite(positions) & ~empty_places(positions)).tolist()
        for step in range(steps):  # text output: one line per agent and frame
            lines.extend(json.dumps({"track": {"f": first_frame + step, "p": ids[step][a], "x": xs[step][a], "y": ys[step][a]}})
                         for a in range(agents) if there[step][a])
        first_frame += steps
    return lines


def write_trajectories(episodes: Sequence[Mapping[str, Any]], stem: str | Path) -> list[Path]:
    """``stem``.csv (tidy table) and ``stem``.ndjson (TrajNet++); returns both paths."""
    from crowdnav.evaluation.storage import atomic_write_csv, atomic_write_text

    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    csv = atomic_write_csv(tidy_table(episodes), stem.with_name(stem.name + ".csv"))
    ndjson = atomic_write_text(stem.with_name(stem.name + ".ndjson"), "\n".join(trajnet_lines(episodes)) + "\n")
    return [csv, ndjson]


class ReplayMismatchError(CrowdNavError, RuntimeError):
    """A replayed test episode ended differently from the one the run recorded."""


def record_policy(policy: str, scenario: str | None = None, *, modalities: Sequence[str] | None = None, episodes: int = 20,
                  test_seed_base: int = 0, overrides: Mapping[str, Any] | None = None) -> list[dict[str, Any]]:
    """The test episodes (seeds ``test_seed_base`` ...) of ``policy`` on ``scenario``, recorded.

    ``policy``: any POLICY string of ``crowdnav evaluate`` (``baseline:NAME``, ``module:function``,
    an SB3 ``.zip``, a crowdnav run folder or checkpoint), loaded by
    :func:`crowdnav.evaluation.evaluate.resolve_policy`; ``scenario`` may be left out for a crowdnav
    run or checkpoint (its own scenario). The episodes are those ``crowdnav evaluate`` scores with
    the same arguments. Raises :class:`crowdnav.evaluation.evaluate.PolicyError` (one line) for a
    policy that cannot be loaded or returns a malformed action.
    """
    from crowdnav.evaluation.evaluate import PolicyError, resolve_policy
    from crowdnav.evaluation.protocol import Protocol

    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    options: dict[str, Any] = {"scenario": scenario, "modalities": list(modalities) if modalities else None,
                               "overrides": dict(overrides) if overrides else None}
    options = {key: value for key, value in options.items() if value is not None}
    _, _, act, privileged, env_options = resolve_policy(policy, options)
    if "scenario" not in env_options:
        raise PolicyError(f"{policy}: no scenario to play it on; name one (--scenario)")
    protocol = Protocol(train_episodes=1, eval_every=1, test_episodes=episodes, seeds=1, test_seed_base=test_seed_base, final_evaluations=1)
    return _play(env_options, protocol.test_seeds, act, privileged, policy)


def _play(env_options: Mapping[str, Any], seeds: Sequence[int], act: Any, privileged: bool, label: str) -> list[dict[str, Any]]:
    from crowdnav.evaluation.evaluate import PolicyError
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    held_out = HeldOutEpisodes(env_options, seeds)
    try:
        return held_out.run(act, privileged=privileged, record=True)
    except (ValueError, TypeError) as error:  # an action of the wrong shape or type, from the user's policy
        raise PolicyError(f"{label}: {str(error).splitlines()[0]}") from None
    finally:
        held_out.close()


def replay_evaluation(run_dir: str | Path, evaluation: int | None = None, *, imports: Collection[str] = ()) -> list[dict[str, Any]]:
    """The test episodes of evaluation ``evaluation`` (default: the last) of a finished result, recorded.

    ``run_dir``: a folder with ``meta.json`` and ``test_episodes.csv``: a benchmark run
    ``<experiment>/<configuration>/seed_<n>`` (its policy snapshot for that evaluation is played),
    a scripted baseline ``<experiment>/baseline_<name>/baseline`` (the same at every evaluation),
    or a ``crowdnav evaluate`` result (its POLICY, as meta.json names it, loaded again: a file by
    the absolute path recorded). No code a results folder names is run: a ``module:function``
    POLICY is imported only if ``imports`` names it too (the command line's ``--import``), from
    the current folder or ``sys.path``, never from a folder meta.json records. Raises
    :class:`ReplayMismatchError` unless every episode's outcome matches the recorded one.
    """
    import pandas as pd
    from crowdnav.evaluation.protocol import Protocol
    from crowdnav.evaluation.storage import META_FILE, ResultsError, read_json

    run_dir = Path(run_dir)
    meta = read_json(run_dir / META_FILE) if (run_dir / META_FILE).is_file() else None
    if meta is None:
        raise ResultsError(f"{run_dir}: not a finished run (no meta.json)")
    protocol = Protocol(**meta["protocol"])
    recorded = pd.read_csv(run_dir / "test_episodes.csv", keep_default_na=False, na_values=["nan"])
    kind = meta.get("kind")
    if kind == "baseline":  # the same at every evaluation: ``evaluation`` changes nothing
        from crowdnav.evaluation.baselines import scripted_policy

        try:
            scripted = scripted_policy(meta["policy"])
        except KeyError:
            raise ResultsError(f"{run_dir}: its meta.json names no scripted baseline ({str(meta['policy'])[:60]!r})") from None
        rows = _play(meta["env"], protocol.test_seeds, scripted, True, meta["policy"])
        expected = recorded.drop_duplicates("test_episode").set_index("test_episode")["outcome"]
    elif kind == "evaluated":  # one evaluation only
        from crowdnav.evaluation.evaluate import PolicyError, is_code_policy, resolve_policy

        source = str(meta.get("policy_source", meta["policy"]))
        named = is_code_policy(source) and source in imports  # code runs only when the user names it again
        if is_code_policy(source) and not named:
            raise ResultsError(f"{run_dir}: it scored the module:function policy {source[:200]}, and crowdnav never imports code "
                               f"a results folder names; to replay it, pass --import {source[:200]} (imports=[...] in Python), "
                               "imported from the current folder or PYTHONPATH")
        try:
            _, _, act, privileged, env_options = resolve_policy(source, meta["env"], allow_import=named)
        except PolicyError as error:
            raise ResultsError(f"{run_dir}: cannot load the policy it scored ({error})") from None
        rows = _play(env_options, protocol.test_seeds, act, privileged, meta["policy"])
        expected = recorded.drop_duplicates("test_episode").set_index("test_episode")["outcome"]
    else:
        from crowdnav.agents import load_policy
        from crowdnav.agents.runs.folder import policy_snapshots

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
        rows = _play(policy.env_options, protocol.test_seeds, policy, False, str(folder))
        expected = this.set_index("test_episode")["outcome"]
    replayed = {row["test_episode"]: row["outcome"] for row in rows}
    differ = {k: (expected[k], replayed[k]) for k in expected.index if replayed.get(k) != expected[k]}
    if differ:
        raise ReplayMismatchError(f"{run_dir}: replayed outcomes differ from the recorded ones (episode: recorded, replayed): {differ}")
    return rows


def result_label(run_dir: str | Path, evaluation: int | None = None) -> str:
    """The file stem :func:`replay_evaluation`'s episodes are written under in ``RUN/trajectories/``.

    ``evaluation_K`` (K the evaluation, zero-padded to 3 digits, the last by default) for a
    benchmark run, ``baseline`` for a scripted baseline, ``evaluate`` for a ``crowdnav evaluate`` result.
    """
    from crowdnav.evaluation.protocol import Protocol
    from crowdnav.evaluation.storage import META_FILE, read_json

    meta = read_json(Path(run_dir) / META_FILE)
    if meta.get("kind") in ("baseline", "evaluated"):
        return "baseline" if meta["kind"] == "baseline" else "evaluate"
    k = Protocol(**meta["protocol"]).evaluations - 1 if evaluation is None else evaluation
    return f"evaluation_{k:03d}"


def finished_results(root: str | Path) -> list[Path]:
    """Every finished result under ``root`` (``root`` itself when it is one): folders whose meta.json is complete."""
    from crowdnav.evaluation.storage import META_FILE, TEST_FILE, ResultsError, is_set_aside, read_json

    root = Path(root)
    candidates = [root / META_FILE] if (root / META_FILE).is_file() else sorted(root.rglob(META_FILE))
    found = []
    for path in candidates:
        try:
            meta = read_json(path)
        except (ResultsError, OSError, ValueError):
            continue
        if is_set_aside(path.parent, root):  # a result being written or replaced (hidden), or one set aside
            continue
        if isinstance(meta, dict) and meta.get("status") == "complete" and "protocol" in meta and (path.parent / TEST_FILE).is_file():
            found.append(path.parent)
    return found
