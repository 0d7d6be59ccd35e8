"""The paper's Figure-4 claims, judged on crowdnav's runs: writes docs/results/README.md.

Reads ``docs/results/<experiment>/evaluation_rates.csv`` (or ``docs/results/archive/<experiment>/``, marked archived;
one row per run and evaluation: the success / collision / out_of_bounds / truncated rates over the 20 held-out test episodes) for the
experiments encoders, modalities, fusion, paradigms and modalities_paper, and judges every claim
of the paper by a rule fixed in this file before the runs were read (``CLAIMS``). Missing
experiments are listed as "not run yet". ``modalities_steps`` and ``paradigms_steps`` (Figure 4(b)
and 4(d) under an env-step budget, batched training) are judged by the same rules, with x in
training env steps and every span the same fraction of the budget (early = 50-300 of 700 is
1/14-3/7 of the budget; the budget is the last evaluation's x).

    python benchmarks/figure4_claims.py [--results docs/results] [--out docs/results/README.md]

Statistics (all over the 5 runs of a configuration; the scripted baselines are reference lines):

* final success: per run, the mean success of the last 3 evaluations (60 test episodes);
* early success: per run, the mean success of the evaluations after 50..300 training episodes;
* std: the across-seed standard deviation (ddof 1) of the success rate at each evaluation,
  averaged over the evaluations of the span named;
* 95% CI: percentile bootstrap over runs (10,000 resamples of the 5 runs, seeded);
* "X is better than Y": a higher mean and P(X > Y) > 0.5;
* P(X > Y): probability of improvement (Agarwal et al. 2021, the rliable statistic) between two
  configurations' per-run scores, P = mean over run pairs of [x > y] + 0.5 [x = y], with a
  bootstrap 95% CI resampling the runs of both.
"""

from __future__ import annotations

import argparse
import csv
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from crowdnav.files import atomic_write_text

EXPERIMENTS = ("encoders", "modalities", "fusion", "paradigms", "modalities_paper", "modalities_steps", "paradigms_steps")
FINAL_EVALUATIONS = 3
PAPER_BUDGET = 700  # training episodes of the paper's protocol; the spans below are stated in them
EARLY = (50, 300)  # training episodes of 700; an env-step experiment uses the same fractions of its budget
RESAMPLES = 10_000
EXCELLENT = 0.8  # final success that counts as "excellent performance"
SIMILAR = 0.15  # final success within this many points counts as "similar performance"
SPIKE = 0.25  # a run's truncated rate at one evaluation at or above this is a truncation spike


CLAIM_TEXTS = {
    "encoders": [
        '(a) all three strategies reach excellent performance',
        '(a) from scratch has the largest std during training',
        '(a) pre-trained frozen is best early',
    ],
    "modalities": [
        '(b) all inputs converge to similar performance',
        '(b) LIDAR and closest obstacle are better early (than LEOG)',
        '(b) LEOG ends with the smallest std',
    ],
    "fusion": [
        '(c) fusion is better than either input in the first half of training',
        '(c) fusion has the smallest std',
        '(c) fusion has no sporadic truncation spikes',
    ],
    "paradigms": [
        '(d) SAC is the best paradigm',
        '(d) SAC has few truncations from early on',
        '(d) TD3 is noisy',
        "(d) DDPG and A2C drift towards truncation; A2C's truncation rate goes to 1",
    ],
}
CLAIM_TEXTS["modalities_paper"] = CLAIM_TEXTS["modalities_steps"] = CLAIM_TEXTS["modalities"]
CLAIM_TEXTS["paradigms_steps"] = CLAIM_TEXTS["paradigms"]
"""The paper's claims per experiment (Figure 4 and its discussion), in the order they are judged."""


