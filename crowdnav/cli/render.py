"""``crowdnav render``: episodes of a policy written to video files."""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from crowdnav.cli.common import CliError, add_override_option, add_reward_options, parse_overrides, reward_options
from crowdnav.suggest import unknown_name_message

if TYPE_CHECKING:
    from crowdnav.envs import CrowdNavEnv


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        "render",
        help="render episodes of a policy to MP4 or GIF files",
        description="Run episodes of a policy in a scenario and write one video per episode (no display or system ffmpeg needed).",
    )
    parser.add_argument("scenario", help="library scenario name (see `crowdnav scenario list`) or path to a YAML file")
    parser.add_argument(
        "--policy",
        default="social-force",
        help="social-force, straight, random, orca, predictive, oracle, a crowdnav checkpoint or run folder, or any POLICY of `crowdnav evaluate`: "
             "baseline:NAME, module:function, an SB3 model .zip (default: social-force)",
    )
    parser.add_argument("--modalities", metavar="KEYS", help="observation keys a module:function or SB3 zip policy reads (default: the scenario's)")
    parser.add_argument("--episodes", type=int, default=3, help="number of episodes (default: 3)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first episode; the next ones use seed+1, ... (default: 0)")
    parser.add_argument("--out", default="videos", help="output folder (default: videos/)")
    parser.add_argument("--format", dest="video_format", choices=["mp4", "gif"], default="mp4", help="video format (default: mp4)")
    parser.add_argument("--human-goals", action="store_true", help="mark every human's goal")
    parser.add_argument("--hide", metavar="OVERLAYS", default="",
                        help="overlays to leave out, comma-separated: " + ", ".join(HIDEABLE) + " (default: draw them all)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.add_argument("--traceback", action="store_true", help="show the full traceback when a module:function policy raises")
    add_override_option(parser)
    add_reward_options(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from crowdnav.agents.runs.render import PolicyLoadError, render_policy
    from crowdnav.paths import OutputPathError
    from crowdnav.scenario import ScenarioError

    if args.episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {args.episodes}")
    if _foreign(args.policy):  # the forms crowdnav evaluate loads: the evaluation layer resolves them
        return _render_foreign(args)
    if args.modalities:  # a scripted name reads the simulator, a shared robot policy its own observations
        raise CliError(f"--modalities: {args.policy} reads {'its own observations' if Path(args.policy).exists() else 'the simulator'}, "
                       "not the observation keys named; leave --modalities out")
    try:
        paths = render_policy(
            args.scenario,
            args.policy,
            episodes=args.episodes,
            seed=args.seed,
            out=args.out,
            video_format=args.video_format,
            overrides=parse_overrides(args.overrides),
            reward_weights=reward_options(args),
            render_options=_render_options(args),
            progress=not args.no_progress,
        )
    except (ScenarioError, PolicyLoadError, OutputPathError) as error:
        raise CliError(str(error)) from None
    for path in paths:
        print(f"wrote {path}")
    return 0


HIDEABLE = ("lidar", "leog", "closest_obstacle", "tracks")
"""Overlays `--hide` can leave out (crowdnav.rendering.renderer.RenderOptions)."""


def _render_options(args: argparse.Namespace) -> dict[str, bool]:
    hidden = [name.strip() for name in args.hide.split(",") if name.strip()]
    unknown = [name for name in hidden if name not in HIDEABLE]
    if unknown:
        raise CliError("--hide: " + unknown_name_message("overlay", unknown[0], HIDEABLE))
    return {"human_goals": args.human_goals, **{name: False for name in hidden}}


def _foreign(policy: str) -> bool:
    return (policy.startswith("baseline:") or policy.endswith(".zip") or (":" in policy and not policy.startswith(("/", ".")))
            or _one_robot_run(policy))


def _one_robot_run(policy: str) -> bool:
    """A training run or checkpoint of one robot: played as `crowdnav evaluate` plays it (--set wins over its own settings)."""
    if not Path(policy).is_dir():
        return False
    from crowdnav.agents.marl.robots import ROBOTS_KIND
    from crowdnav.agents.runs.checkpoint import read_policy_info

    try:
        return bool(read_policy_info(policy).get("agents") != ROBOTS_KIND)
    except (OSError, ValueError):  # not a checkpoint: the agents' loader says so in one line
        return False


def _render_foreign(args: argparse.Namespace) -> int:
    import numpy as np

    from crowdnav.evaluation.evaluate import PolicyError, resolve_policy
    from crowdnav.paths import OutputPathError
    from crowdnav.rendering.episodes import render_episodes
    from crowdnav.scenario import ScenarioError

    options = {"scenario": args.scenario, "overrides": parse_overrides(args.overrides)}
    if args.modalities:
        options["modalities"] = [key.strip() for key in args.modalities.split(",") if key.strip()]
    try:
        name, _, act, privileged, env_options = resolve_policy(args.policy, options)
        memory: dict[str, Any] = {"state": None}  # a recurrent policy's state, carried through its episode
        predict = getattr(act, "predict", None) if getattr(act, "recurrent", False) else None

        def play(env: CrowdNavEnv, observation: Mapping[str, np.ndarray]) -> np.ndarray:  # one episode at a time: a batch of one
            try:
                if privileged:
                    action: np.ndarray = act(env.simulator)
                elif predict is not None:  # its state kept, forgotten where an episode begins
                    batch = {key: np.asarray(value)[None] for key, value in observation.items()}
                    actions, memory["state"] = predict(batch, memory["state"], np.array([env.simulator.step_count == 0]))
                    action = np.asarray(actions)[0]
                else:
                    action = np.asarray(act({key: np.asarray(value)[None] for key, value in observation.items()}))[0]
            except PolicyError:
                raise
            except (Exception, SystemExit) as error:  # the user's policy failed: one line, as `crowdnav evaluate` says it
                message = str(error).splitlines()[0] if str(error) else ""
                raise PolicyError(f"{args.policy} raised {type(error).__name__}{': ' + message if message else ''} while acting "
                                  "(--traceback shows where)") from error
            return action

        extra = {key: value for key, value in env_options.items() if key not in ("scenario", "overrides")}
        label = Path(args.policy).stem if _one_robot_run(args.policy) else name  # a run's videos keep their names
        paths = render_episodes(args.scenario, play, label=label, env_options=extra, episodes=args.episodes, seed=args.seed, out=args.out,
                                video_format=args.video_format, overrides=env_options.get("overrides"),
                                reward_weights=reward_options(args), render_options=_render_options(args),
                                progress=not args.no_progress)
    except (PolicyError, ScenarioError, OutputPathError, ValueError) as error:
        if args.traceback and error.__cause__ is not None:
            import traceback

            traceback.print_exception(error.__cause__)
        raise CliError(str(error).splitlines()[0]) from None
    for path in paths:
        print(f"wrote {path}")
    return 0
