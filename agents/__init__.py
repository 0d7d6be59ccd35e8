"""crowdnav's agents: a shared multi-modal latent, Stable-Baselines3 algorithms on top of it,
LEOG encoder pre-training, training counted in episodes, and checkpoints loadable as policies.

The subpackages, by concept: ``training`` (the config, seed rules, algorithm seam, env wrappers
and ``train`` itself), ``networks`` (the latent's encoders and their pre-training), ``sb3``
(Stable-Baselines3 under crowdnav), ``runs`` (a run's folder, log, checkpoints and resume state,
and what is made of them), ``imitation`` (demonstrations), ``marl`` (shared robot PPO) and
``sarl`` (a value-network agent outside SB3). :mod:`crowdnav.agents.legacy` keeps the module
paths of the flat layout before them importable, for the files that name them.

The names below are imported on first use (PEP 562), so that ``import agents`` (and the
``crowdnav`` command line) does not load torch until it is needed.
"""

from __future__ import annotations

from crowdnav.agents import legacy

from crowdnav.lazy_exports import lazy_exports

legacy.install()

_EXPORTS = {
    "train": "crowdnav.agents.training.run",
    "TrainResult": "crowdnav.agents.training.run",
    "TrainConfig": "crowdnav.agents.training.config",
    "ExtractorConfig": "crowdnav.agents.training.config",
    "EncoderConfig": "crowdnav.agents.training.config",
    "ConfigError": "crowdnav.agents.training.config",
    "load_config": "crowdnav.agents.training.config",
    "load_policy": "crowdnav.agents.runs.checkpoint",
    "train_robots": "crowdnav.agents.marl.robots",
    "load_robots_policy": "crowdnav.agents.marl.robots",
    "RobotsPolicy": "crowdnav.agents.marl.robots",
    "AgentPolicy": "crowdnav.agents.runs.checkpoint",
    "MultiModalExtractor": "crowdnav.agents.networks.extractor",
    "register_encoder": "crowdnav.agents.networks.extractor",
    "GaussianRBF": "crowdnav.agents.networks.rbf",
    "LeogEncoder": "crowdnav.agents.networks.encoders",
    "LeogAutoencoder": "crowdnav.agents.networks.encoders",
    "GridDataset": "crowdnav.agents.networks.dataset",
    "collect_grids": "crowdnav.agents.networks.dataset",
    "save_dataset": "crowdnav.agents.networks.dataset",
    "load_dataset": "crowdnav.agents.networks.dataset",
    "pretrain_encoder": "crowdnav.agents.networks.pretrain",
    "load_encoder": "crowdnav.agents.networks.pretrain",
    "LeogLatentWrapper": "crowdnav.agents.training.wrappers",
    "NormalizeObservation": "crowdnav.agents.training.wrappers",
    "train_seed": "crowdnav.agents.training.seeding",
    "dataset_seed": "crowdnav.agents.training.seeding",
    "demonstration_seed": "crowdnav.agents.training.seeding",
    "DemonstrationConfig": "crowdnav.agents.training.config",
    "Demonstrations": "crowdnav.agents.imitation.cloning",
    "collect_demonstrations": "crowdnav.agents.imitation.demonstrations",
    "behaviour_cloning": "crowdnav.agents.imitation.cloning",
    "warm_start": "crowdnav.agents.imitation.demonstrations",
    "ALGORITHMS": "crowdnav.agents.sb3.factory",
    "make_env": "crowdnav.agents.sb3.factory",
    "make_model": "crowdnav.agents.sb3.factory",
}

__all__ = sorted(_EXPORTS)

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
