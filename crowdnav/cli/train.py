"""``crowdnav train``, ``crowdnav collect-dataset``, ``crowdnav pretrain-encoder``: the agents' commands.

Each ``register_*`` adds one command to the ``crowdnav`` sub-parsers and sets its ``handler``
(``(args) -> int``); :func:`register` adds all three (``crowdnav.cli`` calls it). The agents
(torch, SB3) are imported inside the handlers, so ``crowdnav --help`` stays fast.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

from crowdnav.cli.common import CliError, add_override_option, add_reward_options, parse_overrides, reward_options
from crowdnav.registry import ALGORITHM_NAMES, ENCODER_MODES, algorithm_names

ALGOS = ALGORITHM_NAMES  # the registry's names (also the config's and the factory's)
MODES = tuple(ENCODER_MODES)


class _ConfigDefaultsFormatter(argparse.HelpFormatter):
    """Fills ``{field}`` in help texts with the TrainConfig default, imported only when help is printed."""

    def _expand_help(self, action: argparse.Action) -> str:
        text = super()._expand_help(action)
        if "{" not in text:
            return text
        from crowdnav.agents.training.config import TrainConfig, config_to_dict

        defaults = _flatten(config_to_dict(TrainConfig()))
        shown = {key: ",".join(map(str, value)) if isinstance(value, list) else value for key, value in defaults.items()}
        return re.sub(r"\{([a-z_.]+)\}", lambda match: str(shown[match.group(1)]), text)


def _flatten(document: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in document.items():
        if isinstance(value, dict) and value and key != "overrides":
            flat.update(_flatten(value, f"{prefix}{key}."))
        flat[f"{prefix}{key}"] = value
    return flat


def register(groups: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``train``, ``collect-dataset`` and ``pretrain-encoder``."""
    register_train(groups)
    register_collect_dataset(groups)
    register_pretrain_encoder(groups)


