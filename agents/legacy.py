"""The module paths crowdnav.agents had before its subpackages, still importable (as the modules they became).

Files written before the move name classes by module path, and unpickling them imports that path:
Stable-Baselines3's ``model.zip`` cloudpickles ``policy_kwargs`` (``features_extractor_class``:
``crowdnav.agents.extractor.MultiModalExtractor``), ``policy_class`` (the policies of
``crowdnav.agents.algorithms``, the per-kind robot policy of ``crowdnav.agents.marl_networks``) and
``replay_buffer_class`` (``crowdnav.agents.replay_buffer``), read by ``<Algo>.load`` and by trusted loads
of older checkpoints, whose pickled replay buffers name the same module. crowdnav's own files (JSON,
``.npz``, tensors) name no module.

:data:`MOVED` maps each old path to its module now; :func:`install` (run once by ``crowdnav.agents``)
appends a finder to :data:`sys.meta_path` (:class:`crowdnav.legacy_paths.LegacyPaths`, which also serves
the core's moved modules) that answers an old path with the new module itself: one module object under
both names, so a class unpickled by its old path is the class. Nothing is imported until an old path is.
Code imports the new paths (tests/agents/test_legacy_paths.py checks both).

Not covered: ``crowdnav.agents.marl`` and ``crowdnav.agents.training`` were modules and are now
subpackages (their code is :mod:`crowdnav.agents.marl.robots` and :mod:`crowdnav.agents.training.run`);
no saved file names either.
"""

from __future__ import annotations

from crowdnav import legacy_paths

MOVED: dict[str, str] = {
    "crowdnav.agents.batch_cache": "crowdnav.agents.networks.batch_cache",
    "crowdnav.agents.rbf": "crowdnav.agents.networks.rbf",
    "crowdnav.agents.encoders": "crowdnav.agents.networks.encoders",
    "crowdnav.agents.extractor": "crowdnav.agents.networks.extractor",
    "crowdnav.agents.network_size": "crowdnav.agents.networks.size",
    "crowdnav.agents.dataset": "crowdnav.agents.networks.dataset",
    "crowdnav.agents.pretrain": "crowdnav.agents.networks.pretrain",
    "crowdnav.agents.sb3_algorithm": "crowdnav.agents.sb3.algorithm",
    "crowdnav.agents.sb3_internals": "crowdnav.agents.sb3.internals",
    "crowdnav.agents.algorithms": "crowdnav.agents.sb3.algorithms",
    "crowdnav.agents.algorithm_kinds": "crowdnav.agents.sb3.kinds",
    "crowdnav.agents.callbacks": "crowdnav.agents.sb3.callbacks",
    "crowdnav.agents.replay_buffer": "crowdnav.agents.sb3.replay_buffer",
    "crowdnav.agents.vec_env": "crowdnav.agents.sb3.vec_env",
    "crowdnav.agents.model_zip": "crowdnav.agents.sb3.model_zip",
    "crowdnav.agents.training_session": "crowdnav.agents.sb3.session",
    "crowdnav.agents.factory": "crowdnav.agents.sb3.factory",
    "crowdnav.agents.checkpoint": "crowdnav.agents.runs.checkpoint",
    "crowdnav.agents.run_folder": "crowdnav.agents.runs.folder",
    "crowdnav.agents.episode_log": "crowdnav.agents.runs.episode_log",
    "crowdnav.agents.resume_point": "crowdnav.agents.runs.resume_point",
    "crowdnav.agents.resume_state": "crowdnav.agents.runs.resume_state",
    "crowdnav.agents.resume_worlds": "crowdnav.agents.runs.resume_worlds",
    "crowdnav.agents.train_result": "crowdnav.agents.runs.result",
    "crowdnav.agents.onnx_export": "crowdnav.agents.runs.onnx_export",
    "crowdnav.agents.render": "crowdnav.agents.runs.render",
    "crowdnav.agents.cloning": "crowdnav.agents.imitation.cloning",
    "crowdnav.agents.demonstrations": "crowdnav.agents.imitation.demonstrations",
    "crowdnav.agents.marl_actions": "crowdnav.agents.marl.actions",
    "crowdnav.agents.marl_env": "crowdnav.agents.marl.env",
    "crowdnav.agents.marl_networks": "crowdnav.agents.marl.networks",
    "crowdnav.agents.marl_resume": "crowdnav.agents.marl.resume",
    "crowdnav.agents.marl_vec_env": "crowdnav.agents.marl.vec_env",
    "crowdnav.agents.config": "crowdnav.agents.training.config",
    "crowdnav.agents.seeding": "crowdnav.agents.training.seeding",
    "crowdnav.agents.space_checks": "crowdnav.agents.training.space_checks",
    "crowdnav.agents.algorithm_protocol": "crowdnav.agents.training.algorithm_protocol",
    "crowdnav.agents.protocol_training": "crowdnav.agents.training.episode_loop",
    "crowdnav.agents.training_checks": "crowdnav.agents.training.checks",
    "crowdnav.agents.wrappers": "crowdnav.agents.training.wrappers",
}
"""Old module path -> the module it is now."""


def install() -> None:
    """Put the finder for :data:`MOVED` on :data:`sys.meta_path` once, after the others (:func:`crowdnav.legacy_paths.install`)."""
    legacy_paths.install(MOVED)
