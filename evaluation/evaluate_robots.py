"""``crowdnav evaluate`` of a shared robot policy (``crowdnav train --agents robots``): one network for every robot.

:func:`crowdnav.evaluation.evaluate.evaluate_policy` plays it here: :func:`resolve_robots_policy` loads it with its own
settings and the user's scenario, ``--set`` or track on top, refusing in one line a world whose robots or robot inputs
are not the ones its network was trained on; :func:`play_robots` plays one row per robot per test episode
(:class:`crowdnav.evaluation.robot_rollout.RobotEpisodes`), the rows an experiment writes for it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.evaluation.played_options import run_env_options
from crowdnav.evaluation.result_table import episode_csv
from crowdnav.evaluation.robot_rollout import ROBOTS_AGENTS

from crowdnav.errors import CrowdNavError


class RobotsPolicyError(CrowdNavError, ValueError):
    """A shared robot policy that cannot be loaded, or cannot play the world asked for; one line naming the option."""


def play_robots(policy: Any, env_options: Mapping[str, Any], seeds: Sequence[int], leading: Mapping[str, Any],
                 on_end: Callable[[], None] | None) -> tuple[str, int, list[str]]:
    """(CSV text, robot steps, outcomes) of a shared robot policy on one episode per seed: one row per robot per episode.

    The steps are the rows' sum, robot steps, as an experiment and its baselines count a shared robot policy's test steps.
    """
    from crowdnav.evaluation.robot_rollout import RobotEpisodes

    episodes = RobotEpisodes(env_options, seeds)
    try:
        rows = episodes.run(policy, on_end=on_end)
    finally:
        episodes.close()
    return episode_csv([{**leading, **row} for row in rows]), sum(int(row["steps"]) for row in rows), [str(row["outcome"]) for row in rows]


def is_shared_robots_policy(spec: str) -> bool:
    """Whether POLICY names a shared robot policy's run, checkpoint or model.zip (``crowdnav train --agents robots``)."""
    path = Path(spec)
    if spec.startswith("baseline:") or not path.exists():
        return False
    from crowdnav.agents.runs.checkpoint import find_checkpoint, read_policy_info
    from crowdnav.agents.runs.folder import training_run

    try:
        folder = find_checkpoint(path.parent if path.suffix == ".zip" and path.is_file() else training_run(path))
        return bool(read_policy_info(folder).get("agents") == ROBOTS_AGENTS)
    except (OSError, ValueError):  # not a checkpoint: resolve_policy says what it is in one line
        return False


def resolve_robots_policy(spec: str, requested: Mapping[str, Any], track: Any = None) -> tuple[Path, Any, dict[str, Any]]:
    """(run folder, :class:`crowdnav.agents.marl.robots.RobotsPolicy`, env options played) of a shared robot policy.

    Its own settings with the user's scenario and ``--set`` on top (the track's with ``track``, as for a one-robot
    run); refused in one line, naming the option, where the played world has other robots or gives its network
    other inputs (keys, sizes or scales) than it was trained on: the network has one input row per robot it knows.
    """
    from crowdnav.agents.marl.robots import load_robots_policy
    from crowdnav.agents.runs.folder import training_run

    path = Path(spec)
    path = path.parent if path.suffix == ".zip" and path.is_file() else training_run(path)
    try:
        policy = load_robots_policy(path)
    except (OSError, ValueError) as error:  # a damaged checkpoint: its one line (it names the file)
        line = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise RobotsPolicyError(f"cannot load shared robot policy {spec}: {line}") from None
    played = run_env_options(spec, policy.env_options, requested)  # OptionRefusedError: evaluate's one line
    named = "--set"
    if track is not None:
        played["overrides"], named = dict(track.env_options()["overrides"]), f"--track {track.name}"
    elif played["scenario"] != policy.env_options["scenario"]:
        named = f"--scenario {played['scenario']}"
    elif requested.get("overrides"):  # a sensor setting when one is given: the likeliest to change what the network reads
        given = list(requested["overrides"])
        named = f"--set {', '.join([key for key in given if key.split('.')[0] == 'sensors'] or given)}"
    _check_robots_world(spec, policy, played, named)
    return path, policy, played


def _check_robots_world(spec: str, policy: Any, played: Mapping[str, Any], named: str) -> None:
    """Refuse (one RobotsPolicyError line naming the option) a world whose robots or robot inputs are not the policy's own;
    the played world's robot kinematics turn its commands (``robot_actions``), as they would in training."""
    from crowdnav.agents.marl.actions import RobotActions
    from crowdnav.agents.marl.env import RobotObservations, RobotsConfigError, robots_env
    from crowdnav.agents.sb3.model_zip import describe_shapes
    from gymnasium import spaces

    from crowdnav.scenario import load_scenario

    trained = policy.env_options["scenario"]
    robots = list(load_scenario(played["scenario"], dict(played.get("overrides") or {})).robot_names)
    if robots != policy.robots:
        raise RobotsPolicyError(f"{named}: {spec} drives the robots of {trained!r} ({', '.join(policy.robots)}), not those of "
                          f"{played['scenario']!r} ({', '.join(robots)})")
    env = robots_env(played)
    try:
        config = policy.info["config"]
        try:
            inputs = RobotObservations(env, normalize=bool(config.get("normalize_observations", True)),
                                       identity=bool(policy.info["robots"]["identity"]))
        except RobotsConfigError as error:  # these settings give its robots different observations
            raise RobotsPolicyError(f"{named}: {spec}: {error}") from None
        stored = policy.info["robots"]
        if not inputs.matches(stored):
            space = env.core.robot_spaces[0]
            now = describe_shapes({key: tuple(part.shape or ()) for key, part in space.spaces.items()})
            if len(inputs.offset) != len(stored["offset"]):
                raise RobotsPolicyError(f"{named}: {spec} was trained on {len(stored['offset'])} observation values per robot, these settings "
                                  f"give {len(inputs.offset)} ({now}); its network takes only what it was trained on")
            scaled, start = [], 0
            for key, part in space.spaces.items():  # the keys whose stored offsets or scales these settings change
                end = start + int(spaces.flatdim(part))
                if any(not np.array_equal(np.asarray(stored[field][start:end], np.float32), getattr(inputs, field)[start:end])
                       for field in ("offset", "scale")):
                    scaled.append(key)
                start = end
            raise RobotsPolicyError(f"{named}: {spec} was trained on {', '.join(scaled) or 'observations'} scaled otherwise than these "
                              f"settings give ({now}); its network reads only what it was trained on")
        mode = str(config.get("robot_actions", "native"))
        if mode != "native":
            policy.commands = RobotActions.for_env(mode, env)
    finally:
        env.close()


def robot_keys(env_options: Mapping[str, Any]) -> list[str]:
    """The observation keys each robot of ``env_options`` reads (the shared network's, robot by robot)."""
    from crowdnav.agents.marl.env import robots_env

    env = robots_env(env_options)
    try:
        return list(env.core.robot_spaces[0].spaces)
    finally:
        env.close()


def observation_space(env_options: Mapping[str, Any]) -> Any:
    """The Gymnasium env's observation space in ``env_options`` (the first robot's Dict)."""
    from crowdnav.envs import CrowdNavEnv

    env = CrowdNavEnv(**env_options)
    try:
        return env.observation_space
    finally:
        env.close()
