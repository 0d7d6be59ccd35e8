"""Training throughput: env steps/s including gradient updates, per algorithm and modality set, before/after.

    python benchmarks/bench_train.py [--algos sac td3 ddpg a2c] [--cases ...] [--steps 1000] [--repeats 3]
                                     [--threads 1] [--no-baseline] [--no-reference] [--json FILE]
    python benchmarks/bench_train.py --batched [--algos ppo a2c sac td3 ddpg] [--num-envs 32] [--processes 2]

**Batched training** (``--batched``): every algorithm in the Figure-4 setting (room_furniture,
5 humans at 0.5-1.2 m/s, closest obstacle + goal) with crowdnav's batched defaults
(``num_envs`` worlds of the native vector env, :data:`crowdnav.agents.sb3.factory.BATCHED_DEFAULTS`), timed
over ``--batched-steps`` env steps after a warm-up past ``learning_starts``, next to the
single-env path in the same run (one env, the defaults ``crowdnav train`` had before batching:
SAC at one gradient step per env step); the ``vs single SAC`` column is the ratio of wall-clock
rates. ``--processes N`` also runs N independent trainings of each batched case at once (a
process per core) and reports their summed rate.

Each case builds a fresh agent with crowdnav's defaults (``crowdnav.agents.make_model``) on
``open_space``, runs ``--warmup`` steps (past ``learning_starts``, so every timed step
includes its gradient update), then times ``--steps`` more; the median over ``--repeats``
fresh agents is reported, per wall-clock second and per CPU second of the process (the latter
is less sensitive to other processes sharing the machine). Cases: lidar+goal; leog+goal with the encoder frozen (the grid
encoded once per step by the observation wrapper), frozen without that wrapper (the frozen
CNN runs inside the extractor on every sampled batch), finetune and scratch; leog+lidar+goal
(scratch). The frozen and finetune encoders come from a quick pre-training (their weights do
not change the speed).

**Before/after in one run.** Unless ``--no-baseline``, every case also runs as crowdnav trained
before its speed-ups (``make_model(..., reference=True)``: SB3's own SAC/TD3/DDPG classes and
the extractor's and replay buffer's plain code paths; the same updates, the tests check the
networks come out identical). The two alternate within each repeat (baseline first on even
repeats, last on odd ones), so both see the same machine load; the ``speed-up`` column is the
ratio of the medians per CPU second.

Two plain SB3 references calibrate the machine's load (SAC, MultiInputPolicy, CombinedExtractor,
lidar+goal, 64-64 and 256-256 networks; ``--no-reference`` skips them). The replay-buffer table
(``--no-buffer`` skips it) gives the bytes the replay buffer holds per transition (observation
and next observation, action, reward, done, timeout) and the projection to 100,000
transitions, with the grids bit-packed (crowdnav's default) and as SB3 stores them (uint8).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import torch
from crowdnav.agents.sb3.factory import (
    OFF_POLICY,
    SB3_ALGORITHMS,
    load_leog_weights,
    make_env,
    make_model,
    make_vec_env,
    precomputes_leog,
)
from crowdnav.agents.training.config import EncoderConfig, TrainConfig
from stable_baselines3 import SAC
from stable_baselines3.common.monitor import Monitor

from crowdnav.files import atomic_write_text

CASES = {
    "lidar+goal": (["lidar", "goal"], "scratch", True),
    "leog+goal frozen": (["leog", "goal"], "frozen", True),
    "leog+goal frozen, no wrapper": (["leog", "goal"], "frozen", False),
    "leog+goal finetune": (["leog", "goal"], "finetune", True),
    "leog+goal scratch": (["leog", "goal"], "scratch", True),
    "leog+lidar+goal": (["leog", "lidar", "goal"], "scratch", True),
}
"""Case name -> (modalities, encoder mode, precompute)."""


FIGURE4 = {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]}
"""The Figure-4 setting's crowd in room_furniture (docs/results/README.md)."""


