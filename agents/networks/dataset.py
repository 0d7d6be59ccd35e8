"""Occupancy-grid datasets for pre-training the LEOG encoder: collection by a wandering robot, and the file format.

**File format** (``.npz``, readable with ``numpy.load(path, allow_pickle=False)``):

* ``grids``: uint8 array of shape (N, 1, H, W); a cell is occupied where the value is non-zero
  (crowdnav writes 0/255, like the ``leog`` observation; 0/1 is read the same way).
* ``metadata``: optional 0-d unicode array holding a JSON object (``scenario``, ``seed``,
  ``resolution``, ``size``, ``every``, ``policy``, ``crowdnav_version``, ...).

A dataset from another simulator needs only ``grids`` (uint8, bool, or 0/1 floats; (N, H, W)
is accepted and gets its channel axis). Its grids must have the same H x W, orientation (row
0 farthest ahead, column 0 farthest left) and resolution as the ``leog`` the agent will see.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from crowdnav.files import replacing

DATASET_FORMAT = "crowdnav-leog-dataset/1"


@dataclass
class GridDataset:
    """Occupancy grids (N, 1, H, W) uint8 (non-zero = occupied) and free-form metadata."""

    grids: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.grids)

    @property
    def grid_shape(self) -> tuple[int, int, int]:
        return tuple(self.grids.shape[1:])


def save_dataset(dataset: GridDataset, path: str | Path) -> Path:
    """Write ``dataset`` as a compressed ``.npz`` (the suffix is added if missing); returns the path."""
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_name(path.name + ".npz")
    path.parent.mkdir(parents=True, exist_ok=True)
    metadata = {"format": DATASET_FORMAT, **dataset.metadata}
    grids = _as_grids(dataset.grids, str(path))
    with replacing(path, suffix=".npz") as temporary:  # a link at ``path`` is replaced; ".npz": numpy adds none then
        np.savez_compressed(temporary, grids=grids, metadata=np.array(json.dumps(metadata)))
    return path


def load_dataset(path: str | Path) -> GridDataset:
    """Read a dataset file (see the module docstring); raises ValueError naming the file on a bad layout."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as archive:
            if "grids" not in archive.files:
                raise ValueError(f"{path}: no 'grids' array (found: {', '.join(archive.files) or 'nothing'})")
            grids = _as_grids(archive["grids"], str(path))
            metadata = json.loads(str(archive["metadata"])) if "metadata" in archive.files else {}
    except (OSError, EOFError) as error:
        raise ValueError(f"{path}: cannot read the dataset: {error}") from None
    if not isinstance(metadata, dict):
        raise ValueError(f"{path}: metadata must be a JSON object")
    return GridDataset(grids, metadata)


def _as_grids(grids: np.ndarray, label: str) -> np.ndarray:
    grids = np.asarray(grids)
    if grids.ndim == 3:
        grids = grids[:, None]
    if grids.ndim != 4 or grids.shape[1] != 1 or len(grids) == 0:
        raise ValueError(f"{label}: expected grids of shape (N, 1, H, W) or (N, H, W) with N >= 1, got {grids.shape}")
    if grids.dtype == np.uint8:
        return grids
    if grids.dtype == bool or np.issubdtype(grids.dtype, np.number):
        return ((grids > 0) * 255).astype(np.uint8)
    raise ValueError(f"{label}: grids must be uint8, bool or numbers, got {grids.dtype}")


def collect_grids(
    scenario: str | Path = "room_furniture",
    count: int = 5_000,
    *,
    seed: int = 0,
    every: int = 2,
    hold: float = 5.0,
    overrides: Mapping[str, Any] | None = None,
    sensors: Mapping[str, Any] | None = None,
) -> GridDataset:
    """Let the robot wander with a random policy and keep every ``every``-th LEOG, ``count`` grids in all.

    The random policy draws a uniform action in [-1, 1]^2 and holds it for a geometric number
    of steps (mean ``hold``), so the robot travels across the room instead of jittering in
    place; episodes that end (collision, goal, time limit) are restarted. Everything is seeded
    from ``seed``: episode ``i`` uses seed ``crowdnav.agents.training.seeding.dataset_seed(seed, i)``, never a
    test or training episode's seed.
    """
    from crowdnav.agents.training.seeding import dataset_seed
    from crowdnav.agents.training.space_checks import box_space

    from crowdnav import __version__
    from crowdnav.envs import CrowdNavEnv

    if count < 1 or every < 1 or hold < 1.0:
        raise ValueError(f"expected count >= 1, every >= 1 and hold >= 1, got {count}, {every}, {hold}")
    env = CrowdNavEnv(scenario, modalities=["leog"], overrides=overrides, sensors=sensors)
    shape = box_space(env.observation_space, "leog").shape
    grids = np.empty((count, *shape), dtype=np.uint8)
    rng = np.random.default_rng(seed)
    episode, kept, step = 0, 0, 0
    observation, _ = env.reset(seed=dataset_seed(seed, 0))
    action = rng.uniform(-1.0, 1.0, 2).astype(np.float32)
    while kept < count:
        if step % every == 0:
            grids[kept] = observation["leog"]
            kept += 1
        if rng.random() < 1.0 / hold:
            action = rng.uniform(-1.0, 1.0, 2).astype(np.float32)
        observation, _, terminated, truncated, _ = env.step(action)
        step += 1
        if terminated or truncated:
            episode += 1
            observation, _ = env.reset(seed=dataset_seed(seed, episode))
    leog = env.scenario.sensors.leog
    metadata = {
        "scenario": str(scenario), "seed": seed, "every": every, "hold": hold, "episodes": episode + 1, "steps": step,
        "size": leog.size, "resolution": leog.resolution, "overrides": dict(overrides or {}),
        "policy": "uniform random action held for a geometric number of steps", "crowdnav_version": __version__,
    }
    return GridDataset(grids, metadata)
