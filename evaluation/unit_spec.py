"""What one run is: :class:`UnitSpec`, the configuration, seed and protocol that define it.

Two runs with equal specs are the same run (``spec.json`` in the run's folder holds it, and
:func:`crowdnav.evaluation.runner.run_unit` compares it by :func:`run_identity`: the protocol's ``seeds``, the
experiment's run count, is not part of a run); this module turns a spec into the
TrainConfig the run trains with. Carrying a run out is :mod:`crowdnav.evaluation.runner`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from crowdnav.evaluation.protocol import Protocol
from crowdnav.evaluation.storage import SPEC_FILE, TRAIN_DIR, experiment_of, pretrained_encoder_path

if TYPE_CHECKING:
    from crowdnav.agents.training.config import TrainConfig

PROTOCOL_FIELDS = ("seed", "out", "episodes", "checkpoint_every", "timesteps", "checkpoint_every_steps", "progress", "torch_threads",
                   "save_replay_buffer")
"""TrainConfig fields the protocol sets for every run (an experiment may not set them)."""

PRETRAINED = "<pretrained>"
"""``encoder.weights`` placeholder: the experiment's pre-trained encoder, ``<experiment folder>/encoder/encoder.pt``."""

RUN_COLUMNS = ("experiment", "configuration", "label", "seed")
"""The columns that name the run, first in every table."""


def run_identity(document: Mapping[str, Any]) -> dict[str, Any]:
    """A spec's dict without what does not change the run: the protocol's ``seeds``, the number of runs of the experiment.

    Two spec dicts name the same run when their identities are equal, so adding seeds to an experiment
    (``crowdnav benchmark --seeds N``) leaves its finished runs alone.
    """
    protocol = {key: value for key, value in dict(document.get("protocol") or {}).items() if key != "seeds"}
    return {**document, "protocol": protocol}


@dataclass(frozen=True)
class UnitSpec:
    """Everything that defines one run; two runs with equal specs are the same run."""

    experiment: str
    configuration: str
    seed: int
    train: dict[str, Any]
    """TrainConfig fields of the configuration (without those of :data:`PROTOCOL_FIELDS`)."""
    protocol: dict[str, int]
    """The :class:`Protocol` fields."""
    label: str = ""
    """Name of the configuration in figures and tables (default: the configuration name)."""
    torch_threads: int = field(default=1, compare=False)
    """torch threads of the process (not part of the run's identity)."""
    config: TrainConfig | None = field(default=None, compare=False, repr=False)
    """``train`` already validated as a TrainConfig (by the experiment file's loader), or None: :func:`run_unit` validates it."""

    def to_dict(self) -> dict[str, Any]:
        return {item.name: getattr(self, item.name) for item in dataclasses.fields(self) if item.name not in ("torch_threads", "config")}

    @classmethod
    def from_dict(cls, document: Mapping[str, Any]) -> UnitSpec:
        return cls(**document)

    @property
    def display_label(self) -> str:
        return self.label or self.configuration

    def train_config(self, out_dir: Path) -> dict[str, Any]:
        """The full TrainConfig mapping of this run, writing into ``out_dir/train``."""
        train = dict(self.train)
        if train.get("encoder", {}).get("weights") == PRETRAINED:
            train["encoder"] = {**train["encoder"], "weights": self._encoder_weights(out_dir)}
        return {**train, **self._protocol_fields(out_dir)}

    def config_for(self, out_dir: Path) -> TrainConfig:
        """This run's :class:`~crowdnav.agents.training.config.TrainConfig`: :attr:`config` completed (no second validation),
        or ``train`` validated here when the spec came without it (a dict from a worker process, a test)."""
        if self.config is None:
            from crowdnav.agents.training.config import config_from_mapping

            return config_from_mapping(self.train_config(out_dir), f"{out_dir / SPEC_FILE}")
        update = self._protocol_fields(out_dir)
        if self.config.encoder.weights == PRETRAINED:
            update["encoder"] = self.config.encoder.model_copy(update={"weights": self._encoder_weights(out_dir)})
        # the protocol's values were checked by Protocol, the rest when the config was built
        return self.config.model_copy(update=update)

    def _protocol_fields(self, out_dir: Path) -> dict[str, Any]:
        protocol = Protocol(**self.protocol)
        if protocol.unit == "steps":  # episodes and checkpoint_every stay at their defaults: training ignores them then
            budget = {"timesteps": protocol.train_steps, "checkpoint_every_steps": protocol.eval_every_steps}
        else:
            budget = {"episodes": protocol.train_episodes, "checkpoint_every": protocol.eval_every}
        return {"seed": self.seed, "out": str(out_dir / TRAIN_DIR), **budget, "progress": False, "torch_threads": self.torch_threads,
                "save_replay_buffer": True}

    @staticmethod
    def _encoder_weights(out_dir: Path) -> str:
        return str(pretrained_encoder_path(experiment_of(out_dir)))
