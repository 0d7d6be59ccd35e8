"""Copy a finished experiment's report into docs/results/<experiment>/ with a README of its facts.

    python benchmarks/publish_results.py results/modalities [--docs docs/results] [--workers N]

Copies the curves (png, pdf), the leaderboard (md, csv) and the per-evaluation rates
(evaluation_rates.csv) that ``crowdnav benchmark`` wrote, and writes the README's facts block
(between ``<!-- FACTS -->`` markers, so the hand-written reading around it survives a re-run):
the command, the resolved setting, run count, wall time (the experiment's elapsed time when the
driver recorded it in ``<experiment>.done``, and the sum over runs) and the commits the runs ran
at. Refuses an experiment whose runs are not all finished, and one whose runs ran from a working tree
with uncommitted changes (a commit marked ``+dirty``: that code cannot be checked out again).
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import yaml

from crowdnav.files import atomic_write_text, replacing

FILES = ("curves.png", "curves.pdf", "leaderboard.md", "leaderboard.csv", "evaluation_rates.csv")
START, END = "<!-- FACTS -->", "<!-- /FACTS -->"
FIGURE4_EXPERIMENTS = ("modalities", "fusion", "paradigms", "modalities_paper", "encoders")
"""The experiments benchmarks/run_figure4.sh runs (its command is named beside theirs)."""


def facts(folder: Path, workers: int = 2) -> str:
    experiment = yaml.safe_load((folder / "experiment.yaml").read_text(encoding="utf-8"))
    protocol = experiment["protocol"]
    metas = [json.loads(path.read_text(encoding="utf-8")) for path in sorted(folder.glob("*/*/meta.json"))]
    learned = [m for m in metas if not str(m.get("configuration", "")).startswith("baseline_")]
    expected = len(experiment["configurations"]) * protocol["seeds"]
    if len(learned) < expected:
        raise SystemExit(f"{folder}: {len(learned)} of {expected} runs finished; publish when all are done")
    commits = sorted({c for m in learned for c in m.get("git_commits", [m.get("git_commit")]) if c})
    dirty = [c for c in commits if c.endswith("+dirty")]
    if dirty:
        raise SystemExit(f"{folder}: runs ran from uncommitted code ({', '.join(dirty)}); re-run from a clean commit to publish")
    done = folder.parent / f"{folder.name}.done"
    elapsed = f"{int(done.read_text()) / 60:.0f} min elapsed, " if done.exists() else ""
    total = sum(m["wall_time_s"] for m in learned)
    # the results folder's experiment.yaml holds each configuration resolved (defaults merged in)
    first = experiment["configurations"][0].get("train", {})
    defaults = experiment.get("defaults") or {key: first[key] for key in ("scenario", "overrides", "reward_weights") if key in first}
    lines = [
        "```bash", f"crowdnav benchmark {folder.name} --workers {workers} --no-video"
        + ("   # or benchmarks/run_figure4.sh" if folder.name in FIGURE4_EXPERIMENTS else ""), "```", "",
        f"* **Protocol:** {_budget(protocol)} on the same "
        f"{protocol['test_episodes']} held-out test episodes, {protocol['seeds']} seeds per configuration, sliding window "
        f"{protocol['window']}, final rates over the last {protocol['final_evaluations']} evaluations.",
        f"* **Setting:** scenario `{defaults.get('scenario')}`, overrides `{defaults.get('overrides', {})}`, reward "
        f"`{defaults.get('reward_weights', {}) or {'preset': 'default'}}`; configurations: "
        + ", ".join(f"`{c['name']}` ({c.get('label', c['name'])})" for c in experiment["configurations"]) + ".",
        f"* **Runs:** {len(learned)} ({elapsed}{total / 3600:.1f} h summed over runs, {_at_a_time(workers)} on the 2-core machine).",
        f"* **Code:** commit(s) {', '.join(commits)}.",
    ]
    return "\n".join(lines) + "\n"


def _budget(protocol: dict) -> str:
    """The training budget and evaluation interval, in the protocol's unit (episodes, or env steps)."""
    if "train_steps" in protocol:
        return f"{protocol['train_steps']:,} training env steps, evaluation every {protocol['eval_every_steps']:,}"
    return f"{protocol['train_episodes']} training episodes, evaluation every {protocol['eval_every']}"


def _at_a_time(workers: int) -> str:
    return "one at a time" if workers == 1 else f"{workers} at a time"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="RESULTS/<experiment> written by crowdnav benchmark")
    parser.add_argument("--docs", type=Path, default=Path("docs/results"))
    parser.add_argument("--workers", type=int, default=2, help="the --workers the benchmark ran with (the facts say it)")
    args = parser.parse_args()
    folder = args.folder.resolve()
    block = facts(folder, args.workers)
    target = args.docs / folder.name
    target.mkdir(parents=True, exist_ok=True)
    for name in FILES:
        with replacing(target / name) as temporary:  # a link in docs/results is replaced, never written through
            shutil.copy2(folder / name, temporary)
    readme = target / "README.md"
    text = readme.read_text(encoding="utf-8") if readme.exists() else f"# {folder.name}\n\n{START}\n{END}\n"
    if START not in text:
        text = f"{text.rstrip()}\n\n{START}\n{END}\n"
    head, _, rest = text.partition(START)
    _, _, tail = rest.partition(END)
    atomic_write_text(readme, f"{head}{START}\n{block}{END}{tail}")
    print(f"published {folder} -> {target}")


if __name__ == "__main__":
    main()