def build_batched(algo: str, num_envs: int, warmup: int):
    """A model with crowdnav's defaults for ``num_envs`` worlds (1: the single-env path) in the Figure-4 setting."""
    fields = {"learning_starts": warmup // 2} if algo in OFF_POLICY else {}
    config = TrainConfig(scenario="room_furniture", overrides=FIGURE4, modalities=["closest_obstacle", "goal"], algo=algo,
                         num_envs=num_envs, **fields)
    return make_model(config, make_vec_env(config) if num_envs > 1 else make_env(config))


def _batched_rate(algo: str, num_envs: int, steps: int, warmup: int, threads: int) -> tuple[float, float]:
    torch.set_num_threads(threads)  # a worker process of --processes
    return steps_per_second(lambda: build_batched(algo, num_envs, warmup), steps, warmup)


def batched(args: argparse.Namespace, results: dict) -> None:
    """The --batched table: each algorithm batched, against the single-env SAC path measured in the same run."""
    from concurrent.futures import ProcessPoolExecutor

    single = [steps_per_second(lambda: build_batched("sac", 1, args.warmup), args.steps, args.warmup) for _ in range(args.repeats)]
    report("sac single env (before batching)", single, results)
    base = statistics.median(r[0] for r in single)
    for algo in args.algos:
        warmup = max(args.warmup, 2 * args.num_envs)
        runs = [_batched_rate(algo, args.num_envs, args.batched_steps, warmup, args.threads) for _ in range(args.repeats)]
        name = f"{algo} batched ({args.num_envs} worlds)"
        report(name, runs, results)
        results[name]["vs_single_sac"] = results[name]["steps_per_second"] / base
        print(f"{'':40s} {results[name]['vs_single_sac']:7.1f}x the single-env SAC path", flush=True)
        if args.processes > 1:
            with ProcessPoolExecutor(args.processes) as pool:
                jobs = [pool.submit(_batched_rate, algo, args.num_envs, args.batched_steps, warmup, args.threads)
                        for _ in range(args.processes)]
                rates = [job.result() for job in jobs]
            total = sum(rate[0] for rate in rates)
            results[f"{name} x{args.processes} processes"] = {"steps_per_second": total, "vs_single_sac": total / base}
            print(f"{name + f' x{args.processes} processes':40s} {total:7.1f} steps/s in all ({total / base:.1f}x)", flush=True)


def pretrained_encoder(folder: Path) -> Path:
    from crowdnav.agents import collect_grids, pretrain_encoder

    return pretrain_encoder(collect_grids("room_furniture", 200, seed=0), folder, epochs=1).encoder_path


def build(algo: str, case: str, encoder_file: Path, warmup: int, pack_grids: bool = True, baseline: bool = False):
    modalities, mode, precompute = CASES[case]
    encoder = EncoderConfig(mode=mode, weights=None if mode == "scratch" else str(encoder_file), precompute=precompute)
    fields = {"learning_starts": warmup // 2} if algo in OFF_POLICY else {}
    config = TrainConfig(scenario="open_space", modalities=modalities, algo=algo, encoder=encoder, pack_grids=pack_grids,
                         **fields)
    frozen, saved = load_leog_weights(config)
    env = make_env(config, frozen if precomputes_leog(config) else None)
    return make_model(config, env, saved, reference=baseline)


def reference(net: list[int], warmup: int):
    from crowdnav.envs import CrowdNavEnv

    env = Monitor(CrowdNavEnv("open_space", modalities=["lidar", "goal"]))
    return SAC("MultiInputPolicy", env, policy_kwargs={"net_arch": net}, learning_starts=warmup // 2, seed=0, device="cpu")


def steps_per_second(make, steps: int, warmup: int) -> tuple[float, float]:
    """(env steps per wall-clock second, per CPU second of this process)."""
    model = make()
    model.learn(warmup)
    wall, cpu = time.perf_counter(), time.process_time()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - wall), steps / (time.process_time() - cpu)


def report(name: str, runs: list[tuple[float, float]], results: dict, before: list[tuple[float, float]] | None = None) -> None:
    wall, cpu = statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs)
    results[name] = {"steps_per_second": wall, "steps_per_cpu_second": cpu}
    line = f"{name:40s} {wall:7.1f} steps/s {cpu:7.1f} per CPU-s"
    if before is not None:
        base_wall, base_cpu = statistics.median(r[0] for r in before), statistics.median(r[1] for r in before)
        results[name].update(baseline_steps_per_second=base_wall, baseline_steps_per_cpu_second=base_cpu, speedup=cpu / base_cpu)
        line += f" | before {base_wall:7.1f} steps/s {base_cpu:7.1f} per CPU-s | speed-up {cpu / base_cpu:4.2f}x"
    print(f"{line}  (wall runs: {', '.join(f'{r[0]:.0f}' for r in runs)})", flush=True)


def buffer_bytes(model) -> int:
    """Bytes per transition of an off-policy model's replay buffer (all arrays, per slot)."""
    buffer = model.replay_buffer
    arrays = [*buffer.observations.values(), *buffer.next_observations.values(), buffer.actions, buffer.rewards,
              buffer.dones, buffer.timeouts]
    return sum(array.nbytes for array in arrays) // buffer.buffer_size


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algos", nargs="+", default=["sac", "td3", "ddpg", "a2c"], choices=SB3_ALGORITHMS)
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--warmup", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--no-baseline", action="store_true", help="skip the before-the-speed-ups runs of each case")
    parser.add_argument("--no-reference", action="store_true", help="skip the plain SB3 SAC references")
    parser.add_argument("--no-buffer", action="store_true", help="skip the replay-buffer size table")
    parser.add_argument("--json", type=Path, help="also write the results here")
    parser.add_argument("--batched", action="store_true", help="the batched-training table instead (see the module doc)")
    parser.add_argument("--num-envs", type=int, default=32, help="--batched: worlds per training")
    parser.add_argument("--batched-steps", type=int, default=40_000, help="--batched: env steps timed per batched run")
    parser.add_argument("--processes", type=int, default=1, help="--batched: also run this many trainings at once")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, torch {torch.__version__}, "
          f"{args.threads} thread(s); load average at start {os.getloadavg()[0]:.2f}", flush=True)
    results: dict[str, dict[str, float]] = {}
    if args.batched:
        batched(args, results)
    else:
        single_env_tables(args, results)
    print(f"# load average at end {os.getloadavg()[0]:.2f}")
    if args.json is not None:
        atomic_write_text(args.json, json.dumps(results, indent=2) + "\n")
    return 0