@dataclass
class Runs:
    """One configuration's rates: arrays of shape (runs, evaluations)."""

    episodes: np.ndarray
    rates: dict[str, np.ndarray]
    budget: int = PAPER_BUDGET
    """The last evaluation's x (700 episodes, or the env-step budget): spans scale with it."""

    def scaled(self, low: int, high: int) -> tuple[float, float]:
        """A span stated in episodes of the paper's 700, as the same fraction of this budget."""
        return low * self.budget / PAPER_BUDGET, high * self.budget / PAPER_BUDGET

    def final(self, outcome: str = "success") -> np.ndarray:
        return self.rates[outcome][:, -FINAL_EVALUATIONS:].mean(axis=1)

    def span(self, low: int, high: int, outcome: str = "success") -> np.ndarray:
        low, high = self.scaled(low, high)
        keep = (self.episodes >= low) & (self.episodes <= high)
        return self.rates[outcome][:, keep].mean(axis=1)

    def std(self, low: int = 0, high: int = 10**9, outcome: str = "success") -> float:
        low, high = self.scaled(low, high)
        keep = (self.episodes >= low) & (self.episodes <= high)
        values = self.rates[outcome][:, keep]
        return float(values.std(axis=0, ddof=1).mean()) if len(values) > 1 else 0.0

    def spikes(self) -> int:
        """(run, evaluation) pairs with a truncated rate >= SPIKE, after the first evaluation."""
        return int((self.rates["truncated"][:, 1:] >= SPIKE).sum())


def load(path: Path) -> dict[str, Runs]:
    """Per configuration, the rates of every seed at each evaluation, aligned by evaluation index.

    An on-policy run can be evaluated a few episodes after the scheduled point (its snapshot
    came at a rollout's end, as crowdnav did before snapshots were taken when the episode ends);
    the evaluation index, not the exact episode count, says which point it is. The x of each
    point is its earliest episode count over seeds (the scheduled one).
    """
    rows: dict[str, dict[int, dict[int, dict[str, float]]]] = defaultdict(lambda: defaultdict(dict))
    points: dict[str, dict[int, int]] = defaultdict(dict)
    with open(path, newline="", encoding="utf-8") as handle:
        for row in csv.DictReader(handle):
            if row["configuration"].startswith("baseline_"):
                continue
            k, name = int(row["evaluation"]), row["configuration"]
            rows[name][int(row["seed"])][k] = {key: float(row.get(key) or 0.0) for key in ("success", "collision", "out_of_bounds", "truncated")}
            x = int(row["training_steps"]) if row.get("training_steps") else int(row["training_episodes"])
            points[name][k] = min(points[name].get(k, 10**15), x)
    out = {}
    for name, seeds in rows.items():
        evaluations = sorted(points[name])
        complete = [s for s in sorted(seeds) if sorted(seeds[s]) == evaluations]
        xs = np.array([points[name][k] for k in evaluations])
        out[name] = Runs(xs,
                         {key: np.array([[seeds[s][k][key] for k in evaluations] for s in complete])
                          for key in ("success", "collision", "out_of_bounds", "truncated")},
                         budget=int(xs[-1]))
    return out


