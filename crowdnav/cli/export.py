"""``crowdnav export``: a trained policy as an ONNX file a robot runs with onnxruntime alone."""

from __future__ import annotations

import argparse
from pathlib import Path

from crowdnav.cli.common import CliError


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``export``."""
    parser = subparsers.add_parser(
        "export", help="write a trained policy as ONNX (raw observation dict in, deterministic action out)",
        description="POLICY: a crowdnav training run folder or checkpoint (a benchmark run folder works too). The ONNX "
                    "graph takes one input per observation key (the raw CrowdNavEnv observation, batch first) and "
                    "returns `action` (batch, 2), what the policy does deterministically; the observation scaling and a "
                    "frozen LEOG encoder are inside. Run it with numpy and onnxruntime only (docs/deploy.md).",
    )
    parser.add_argument("policy", metavar="POLICY")
    parser.add_argument("--out", default="policy.onnx", metavar="FILE", help="the ONNX file (default: %(default)s)")
    parser.add_argument("--force", action="store_true", help="replace FILE if it exists")
    parser.set_defaults(handler=export_command)


def export_command(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if out.suffix != ".onnx":
        raise CliError(f"--out {args.out}: expected a file name ending in .onnx")
    if out.exists() and not args.force:
        raise CliError(f"{out} exists; pass --force to replace it")
    policy = Path(args.policy)
    if not policy.exists():
        raise CliError(f"{args.policy}: no such run folder or checkpoint (export takes a crowdnav training run or checkpoint)")
    from crowdnav.agents.runs.folder import POLICY_FILE

    if policy.is_file() and policy.suffix == ".zip":
        if not (policy.parent / POLICY_FILE).is_file():  # `crowdnav evaluate` and `render` take it with --scenario / --modalities
            raise CliError(f"{args.policy} is an SB3 model .zip without crowdnav's {POLICY_FILE}: an exported graph needs the "
                           "scenario, sensor settings and observation scaling a crowdnav checkpoint records; export the crowdnav "
                           "run folder or checkpoint that holds it (docs/deploy.md)")
        policy = policy.parent  # a crowdnav checkpoint's own model.zip: its folder is the checkpoint
    from crowdnav.agents.runs.onnx_export import ExportError, export_onnx
    from crowdnav.errors import CrowdNavError

    try:
        path = export_onnx(policy, out)
    except (ExportError, CrowdNavError, ValueError) as error:  # a damaged checkpoint or its scenario: one line, as evaluate says it
        raise CliError(str(error).splitlines()[0]) from None
    print(f"wrote {path}")
    return 0
