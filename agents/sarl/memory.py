"""The replay memory of the SARL-style agent: transitions between observed joint states, as value-network features."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from crowdnav.agents.sarl.files import array_headers, expect, finite, only, refuse
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
    def load(cls, path: Path, capacity: int, humans: int, statics: int, robot_features: int) -> ReplayMemory:
        """The memory saved at ``path``, whose shapes must be those of ``capacity`` transitions of these sizes (else one line)."""
        headers = array_headers(path)
        only(path, headers, (*FIELDS, "counters"))
        expect(path, headers, "counters", (3,), "iu")
        with np.load(path, allow_pickle=False) as arrays:
            saved, size, position = (int(value) for value in arrays["counters"])
            if saved != capacity or not 0 <= size <= capacity or not 0 <= position < capacity:
                refuse(path, f"counters: expected capacity {capacity} (memory_size), size and next within it, got {saved}, {size}, {position}")
            rows = {"robot": (robot_features,), "humans": (humans, HUMAN_FEATURES), "statics": (statics, STATIC_FEATURES)}
            for name in FIELDS:
                if name.removeprefix("next_") == "statics" and not statics and name not in headers:
                    continue  # a checkpoint from before the room was read holds no statics: 0 slots
                expect(path, headers, name, (size, *rows.get(name.removeprefix("next_"), ())))
            memory = cls(capacity, humans, statics, robot_features)
            for name in FIELDS:
                if name in headers:
                    getattr(memory, name)[:size] = finite(path, name, arrays[name])
        memory.size, memory.next = size, position
        return memory