def register_train(groups: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = groups.add_parser(
        "train", help=f"train an RL agent ({', '.join(name.upper() for name in ALGOS)}) on a scenario",
        description="Train an agent from a YAML config; the flags override the config's fields. "
                    "Outputs (checkpoint, snapshots, episodes.csv) go to --out. Defaults shown are the config's.",
        formatter_class=_ConfigDefaultsFormatter,
    )
    # "{field}" in a help text is the config field's default, read only when help is printed
    parser.add_argument("--config", type=Path, metavar="CONFIG.yaml", help="training config (default: all defaults)")
    parser.add_argument("--scenario", metavar="NAME_OR_PATH", help="library scenario name or scenario YAML file (default: {scenario})")
    parser.add_argument("--algo", choices=algorithm_names(), help="RL algorithm (default: {algo})")
    parser.add_argument("--agents", choices=("robot", "robots"),
                        help="robot: the first robot learns; robots: every robot of a multi-robot scenario, one shared PPO policy "
                             "(default: {agents})")
    parser.add_argument("--modalities", metavar="KEYS", help="comma-separated observation keys, e.g. leog,lidar,goal (default: {modalities})")
    parser.add_argument("--encoder", choices=MODES, help="LEOG encoder mode (default: {encoder.mode})")
    parser.add_argument("--encoder-weights", metavar="PATH", help="pre-trained encoder (encoder.pt or its folder) (default: {encoder.weights})")
    parser.add_argument("--episodes", type=int, metavar="N", help="training episodes in all (default: {episodes})")
    parser.add_argument("--timesteps", type=int, metavar="N", help="training length in env steps over all worlds, instead of --episodes")
    parser.add_argument("--num-envs", type=int, metavar="N", help="worlds collected from at once; 1: one env (default: {num_envs})")
    parser.add_argument("--updates-per-step", type=float, metavar="R",
                        help="off-policy, batched: gradient steps per env step (default: per algorithm)")
    parser.add_argument("--seed", type=int, metavar="N", help="seed of the networks and the training episodes (default: {seed})")
    parser.add_argument("--out", metavar="DIR", help="output folder (default: {out})")
    parser.add_argument("--threads", type=int, metavar="N", help="torch threads (default: {torch_threads})")
    parser.add_argument("--device", metavar="DEVICE", help="torch device: cpu, cuda, auto (default: {device})")
    add_override_option(parser)  # --set PATH=VALUE: scenario overrides, merged into the config's own
    add_reward_options(parser)  # --reward PRESET, --reward-weight TERM=VALUE: into reward_weights
    parser.add_argument("--resume", action="store_true", help="continue the run in --out from its checkpoint")
    parser.add_argument("--tensorboard", action="store_true",
                        help="write TensorBoard logs to OUT/tensorboard (pip install -e \".[tensorboard]\" in crowdnav's clone)")
    parser.add_argument("--trust-pickle", action="store_true",
                        help="with --resume: accept a checkpoint of an older crowdnav, whose pickled state can run code "
                             "(only for runs you trust; docs/security.md)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--print-config", action="store_true", help="print the resolved config (YAML) and exit")
    parser.add_argument("--list-options", action="store_true", help="list every config field with its default and meaning, and exit")
    parser.set_defaults(handler=train_command)


def register_collect_dataset(groups: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = groups.add_parser(
        "collect-dataset", help="record occupancy grids of a randomly wandering robot into a .npz dataset",
        description="Let the robot wander with a random policy and save its LEOG observations "
                    "(uint8 array 'grids' of shape (N, 1, H, W) plus JSON metadata) for encoder pre-training.",
    )
    parser.add_argument("--scenario", default="room_furniture", metavar="NAME_OR_PATH", help="scenario (default: room_furniture)")
    parser.add_argument("--grids", type=int, default=5_000, metavar="N", help="number of grids (default: 5000)")
    parser.add_argument("--every", type=int, default=2, metavar="K", help="keep every K-th step's grid (default: 2)")
    parser.add_argument("--seed", type=int, default=0, metavar="N", help="seed (default: 0)")
    parser.add_argument("--out", required=True, type=Path, metavar="FILE.npz", help="dataset file to write")
    parser.set_defaults(handler=collect_dataset_command)


def register_pretrain_encoder(groups: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = groups.add_parser(
        "pretrain-encoder", help="pre-train the LEOG encoder as a convolutional autoencoder",
        description="Train an autoencoder on occupancy grids, from a dataset file or collected online "
                    "from a scenario, and save encoder.pt, encoder.json and loss.png in --out.",
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--dataset", type=Path, metavar="FILE.npz", help="dataset from collect-dataset (or another simulator)")
    source.add_argument("--scenario", metavar="NAME_OR_PATH", help="collect grids online from this scenario (default: room_furniture)")
    parser.add_argument("--grids", type=int, default=5_000, metavar="N", help="grids to collect online (default: 5000)")
    parser.add_argument("--epochs", type=int, default=30, metavar="N", help="training epochs (default: 30)")
    parser.add_argument("--batch-size", type=int, default=32, metavar="N", help="minibatch size (default: 32)")
    parser.add_argument("--lr", type=float, default=3e-3, metavar="LR", help="Adam learning rate (default: 3e-3)")
    parser.add_argument("--latent", type=int, default=64, metavar="N", help="latent size (default: 64, as the agents' default)")
    parser.add_argument("--val-fraction", type=float, default=0.1, metavar="F", help="held-out fraction (default: 0.1)")
    parser.add_argument("--seed", type=int, default=0, metavar="N", help="seed (default: 0)")
    parser.add_argument("--threads", type=int, default=1, metavar="N", help="torch threads (default: 1)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder")
    parser.set_defaults(handler=pretrain_encoder_command)


# ----------------------------------------------------------------------------- handlers


def train_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The flags given on the command line, as dotted config overrides."""
    overrides: dict[str, Any] = {}
    simple = {"scenario": "scenario", "algo": "algo", "agents": "agents", "episodes": "episodes", "seed": "seed", "out": "out",
              "timesteps": "timesteps", "num_envs": "num_envs", "updates_per_step": "updates_per_step",
              "threads": "torch_threads", "device": "device", "encoder": "encoder.mode", "encoder_weights": "encoder.weights"}
    for flag, field in simple.items():
        value = getattr(args, flag)
        if value is not None:
            overrides[field] = value
    if args.modalities is not None:
        overrides["modalities"] = [key.strip() for key in args.modalities.split(",") if key.strip()]
    if args.no_progress:
        overrides["progress"] = False
    if args.tensorboard:
        overrides["tensorboard"] = True
    for term, weight in reward_options(args).items():  # merged into the config file's reward_weights
        overrides[f"reward_weights.{term}"] = weight
    return overrides


def train_command(args: argparse.Namespace) -> int:
    from crowdnav.agents.training.config import ConfigError, describe_fields, load_config

    if args.list_options:
        for name, default, doc in describe_fields():
            print(f"{name} (default {default}): {doc}")
        return 0
    try:
        config = load_config(args.config, train_overrides(args))
        scenario_overrides = parse_overrides(args.overrides)
        if scenario_overrides:  # --set adds to the config's own scenario overrides
            config = load_config(args.config, {**train_overrides(args), "overrides": {**config.overrides, **scenario_overrides}})
    except ConfigError as error:
        raise CliError(str(error)) from None
    if args.print_config:
        import yaml

        from crowdnav.agents.training.config import config_to_dict

        sys.stdout.write(yaml.safe_dump(config_to_dict(config), sort_keys=False))
        return 0
    from crowdnav.agents.training.run import describe_run, train
    from crowdnav.cli.signals import interrupt_on_sigterm
    from crowdnav.scenario import ScenarioError

    with interrupt_on_sigterm() as stopped:  # SIGTERM (kill, timeout, preemption) stops the run as Ctrl-C does
        try:
            result = train(config, resume=args.resume, trust_pickle=args.trust_pickle)
        except (ConfigError, ScenarioError, FileNotFoundError) as error:
            raise CliError(str(error)) from None
        except KeyboardInterrupt:
            print(f"crowdnav: interrupted; {_how_to_continue(Path(config.out))}", file=sys.stderr)
            return stopped.exit_status
    print(describe_run(result))
    return 0


def _how_to_continue(out: Path) -> str:
    """What the user runs after a stopped training: resume from the checkpoint a kill keeps, or start again."""
    from crowdnav.agents.runs.folder import checkpoint_dir
    from crowdnav.files import whole_copies

    current = checkpoint_dir(out)
    if current.is_dir() or whole_copies(current):  # a kill inside the checkpoint's swap keeps a whole copy beside it
        return f"the last checkpoint in {out} is kept: add --resume to the same command to continue from it"
    return f"{out} has no checkpoint yet: run the same command again to start over"


def collect_dataset_command(args: argparse.Namespace) -> int:
    from crowdnav.agents.networks.dataset import collect_grids, save_dataset
    from crowdnav.scenario import ScenarioError

    try:
        dataset = collect_grids(args.scenario, args.grids, seed=args.seed, every=args.every)
    except (ScenarioError, ValueError) as error:
        raise CliError(str(error)) from None
    path = save_dataset(dataset, args.out)
    print(f"wrote {len(dataset)} grids of shape {dataset.grid_shape} to {path}")
    return 0


def pretrain_encoder_command(args: argparse.Namespace) -> int:
    import torch

    from crowdnav.agents.networks.dataset import collect_grids, load_dataset
    from crowdnav.agents.networks.pretrain import pretrain_encoder
    from crowdnav.scenario import ScenarioError

    torch.set_num_threads(args.threads)
    try:
        if args.dataset is not None:
            dataset = load_dataset(args.dataset)
        else:
            dataset = collect_grids(args.scenario or "room_furniture", args.grids, seed=args.seed)
        result = pretrain_encoder(
            dataset, args.out, latent=args.latent, epochs=args.epochs, batch_size=args.batch_size,
            learning_rate=args.lr, val_fraction=args.val_fraction, seed=args.seed, progress=True,
        )
    except (ScenarioError, ValueError) as error:
        raise CliError(str(error)) from None
    print(f"held-out loss {result.initial_val_loss:.4f} -> {result.final_val_loss:.4f} "
          f"({result.initial_val_loss / result.final_val_loss:.1f}x lower) in {result.seconds:.1f} s; wrote {result.encoder_path}")
    return 0
