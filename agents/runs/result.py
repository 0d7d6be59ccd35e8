"""What a finished training run reports (:class:`TrainResult`), for single-agent and shared robot runs alike."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from crowdnav.agents.sb3.callbacks import EpisodeRecord
from stable_baselines3.common.base_class import BaseAlgorithm

if TYPE_CHECKING:
    from crowdnav.agents.training.algorithm_protocol import Algorithm


@dataclass
class TrainResult:
    """Summary of a finished (or resumed and finished) run."""

    out: Path
    checkpoint: Path
    episodes: int
    """Episodes done in all, resumed ones included."""
    timesteps: int
    successes: int
    """Successful episodes in all."""
    seconds: float
    """Wall time of this session."""
    steps_per_second: float
    """Env steps per second in this session, gradient updates included."""
    records: list[EpisodeRecord] = field(default_factory=list)
    """The episodes of this session."""
    model: BaseAlgorithm | Algorithm | None = field(default=None, repr=False)
    """The trained SB3 model, or a registered algorithm's agent (crowdnav.agents.training.algorithm_protocol)."""

    @property
    def success_rate(self) -> float:
        return self.successes / self.episodes if self.episodes else 0.0
