"""The replay memory of the SARL-style agent: transitions between observed joint states, as value-network features."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from crowdnav.agents.sarl.lookahead import HUMAN_FEATURES, ROBOT_FEATURES

FIELDS = ("robot", "humans", "next_robot", "next_humans", "reward", "terminal")


class ReplayMemory:
    """A ring of ``capacity`` transitions ``(s, r, s', terminal)``; ``terminal``: the episode ended there (no bootstrap)."""

    def __init__(self, capacity: int, humans: int):
        self.capacity, self.size, self.next = int(capacity), 0, 0
        self.robot = np.zeros((capacity, ROBOT_FEATURES), dtype=np.float32)
        self.humans = np.zeros((capacity, humans, HUMAN_FEATURES), dtype=np.float32)
        self.next_robot = np.zeros_like(self.robot)
        self.next_humans = np.zeros_like(self.humans)
        self.reward = np.zeros(capacity, dtype=np.float32)
        self.terminal = np.zeros(capacity, dtype=np.float32)

    def add(self, robot: np.ndarray, humans: np.ndarray, reward: float, next_robot: np.ndarray, next_humans: np.ndarray,
            terminal: bool) -> None:
        i = self.next
        self.robot[i], self.humans[i], self.reward[i] = robot, humans, reward
        self.next_robot[i], self.next_humans[i], self.terminal[i] = next_robot, next_humans, float(terminal)
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
            memory = cls(capacity, arrays["humans"].shape[1])
            for name in FIELDS:
                getattr(memory, name)[:size] = arrays[name]
        memory.size, memory.next = size, position
        return memory
