"""The replay memory of the SARL-style agent: transitions between observed joint states, as value-network features."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from crowdnav.agents.sarl.lookahead import HUMAN_FEATURES, ROBOT_FEATURES, STATIC_FEATURES

FIELDS = ("robot", "humans", "statics", "next_robot", "next_humans", "next_statics", "reward", "terminal")


class ReplayMemory:
    """A ring of ``capacity`` transitions ``(s, r, s', terminal)``; ``terminal``: the episode ended there (no bootstrap)."""

    def __init__(self, capacity: int, humans: int, statics: int = 0, robot_features: int = ROBOT_FEATURES):
        self.capacity, self.size, self.next = int(capacity), 0, 0
        self.robot = np.zeros((capacity, robot_features), dtype=np.float32)
        self.humans = np.zeros((capacity, humans, HUMAN_FEATURES), dtype=np.float32)
        self.statics = np.zeros((capacity, statics, STATIC_FEATURES), dtype=np.float32)  # 0 slots: the room unseen
        self.next_robot = np.zeros_like(self.robot)
        self.next_humans = np.zeros_like(self.humans)
        self.next_statics = np.zeros_like(self.statics)
        self.reward = np.zeros(capacity, dtype=np.float32)
        self.terminal = np.zeros(capacity, dtype=np.float32)

    def add(self, state: tuple[np.ndarray, ...], reward: float, following: tuple[np.ndarray, ...], terminal: bool) -> None:
        """One transition: ``state`` and ``following`` are (robot, humans, statics) features."""
        i = self.next
        (self.robot[i], self.humans[i], self.statics[i]), self.reward[i] = state, reward
        (self.next_robot[i], self.next_humans[i], self.next_statics[i]), self.terminal[i] = following, float(terminal)
        self.next = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, rng: np.random.Generator, batch: int) -> dict[str, np.ndarray]:
        index = rng.integers(0, self.size, size=batch)
        return {name: getattr(self, name)[index] for name in FIELDS}

    def save(self, path: Path) -> None:
        """The filled rows only (compressed; a fresh run's checkpoint is small)."""
        filled = slice(0, self.size)
        np.savez_compressed(path, **{name: getattr(self, name)[filled] for name in FIELDS},
                            counters=np.array([self.capacity, self.size, self.next], dtype=np.int64))

    @classmethod
    def load(cls, path: Path) -> ReplayMemory:
        with np.load(path, allow_pickle=False) as arrays:
            capacity, size, position = (int(value) for value in arrays["counters"])
            # a checkpoint from before the room was read holds no statics: 0 slots
            statics = arrays["statics"].shape[1] if "statics" in arrays.files else 0
            memory = cls(capacity, arrays["humans"].shape[1], statics, arrays["robot"].shape[1])
            for name in FIELDS:
                if name in arrays.files:
                    getattr(memory, name)[:size] = arrays[name]
        memory.size, memory.next = size, position
        return memory
