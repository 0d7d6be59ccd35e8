"""A learning algorithm outside Stable-Baselines3, for the algorithm-seam tests (docs/architecture.md's recipe).

A linear policy ``tanh(W [x, 1])`` on the flattened observation, trained by antithetic random search: each
update plays one episode with ``W + noise * delta`` and one with ``W - noise * delta`` and moves ``W`` along
``delta`` by the difference of their returns. Everything it learns from, its random stream included, is saved
as ``weights.npz`` (read with ``allow_pickle=False``) and ``state.json``: a resumed run continues exactly.

It collects as every algorithm does, from the run's worlds (``num_envs``) behind SB3's ``VecEnv`` API, acting on all
of them in one call; an episode's return counts for the candidate (``+`` or ``-``) in force when it ended.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from crowdnav.registry import AlgorithmSpec


class RandomSearchAgent:
    """Implements crowdnav.agents.training.algorithm_protocol.Algorithm; ``RandomSearchAgent(env, config)`` is the builder."""

    def __init__(self, env: VecEnv, config: Any):
        spaces = env.observation_space.spaces
        self.shapes = {key: list(spaces[key].shape) for key in sorted(spaces)}
        inputs = sum(int(np.prod(shape)) for shape in self.shapes.values()) + 1
        self.weights = np.zeros((int(np.prod(env.action_space.shape)), inputs))
        self.step_size = float(config.algo_kwargs.get("step_size", 0.005))
        self.noise = float(config.algo_kwargs.get("noise", 0.3))
        self.rng = np.random.default_rng(config.seed)
        self.delta: np.ndarray | None = None
        self.plus_return: float | None = None
        """The return of ``W + noise * delta``, once its episode is played (then ``W - noise * delta`` is next)."""

    # ------------------------------------------------------------------ the protocol

    def learn(self, env: VecEnv, keep_going: Callable[[], bool]) -> None:
        observation = env.reset()
        returns = np.zeros(env.num_envs)
        while True:
            if self.delta is None:
                self.delta = self.rng.standard_normal(self.weights.shape)
            sign = 1.0 if self.plus_return is None else -1.0
            observation, rewards, dones, _ = env.step(self._act(self.weights + sign * self.noise * self.delta, observation))
            returns += rewards
            for world in np.flatnonzero(dones):  # every ended episode, in world order, then crowdnav's keep_going
                self._ended(float(returns[world]))
                returns[world] = 0.0
                if not keep_going():
                    return

    def predict(self, observation: Mapping[str, np.ndarray], state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        return self._act(self.weights, observation), None  # no memory: no state

    def save(self, folder: Path) -> None:
        arrays = {"weights": self.weights, **({"delta": self.delta} if self.delta is not None else {})}
        np.savez(folder / "weights.npz", **arrays)
        state = {"shapes": self.shapes, "step_size": self.step_size, "noise": self.noise, "plus_return": self.plus_return,
                 "rng": self.rng.bit_generator.state}
        (folder / "state.json").write_text(json.dumps(state), encoding="utf-8")

    @classmethod
    def load(cls, folder: Path) -> RandomSearchAgent:
        agent = cls.__new__(cls)
        state = json.loads((folder / "state.json").read_text(encoding="utf-8"))
        with np.load(folder / "weights.npz", allow_pickle=False) as arrays:
            agent.weights = arrays["weights"]
            agent.delta = arrays["delta"] if "delta" in arrays else None
        agent.shapes, agent.step_size, agent.noise = state["shapes"], state["step_size"], state["noise"]
        agent.plus_return = state["plus_return"]
        agent.rng = np.random.default_rng()
        agent.rng.bit_generator.state = state["rng"]
        return agent

    # ------------------------------------------------------------------ helpers

    def _act(self, weights: np.ndarray, observation: Mapping[str, np.ndarray]) -> np.ndarray:
        first = next(iter(self.shapes))
        batched = np.ndim(observation[first]) > len(self.shapes[first])
        rows = [np.asarray(observation[key], dtype=np.float64).reshape((-1, int(np.prod(shape))) if batched else -1)
                for key, shape in self.shapes.items()]
        features = np.concatenate([*rows, np.ones((rows[0].shape[0], 1)) if batched else np.ones(1)], axis=-1)
        return np.tanh(features @ weights.T).astype(np.float32)

    def _ended(self, episode_return: float) -> None:
        """The return of the candidate played: the first of a pair is kept, the second moves ``W``."""
        if self.delta is None:  # several worlds: a pair was completed earlier in this step
            self.delta = self.rng.standard_normal(self.weights.shape)
        if self.plus_return is None:
            self.plus_return = episode_return
        else:
            self.weights += self.step_size * (self.plus_return - episode_return) / 2 * self.delta
            self.delta, self.plus_return = None, None


SPEC = AlgorithmSpec("Linear policy trained by antithetic random search (a test algorithm outside SB3).", builder=RandomSearchAgent)
"""What a test registers: ``register_algorithm("random_search", SPEC)``."""
