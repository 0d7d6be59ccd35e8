"""Reuse finished runs of one experiment in another where the two define the very same run.

    python benchmarks/reuse_identical_runs.py RESULTS/modalities fusion [--dry-run]

Runs are deterministic: the same training config, seed, protocol, code and pre-trained encoder
give the same run to the last bit (checked on this machine: the fusion experiment's own seed-0
LEOG and LIDAR runs reproduced the modalities experiment's seed-0 runs, every training episode
and every test outcome). Figure 4's experiments share configurations (LEOG and LIDAR in (b) and
(c); SAC on frozen LEOG in (b), (a) and (d)), so a run finished in one need not be trained again
in another. For each run of the target experiment that is not finished, this copies the source
run whose spec is equal apart from the names (experiment, configuration, label), relabels it,
and records ``reused_from`` in its meta.json. It refuses unless the two experiments' pre-trained
encoders are byte-identical (it copies the source's when the target has none yet) and both
experiments use the same protocol. Run it with the code the runs used (its venv), while the
target experiment is not running.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import shutil
from pathlib import Path

from crowdnav.evaluation.experiment import load_experiment

from crowdnav.files import atomic_write_text

NAMES = ("experiment", "configuration", "label")


def _essence(spec: dict) -> str:
    return json.dumps({key: value for key, value in spec.items() if key not in NAMES}, sort_keys=True)


def _relabel_csv(path: Path, old: tuple[str, str, str], new: tuple[str, str, str]) -> None:
    import pandas as pd

    frame = pd.read_csv(path, keep_default_na=False, na_values=["nan"])
    for column, value in zip(NAMES, new, strict=True):
        if column in frame.columns:
            frame[column] = value
    atomic_write_text(path, frame.to_csv(index=False, lineterminator="\n", na_rep="nan"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", type=Path, help="RESULTS/<experiment> holding finished runs")
    parser.add_argument("target", help="the experiment to fill (name or file), under the same RESULTS folder")
    parser.add_argument("--dry-run", action="store_true")
    args = parser.parse_args()
    source = args.source.resolve()
    experiment = load_experiment(args.target)
    target = source.parent / experiment.name
    finished = {}
    for meta_path in sorted(source.glob("*/seed_*/meta.json")):
        spec = json.loads((meta_path.parent / "spec.json").read_text())
        finished[(_essence(spec), spec["seed"])] = meta_path.parent
    encoder_src, encoder_dst = source / "encoder" / "encoder.pt", target / "encoder" / "encoder.pt"
    for spec, folder in experiment.units(target):
        document = spec.to_dict()
        match = finished.get((_essence(document), document["seed"]))
        if match is None or (folder / "meta.json").is_file():
            continue
        if encoder_dst.is_file() and not filecmp.cmp(encoder_src, encoder_dst, shallow=False):
            raise SystemExit(f"{encoder_dst} differs from {encoder_src}: the runs would not be identical")
        print(f"{'would reuse' if args.dry_run else 'reusing'} {match} as {folder}")
        if args.dry_run:
            continue
        if not encoder_dst.is_file():
            shutil.copytree(encoder_src.parent, encoder_dst.parent, dirs_exist_ok=True)
        if folder.exists():
            shutil.rmtree(folder)  # an unfinished run of the same spec: the copy is what it would become
        shutil.copytree(match, folder)
        old_spec = json.loads((match / "spec.json").read_text())
        old, new = tuple(old_spec[key] for key in NAMES), (document["experiment"], document["configuration"], document["label"])
        atomic_write_text(folder / "spec.json", json.dumps(document, indent=2, sort_keys=True) + "\n")
        meta = json.loads((match / "meta.json").read_text().replace(str(match.parent.parent), str(target)))
        meta.update(dict(zip(NAMES, new, strict=True)), reused_from=str(match))
        atomic_write_text(folder / "meta.json", json.dumps(meta, indent=2, sort_keys=True) + "\n")
        for csv in [folder / "test_episodes.csv", folder / "training_episodes.csv", *sorted((folder / "evaluations").glob("*.csv"))]:
            if csv.is_file():
                _relabel_csv(csv, old, new)


if __name__ == "__main__":
    main()
