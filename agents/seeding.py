"""Seed rules: which seed each training episode and each grid-collection episode uses.

Plain arithmetic without torch, so evaluation (the protocol's check that test seeds never meet
training seeds) can use the rules without loading the training stack.
"""

from __future__ import annotations

TRAIN_SEED_BASE = 1_000_000
"""Training seeds start here; seeds below it are free for held-out test episodes."""


def train_seed(seed: int, episode: int) -> int:
    """Seed of training episode ``episode`` (0-based) of a run with seed ``seed``: disjoint ranges per run seed."""
    return TRAIN_SEED_BASE * (seed + 1) + episode


DATASET_SEED_OFFSET = TRAIN_SEED_BASE // 2
"""Grid-collection episodes use the upper half of each seed's band: no run trains 500,000 episodes."""


def dataset_seed(seed: int, episode: int) -> int:
    """Seed of episode ``episode`` of a random-policy grid collection with seed ``seed``.

    Disjoint from the held-out test seeds (below :data:`TRAIN_SEED_BASE`) and from every
    training episode, so an encoder pre-trained on the collection never saw a test episode.
    """
    return TRAIN_SEED_BASE * (seed + 1) + DATASET_SEED_OFFSET + episode
