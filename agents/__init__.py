"""crowdnav's agents: a shared multi-modal latent, Stable-Baselines3 algorithms on top of it,
LEOG encoder pre-training, training counted in episodes, and checkpoints loadable as policies.

The names below are imported on first use (PEP 562), so that ``import agents`` (and the
``crowdnav`` command line) does not load torch until it is needed.
"""

from __future__ import annotations

from crowdnav.lazy_exports import lazy_exports

_EXPORTS = {
    "train": "crowdnav.agents.training",
    "TrainResult": "crowdnav.agents.training",
    "TrainConfig": "crowdnav.agents.config",
    "ExtractorConfig": "crowdnav.agents.config",
    "EncoderConfig": "crowdnav.agents.config",
    "ConfigError": "crowdnav.agents.config",
    "load_config": "crowdnav.agents.config",
    "load_policy": "crowdnav.agents.checkpoint",
    "train_robots": "crowdnav.agents.marl",
    "load_robots_policy": "crowdnav.agents.marl",
    "RobotsPolicy": "crowdnav.agents.marl",
    "AgentPolicy": "crowdnav.agents.checkpoint",
    "MultiModalExtractor": "crowdnav.agents.extractor",
    "register_encoder": "crowdnav.agents.extractor",
    "GaussianRBF": "crowdnav.agents.rbf",
    "LeogEncoder": "crowdnav.agents.encoders",
    "LeogAutoencoder": "crowdnav.agents.encoders",
    "GridDataset": "crowdnav.agents.dataset",
    "collect_grids": "crowdnav.agents.dataset",
    "save_dataset": "crowdnav.agents.dataset",
    "load_dataset": "crowdnav.agents.dataset",
    "pretrain_encoder": "crowdnav.agents.pretrain",
    "load_encoder": "crowdnav.agents.pretrain",
    "LeogLatentWrapper": "crowdnav.agents.wrappers",
    "NormalizeObservation": "crowdnav.agents.wrappers",
    "train_seed": "crowdnav.agents.seeding",
    "dataset_seed": "crowdnav.agents.seeding",
    "demonstration_seed": "crowdnav.agents.seeding",
    "DemonstrationConfig": "crowdnav.agents.config",
    "Demonstrations": "crowdnav.agents.cloning",
    "collect_demonstrations": "crowdnav.agents.demonstrations",
    "behaviour_cloning": "crowdnav.agents.cloning",
    "warm_start": "crowdnav.agents.demonstrations",
    "ALGORITHMS": "crowdnav.agents.factory",
    "make_env": "crowdnav.agents.factory",
    "make_model": "crowdnav.agents.factory",
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
