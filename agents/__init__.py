"""crowdnav's agents: a shared multi-modal latent, Stable-Baselines3 algorithms on top of it,
LEOG encoder pre-training, training counted in episodes, and checkpoints loadable as policies.

The names below are imported on first use (PEP 562), so that ``import agents`` (and the
``crowdnav`` command line) does not load torch until it is needed.
"""

from __future__ import annotations

from crowdnav.lazy_exports import lazy_exports

_EXPORTS = {
    "train": "agents.training",
    "TrainResult": "agents.training",
    "TrainConfig": "agents.config",
    "ExtractorConfig": "agents.config",
    "EncoderConfig": "agents.config",
    "ConfigError": "agents.config",
    "load_config": "agents.config",
    "load_policy": "agents.checkpoint",
    "AgentPolicy": "agents.checkpoint",
    "MultiModalExtractor": "agents.extractor",
    "register_encoder": "agents.extractor",
    "GaussianRBF": "agents.rbf",
    "LeogEncoder": "agents.encoders",
    "LeogAutoencoder": "agents.encoders",
    "GridDataset": "agents.dataset",
    "collect_grids": "agents.dataset",
    "save_dataset": "agents.dataset",
    "load_dataset": "agents.dataset",
    "pretrain_encoder": "agents.pretrain",
    "load_encoder": "agents.pretrain",
    "LeogLatentWrapper": "agents.wrappers",
    "NormalizeObservation": "agents.wrappers",
    "train_seed": "agents.wrappers",
    "dataset_seed": "agents.wrappers",
    "ALGORITHMS": "agents.factory",
    "make_env": "agents.factory",
    "make_model": "agents.factory",
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