def ci(values: np.ndarray, seed: int = 0) -> tuple[float, float]:
    rng = np.random.default_rng(seed)
    means = values[rng.integers(0, len(values), (RESAMPLES, len(values)))].mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def improvement(x: np.ndarray, y: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    """P(X > Y) over run pairs, with a bootstrap 95% CI."""
    def p(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        diff = a[..., :, None] - b[..., None, :]
        return ((diff > 0) + 0.5 * (diff == 0)).mean(axis=(-2, -1))
    rng = np.random.default_rng(seed)
    xs = x[rng.integers(0, len(x), (RESAMPLES, len(x)))]
    ys = y[rng.integers(0, len(y), (RESAMPLES, len(y)))]
    low, high = np.percentile(p(xs, ys), [2.5, 97.5])
    return float(p(x, y)), float(low), float(high)


def span_text(r: dict[str, Runs], span: tuple[int, int]) -> str:
    """``evaluations 50-300`` (episodes of 700), or the same fraction in env steps (``evaluations at 142,857-857,143 env steps``)."""
    runs = next(iter(r.values()))
    if runs.budget == PAPER_BUDGET:
        return f"evaluations {span[0]}-{span[1]}"
    low, high = runs.scaled(*span)
    return f"evaluations at {low:,.0f}-{high:,.0f} env steps"


def pct(value: float) -> str:
    return f"{100 * value:.0f}%"


def score(runs: Runs, values: np.ndarray) -> str:
    low, high = ci(values)
    return f"{pct(values.mean())} [{pct(low)}, {pct(high)}]"


def pi(a: str, b: str, x: np.ndarray, y: np.ndarray) -> str:
    value, low, high = improvement(x, y)
    return f"P({a} > {b}) = {value:.2f} [{low:.2f}, {high:.2f}]"


Verdict = tuple[str, str]  # (verdict, numbers)


def beats(x: np.ndarray, y: np.ndarray) -> bool:
    """X is better than Y: a higher mean and a probability of improvement above one half."""
    return bool(x.mean() > y.mean() and improvement(x, y)[0] > 0.5)


def _grade(hits: int, total: int) -> str:
    return "reproduced" if hits == total else "partly" if hits else "not reproduced"


def encoders(r: dict[str, Runs]) -> list[tuple[str, Verdict]]:
    finals = {k: v.final() for k, v in r.items()}
    excellent = sum(v.mean() >= EXCELLENT for v in finals.values())
    stds = {k: v.std() for k, v in r.items()}
    early = {k: v.span(*EARLY) for k, v in r.items()}
    early_best = max(early, key=lambda k: early[k].mean()) == "frozen"
    p_t, p_s = improvement(early["frozen"], early["finetune"])[0], improvement(early["frozen"], early["scratch"])[0]
    return [
        (CLAIM_TEXTS["encoders"][0],
         (_grade(excellent, 3), "final success " + ", ".join(f"{k} {score(v, finals[k])}" for k, v in r.items())
          + f"; 'excellent' = mean >= {pct(EXCELLENT)}")),
        (CLAIM_TEXTS["encoders"][1],
         ("reproduced" if max(stds, key=stds.get) == "scratch" else "not reproduced",
          "std of success over evaluations " + ", ".join(f"{k} {v:.3f}" for k, v in stds.items()))),
        (CLAIM_TEXTS["encoders"][2],
         ("reproduced" if early_best and min(p_t, p_s) > 0.5 else "partly" if early_best or max(p_t, p_s) > 0.5 else "not reproduced",
          f"success over {span_text(r, EARLY)}: " + ", ".join(f"{k} {score(v, early[k])}" for k, v in r.items())
          + "; " + pi("frozen", "finetune", early["frozen"], early["finetune"])
          + "; " + pi("frozen", "scratch", early["frozen"], early["scratch"]))),
    ]


def modalities(r: dict[str, Runs]) -> list[tuple[str, Verdict]]:
    finals = {k: v.final() for k, v in r.items()}
    means = [v.mean() for v in finals.values()]
    gap = max(means) - min(means)
    early = {k: v.span(*EARLY) for k, v in r.items()}
    better = sum(beats(early[k], early["leog"]) for k in ("lidar", "closest_obstacle"))
    final_std = {k: float(v.std(ddof=1)) for k, v in finals.items()}
    return [
        (CLAIM_TEXTS["modalities"][0],
         ("reproduced" if gap <= SIMILAR else "partly" if gap <= 2 * SIMILAR else "not reproduced",
          "final success " + ", ".join(f"{k} {score(v, finals[k])}" for k, v in r.items())
          + f"; spread {pct(gap)} ('similar' = within {pct(SIMILAR)})")),
        (CLAIM_TEXTS["modalities"][1],
         (_grade(better, 2), f"success over {span_text(r, EARLY)}: " + ", ".join(f"{k} {score(v, early[k])}" for k, v in r.items())
          + "; " + pi("lidar", "leog", early["lidar"], early["leog"])
          + "; " + pi("closest_obstacle", "leog", early["closest_obstacle"], early["leog"]))),
        (CLAIM_TEXTS["modalities"][2],
         ("reproduced" if min(final_std, key=final_std.get) == "leog" else "not reproduced",
          "across-seed std of final success " + ", ".join(f"{k} {v:.3f}" for k, v in final_std.items()))),
    ]


def fusion(r: dict[str, Runs]) -> list[tuple[str, Verdict]]:
    half = (50, 350)
    first = {k: v.span(*half) for k, v in r.items()}
    better = sum(beats(first["leog_lidar"], first[k]) for k in ("leog", "lidar"))
    stds = {k: v.std() for k, v in r.items()}
    spikes = {k: v.spikes() for k, v in r.items()}
    calm = spikes["leog_lidar"] == 0 or spikes["leog_lidar"] < min(spikes["leog"], spikes["lidar"])
    return [
        (CLAIM_TEXTS["fusion"][0],
         (_grade(better, 2), f"success over {span_text(r, half)}: " + ", ".join(f"{k} {score(v, first[k])}" for k, v in r.items())
          + "; " + pi("leog_lidar", "leog", first["leog_lidar"], first["leog"])
          + "; " + pi("leog_lidar", "lidar", first["leog_lidar"], first["lidar"]))),
        (CLAIM_TEXTS["fusion"][1],
         ("reproduced" if min(stds, key=stds.get) == "leog_lidar" else "not reproduced",
          "std of success over evaluations " + ", ".join(f"{k} {v:.3f}" for k, v in stds.items()))),
        (CLAIM_TEXTS["fusion"][2],
         ("reproduced" if spikes["leog_lidar"] == 0 else "partly" if calm else "not reproduced",
          f"(run, evaluation) pairs with truncated >= {pct(SPIKE)} after the first evaluation: "
          + ", ".join(f"{k} {v}" for k, v in spikes.items()))),
    ]


def paradigms(r: dict[str, Runs]) -> list[tuple[str, Verdict]]:
    finals = {k: v.final() for k, v in r.items()}
    sac_best = max(finals, key=lambda k: finals[k].mean()) == "sac"
    p_min = min(improvement(finals["sac"], finals[k])[0] for k in finals if k != "sac")
    sac_trunc = r["sac"].rates["truncated"][:, r["sac"].episodes >= r["sac"].scaled(100, 0)[0]].mean()
    noise = {k: float(np.abs(np.diff(v.rates["success"], axis=1)).mean()) for k, v in r.items()}
    drift = {k: (r[k].span(*EARLY, "truncated").mean(), r[k].final("truncated").mean()) for k in ("ddpg", "a2c")}
    drift_hits = sum(late > early for early, late in drift.values()) + (drift["a2c"][1] >= 0.9)
    return [
        (CLAIM_TEXTS["paradigms"][0],
         ("reproduced" if sac_best and p_min > 0.5 else "partly" if sac_best else "not reproduced",
          "final success " + ", ".join(f"{k} {score(v, finals[k])}" for k, v in r.items())
          + "; " + "; ".join(pi("sac", k, finals["sac"], finals[k]) for k in finals if k != "sac"))),
        (CLAIM_TEXTS["paradigms"][1],
         ("reproduced" if sac_trunc <= 0.1 else "not reproduced", f"SAC's truncated rate from evaluation 100 on: {pct(sac_trunc)} ('few' = <= 10%)")),
        (CLAIM_TEXTS["paradigms"][2],
         ("reproduced" if max(noise, key=noise.get) == "td3" else "not reproduced",
          "mean |change of success| between consecutive evaluations " + ", ".join(f"{k} {v:.3f}" for k, v in noise.items()))),
        (CLAIM_TEXTS["paradigms"][3],
         (_grade(drift_hits, 3), f"truncated rate early ({span_text(r, EARLY).removeprefix('evaluations ')}) -> final: "
          + ", ".join(f"{k} {pct(a)} -> {pct(b)}" for k, (a, b) in drift.items()))),
    ]


CLAIMS: dict[str, Callable[[dict[str, Runs]], list[tuple[str, Verdict]]]] = {
    "encoders": encoders, "modalities": modalities, "fusion": fusion, "paradigms": paradigms, "modalities_paper": modalities,
    "modalities_steps": modalities, "paradigms_steps": paradigms,
}


def report(results: Path) -> str:
    lines = ["| experiment | claim | verdict | numbers |", "|---|---|---|---|"]
    for name in EXPERIMENTS:
        # an archived experiment (runs that cannot be repeated from the history) is still judged, and says so
        folder = next((f for f in (name, f"archive/{name}") if (results / f / "evaluation_rates.csv").exists()), name)
        link = f"[{name}]({folder}/)" + (" (archived)" if folder != name else "")
        path = results / folder / "evaluation_rates.csv"
        if not path.exists():
            lines += [f"| {link} | {claim} | not run yet | |" for claim in CLAIM_TEXTS[name]]
            continue
        runs = load(path)
        for claim, (verdict, numbers) in CLAIMS[name](runs):
            seeds = ", ".join(f"{k} {len(v.rates['success'])}" for k, v in runs.items())
            lines.append(f"| {link} | {claim} | **{verdict}** | {numbers} (runs: {seeds}) |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("docs/results"))
    parser.add_argument("--out", type=Path, help="write the table into this README between the CLAIMS markers (default: print)")
    args = parser.parse_args()
    table = report(args.results)
    if args.out is None:
        print(table)
        return
    text = args.out.read_text(encoding="utf-8")
    start, end = "<!-- CLAIMS -->", "<!-- /CLAIMS -->"
    head, _, rest = text.partition(start)
    _, _, tail = rest.partition(end)
    atomic_write_text(args.out, f"{head}{start}\n{table}{end}{tail}")


if __name__ == "__main__":
    main()