def single_env_tables(args: argparse.Namespace, results: dict) -> None:
    """The per-algorithm, per-case tables of one env (with the before-the-speed-ups baseline) and the buffer sizes."""
    with tempfile.TemporaryDirectory() as folder:
        encoder_file = pretrained_encoder(Path(folder))
        if not args.no_reference:
            for net in ([64, 64], [256, 256]):
                runs = [steps_per_second(lambda net=net: reference(net, args.warmup), args.steps, args.warmup) for _ in range(args.repeats)]
                report(f"SB3 reference SAC {net[0]}-{net[1]}, lidar+goal", runs, results)
        for algo in args.algos:
            for case in args.cases:
                runs, before = [], []
                for repeat in range(args.repeats):
                    order = (False, True) if repeat % 2 else (True, False)  # baseline first, then last, alternately
                    for baseline in order if not args.no_baseline else (False,):
                        timing = steps_per_second(lambda a=algo, c=case, b=baseline: build(a, c, encoder_file, args.warmup, baseline=b),
                                                  args.steps, args.warmup)
                        (before if baseline else runs).append(timing)
                report(f"{algo} {case}", runs, results, before if not args.no_baseline else None)
        if not args.no_buffer:
            print("\n# replay buffer (SAC): bytes per transition, and GB for 100,000 transitions", flush=True)
            print(f"{'case':45s} {'packed grids':>22s} {'uint8 grids':>22s}")
            for case in args.cases:
                packed, plain = (buffer_bytes(build("sac", case, encoder_file, args.warmup, pack)) for pack in (True, False))
                results[f"buffer {case}"] = {"bytes_per_transition": packed, "bytes_per_transition_uint8": plain}
                print(f"{case:45s} {packed:8d} B {packed * 1e5 / 1e9:7.3f} GB {plain:8d} B {plain * 1e5 / 1e9:7.3f} GB", flush=True)


if __name__ == "__main__":
    sys.exit(main())
