"""Time each sensing modality's observe() over a stream of real simulator states.

For each crowd size, a simulator runs a few episodes with a random robot and records its
states; each modality then observes every recorded state (the state is restored into the
simulator, geometry included, so every observation reads genuine cached geometry). The
reported figure is the median over ``--repeats`` of the mean microseconds per observe().

    .venv/bin/python benchmarks/bench_sensors.py
    .venv/bin/python benchmarks/bench_sensors.py --scenario room_furniture --humans 10 --states 1000
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import dataclass

import numpy as np

from crowdnav import Simulator
from crowdnav.sensors import build_modalities

ALL = ["goal", "closest_obstacle", "lidar", "leog", "velocity"]
GEOMETRY = ("positions", "velocities", "robot_heading", "pair_offset", "pair_distance", "polygon_offset", "polygon_distance",
            "disc_offset", "disc_distance", "radii")


@dataclass
class Snapshot:
    """What the sensors read from a simulator: state and cached geometry."""

    fields: dict


def record_states(sim: Simulator, count: int, seed: int) -> list[Snapshot]:
    """Run episodes with a random robot and snapshot every state (post reset and post step)."""
    rng = np.random.default_rng(seed)
    episode = 0
    sim.reset(seed=seed)
    states = []
    while len(states) < count:
        states.append(snapshot(sim))
        events = sim.step(rng.uniform(-1.0, 1.0, size=2))
        if events.terminated or events.truncated:
            episode += 1
            sim.reset(seed=seed + episode)
    return states


def _copy(value):
    return value.copy() if isinstance(value, np.ndarray) else value


def snapshot(sim: Simulator) -> Snapshot:
    # radii are replaced (never modified) at reset: sharing the object across an episode's
    # snapshots keeps the sensors' per-episode caches valid, as in a real episode
    fields = {name: _copy(getattr(sim, name)) for name in GEOMETRY if hasattr(sim, name) and name != "radii"}
    fields["radii"] = sim.radii
    return Snapshot(fields)


def restore(sim: Simulator, snapshot: Snapshot) -> None:
    for name, value in snapshot.fields.items():
        setattr(sim, name, value)


def time_modality(observe, sims_states, repeats: int) -> float:
    """Median over repeats of the mean microseconds per call of observe(sim)."""
    results = []
    for _ in range(repeats):
        elapsed = 0.0
        for sim, snapshot in sims_states:
            restore(sim, snapshot)
            begin = time.perf_counter()
            observe(sim)
            elapsed += time.perf_counter() - begin
        results.append(elapsed / len(sims_states) * 1e6)
    return statistics.median(results)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="room_furniture", help="library scenario name or YAML path")
    parser.add_argument("--humans", type=int, nargs="+", default=[5, 10, 20, 50], help="crowd sizes to time")
    parser.add_argument("--states", type=int, default=500, help="recorded simulator states per crowd size")
    parser.add_argument("--repeats", type=int, default=7, help="timing repeats (the median is reported)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the recorded episodes")
    parser.add_argument("--modalities", nargs="+", default=ALL, help="modalities to time")
    args = parser.parse_args()

    header = f"{'humans':>6} " + " ".join(f"{name:>16}" for name in args.modalities) + f" {'all together':>14}"
    print(f"median microseconds per observe() in {args.scenario}, {args.states} states, {args.repeats} repeats")
    print(header)
    for humans in args.humans:
        sim = Simulator(args.scenario, {"humans.count": humans})
        states = [(sim, snapshot) for snapshot in record_states(sim, args.states, args.seed)]
        modalities = build_modalities(args.modalities, sim.world, sim.scenario.sensors)
        row = [time_modality(modality.observe, states, args.repeats) for modality in modalities.values()]

        def observe_all(s, modalities=modalities):
            return {key: modality.observe(s) for key, modality in modalities.items()}

        together = time_modality(observe_all, states, args.repeats)
        print(f"{humans:>6} " + " ".join(f"{value:>16.1f}" for value in row) + f" {together:>14.1f}")


if __name__ == "__main__":
    main()
