"""``crowdnav render``: episodes of a policy written to video files."""

from __future__ import annotations

import argparse

from crowdnav.cli.common import CliError, add_override_option, add_reward_options, parse_overrides, reward_options


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "render",
        help="render episodes of a policy to MP4 or GIF files",
        description="Run episodes of a policy in a scenario and write one video per episode (no display or system ffmpeg needed).",
    )
    parser.add_argument("scenario", help="library scenario name (see `crowdnav scenario list`) or path to a YAML file")
    parser.add_argument(
        "--policy",
        default="social-force",
        help="social-force, straight, random, or the path to a trained checkpoint (default: social-force)",
    )
    parser.add_argument("--episodes", type=int, default=3, help="number of episodes (default: 3)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first episode; the next ones use seed+1, ... (default: 0)")
    parser.add_argument("--out", default="videos", help="output folder (default: videos/)")
    parser.add_argument("--format", dest="video_format", choices=["mp4", "gif"], default="mp4", help="video format (default: mp4)")
    parser.add_argument("--human-goals", action="store_true", help="mark every human's goal")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_override_option(parser)
    add_reward_options(parser)
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from crowdnav.agents.render import PolicyLoadError, render_policy
    from crowdnav.paths import OutputPathError
    from crowdnav.scenario import ScenarioError

    if args.episodes < 1:
        raise CliError(f"--episodes must be at least 1, got {args.episodes}")
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
            render_options={"human_goals": args.human_goals},
            progress=not args.no_progress,
        )
    except (ScenarioError, PolicyLoadError, OutputPathError) as error:
        raise CliError(str(error)) from None
    for path in paths:
        print(f"wrote {path}")
    return 0
