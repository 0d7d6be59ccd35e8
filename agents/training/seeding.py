"""Seed rules: which seed each training, grid-collection and demonstration episode uses.

Plain arithmetic without torch, so evaluation (the protocol's check that test seeds never meet
training seeds) can use the rules without loading the training stack.
"""

from __future__ import annotations

from collections.abc import Iterable

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


DEMONSTRATION_SEED_OFFSET = TRAIN_SEED_BASE * 3 // 4
"""Demonstration episodes use the last quarter of each seed's band, [750,000, 1,000,000): above the
grid collections' [500,000, 750,000) and every training episode (at most 500,000, see EpisodeSeedCounter)."""

DEMONSTRATION_EPISODES = TRAIN_SEED_BASE - DEMONSTRATION_SEED_OFFSET
"""How many demonstration episodes one seed's quarter holds (250,000)."""

MAX_TRAIN_EPISODES = DATASET_SEED_OFFSET
"""Training episodes a run may start (500,000): beyond, their seeds would be grid-collection seeds."""

MAX_SEED = 2**31 - 1
"""Largest run seed: numpy's and torch's generators take it, and every episode seed derived from it fits in 64 bits."""


def demonstration_seed(seed: int, episode: int) -> int:
    """Seed of demonstration episode ``episode`` (0-based) of the scripted expert, for a run with seed ``seed``.

    Disjoint from the held-out test seeds (below :data:`TRAIN_SEED_BASE`), from the grid
    collections (:func:`dataset_seed`) and from the run's training episodes, so a
    warm-started agent never imitated a test episode nor an episode it later trains on.
    """
    if not 0 <= episode < DEMONSTRATION_EPISODES:
        raise ValueError(f"demonstration episode {episode} outside the band's quarter [0, {DEMONSTRATION_EPISODES})")
    return TRAIN_SEED_BASE * (seed + 1) + DEMONSTRATION_SEED_OFFSET + episode


class EpisodeSeedCounter:
    """Numbers the training episodes of a run that collects from several worlds at once.

    Episodes are numbered in the order they start: the first reset gives worlds 0..B-1 the
    episodes ``first_episode`` .. ``first_episode + B - 1``; afterwards, the worlds whose
    episodes ended in one step start the next numbers in ascending world order. Episode ``i``
    uses seed :func:`train_seed` ``(seed, i)``: a run is the same from the same seed whatever
    seed an algorithm passes to the environment, and never meets a held-out test seed.
    Picklable (a checkpoint stores it with the environment).
    """

    def __init__(self, seed: int, first_episode: int = 0):
        self.run_seed = seed
        self.next_episode = first_episode
        self.episode_of: dict[int, int] = {}
        """World -> the episode it is playing."""
        self.ended_of: dict[int, int] = {}
        """World -> the episode it played before its current one (the one that just ended, right after an autoreset)."""

    def __call__(self, worlds: Iterable[int]) -> list[int]:
        seeds = []
        for world in worlds:
            if self.next_episode >= MAX_TRAIN_EPISODES:  # 10+ M env steps of short episodes; the next band is the grids'
                raise RuntimeError(f"a run may start at most {MAX_TRAIN_EPISODES:,} training episodes (their seeds would reach "
                                   "the grid-collection band, crowdnav.agents.training.seeding); split the budget over run seeds")
            if int(world) in self.episode_of:
                self.ended_of[int(world)] = self.episode_of[int(world)]
            self.episode_of[int(world)] = self.next_episode
            seeds.append(train_seed(self.run_seed, self.next_episode))
            self.next_episode += 1
        return seeds


def check_test_seeds(first: int, episodes: int) -> None:
    """ValueError (one line) unless held-out test seeds ``first`` .. ``first + episodes - 1`` lie below :data:`TRAIN_SEED_BASE`.

    Every seed from :data:`TRAIN_SEED_BASE` on belongs to some run seed's band (its training,
    grid-collection and demonstration episodes), so a policy of unknown run seed (``crowdnav
    evaluate POLICY``) is tested only below it: the benchmark refuses the same overlap for its runs
    (``Protocol.check_disjoint``).
    """
    if first < 0:
        raise ValueError(f"test seeds must be non-negative, got a first seed of {first:,}")
    last = first + episodes - 1
    if last >= TRAIN_SEED_BASE:
        shared = max(first, TRAIN_SEED_BASE)
        run_seed = shared // TRAIN_SEED_BASE - 1
        raise ValueError(f"test seeds {first:,}-{last:,} include {shared:,}, a seed of run seed {run_seed:,}'s training, grid and "
                         f"demonstration episodes (crowdnav.agents.training.seeding); held-out test seeds lie below {TRAIN_SEED_BASE:,}")
