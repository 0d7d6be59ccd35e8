"""The optional imitation warm start of the SARL-style agent (RL + demonstrations, reported apart from pure RL).

As in Chen et al. 2019, the value network first regresses the discounted returns of a scripted teacher's
episodes, then deep V-learning goes on from there. The teacher is one of crowdnav's scripted robots
(:data:`TEACHERS`) and reads the simulator, to produce the demonstrations only: the agent's own acting never
does. Its episodes are training episodes of the run (logged and seeded like every other one).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.agents.sarl.files import array_headers, expect, finite, only, refuse
from crowdnav.agents.sarl.lookahead import HUMAN_FEATURES, STATIC_FEATURES
from crowdnav.agents.training.config import ConfigError

TEACHERS = ("predictive", "orca", "oracle", "onboard")
"""Scripted robots that may teach: the predictive planner (true current state), the ORCA robot, the oracle (future), and
the onboard planner (the same planner fed by the robot's own tracker and map: no privileged state)."""


def make_teacher(name: str) -> Any:
    """The scripted robot ``name`` as a callable ``teacher(simulator) -> action``."""
    if name not in TEACHERS:
        raise ConfigError(f"algo_kwargs.imitation_teacher: {name!r} is not one of {', '.join(TEACHERS)}")
    from crowdnav.planning.scripted import SCRIPTED_POLICIES

    return SCRIPTED_POLICIES[name]()


def world_simulators(env: Any) -> list[Any]:
    """Each world's simulator of a :func:`crowdnav.agents.sb3.factory.make_vec_env` env (or a VecEnvWrapper of it), for the teacher.

    The vector env's engine gives them (:meth:`crowdnav.envs.engines.protocol.WorldEngine.simulators`): where it holds single
    envs (one world, or crowds too large to stack) their live simulators (read, never stepped: the teacher of one
    world reads what it read before the vector stack); stacked worlds a snapshot per call, so a teacher that keeps a
    plan per episode state (the oracle) plans again at every step there.
    """
    simulators: list[Any] = env.get_attr("engine")[0].simulators()
    return simulators


def discounted_returns(rewards: list[float], discount: float) -> np.ndarray:
    """Per step, the discounted sum of the episode's rewards from that step on (nothing after its end)."""
    returns = np.zeros(len(rewards), dtype=np.float32)
    total = 0.0
    for index in range(len(rewards) - 1, -1, -1):
        total = rewards[index] + discount * total
        returns[index] = total
    return returns


class Demonstrations:
    """The teacher's visited states (value-network features) and their discounted returns."""

    def __init__(self) -> None:
        self.robot: list[np.ndarray] = []
        self.humans: list[np.ndarray] = []
        self.statics: list[np.ndarray] = []
        self.returns: list[np.ndarray] = []

    def add_episode(self, states: list[tuple[np.ndarray, ...]], rewards: list[float], discount: float) -> None:
        """One teacher episode: its states' (robot, humans, statics) features and its rewards."""
        robot, humans, statics = zip(*states, strict=True)
        self.robot.append(np.stack(robot))
        self.humans.append(np.stack(humans))
        self.statics.append(np.stack(statics))
        self.returns.append(discounted_returns(rewards, discount))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(robot, humans, statics, returns) of every held step."""
        return np.concatenate(self.robot), np.concatenate(self.humans), np.concatenate(self.statics), np.concatenate(self.returns)

    @property
    def episodes(self) -> int:
        """How many teacher episodes are held."""
        return len(self.returns)

    def __len__(self) -> int:
        return sum(len(item) for item in self.returns)

    def save(self, path: Path) -> None:
        lengths = np.array([len(item) for item in self.returns], dtype=np.int64)
        if len(lengths):
            robot, humans, statics, returns = self.arrays()
            np.savez_compressed(path, robot=robot, humans=humans, statics=statics, returns=returns, lengths=lengths)
        else:
            np.savez_compressed(path, lengths=lengths)

    @classmethod
    def load(cls, path: Path, humans: int, statics: int, robot_features: int, episodes: int) -> Demonstrations:
        """The demonstrations saved at ``path``: at most ``episodes`` teacher episodes of these sizes (else one line)."""
        headers = array_headers(path)
        only(path, headers, ("robot", "humans", "statics", "returns", "lengths"))
        if "lengths" not in headers or len(headers["lengths"][0]) != 1 or headers["lengths"][0][0] > episodes:
            refuse(path, f"lengths: expected at most {episodes} (imitation_episodes) episode lengths, holds {headers.get('lengths', ('none',))[0]}")
        expect(path, headers, "lengths", headers["lengths"][0], "iu")
        demonstrations = cls()
        with np.load(path, allow_pickle=False) as arrays:
            lengths = arrays["lengths"]
            if len(lengths):
                if (lengths < 1).any():
                    refuse(path, "lengths: expected episodes of at least one step")
                steps = int(lengths.sum())
                for name, rows in (("robot", (robot_features,)), ("humans", (humans, HUMAN_FEATURES)), ("returns", ()),
                                   *((("statics", (statics, STATIC_FEATURES)),) if statics or "statics" in headers else ())):
                    expect(path, headers, name, (steps, *rows))
                splits = np.cumsum(lengths)[:-1]
                demonstrations.robot = list(np.split(finite(path, "robot", arrays["robot"]), splits))
                demonstrations.humans = list(np.split(finite(path, "humans", arrays["humans"]), splits))
                # a checkpoint from before the room was read holds no statics: 0 slots
                statics_rows = finite(path, "statics", arrays["statics"]) if "statics" in headers else \
                    np.zeros((steps, 0, STATIC_FEATURES), np.float32)
                demonstrations.statics = list(np.split(statics_rows, splits))
                demonstrations.returns = list(np.split(finite(path, "returns", arrays["returns"]), splits))
        return demonstrations
