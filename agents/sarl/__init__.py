"""``sarl``: a SARL-style value network with a one-step lookahead over the crowd's constant-velocity motion.

Chen et al. 2019, "Crowd-Robot Interaction: Crowd-aware Robot Navigation with Attention-based Deep
Reinforcement Learning", written here from the paper: :mod:`~crowdnav.agents.sarl.network` (the attention value
network), :mod:`~crowdnav.agents.sarl.lookahead` (what the agent reads and predicts),
:mod:`~crowdnav.agents.sarl.agent` (acting and deep V-learning). It is registered as ``algo: sarl`` through the
``crowdnav.algorithms`` entry point (pyproject.toml); torch is imported when an agent is built or loaded.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from crowdnav.registry import AlgorithmSpec


class _Builder:
    """``builder(env, config)`` and ``builder.load(folder)`` of :class:`~crowdnav.agents.sarl.agent.SarlAgent`, imported on use."""

    def __call__(self, env: Any, config: Any) -> Any:
        from crowdnav.agents.sarl.agent import SarlAgent

        return SarlAgent(env, config)

    def load(self, folder: Path) -> Any:
        from crowdnav.agents.sarl.agent import SarlAgent

        return SarlAgent.load(folder)


SPEC = AlgorithmSpec("SARL-style attention value network acting by a one-step lookahead over the humans' constant-velocity motion "
                     "(deep V-learning; reads humans, goal, velocity).", builder=_Builder())
"""The ``sarl`` algorithm (entry point ``crowdnav.algorithms``)."""
