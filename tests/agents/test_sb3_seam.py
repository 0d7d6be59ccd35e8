"""The SB3 algorithms through the algorithm seam: the same registry lookups pick the trainer, the checkpoint reader
and the ONNX module for them and for an algorithm outside SB3 (tests/agents/toy_algorithm.py); an SB3 algorithm is
one registry entry."""

from __future__ import annotations

import csv
from dataclasses import replace

import numpy as np
import pytest

from crowdnav.registry import ALGORITHM_SPECS, AlgorithmSpec, algorithm_names, register_algorithm, unregister_algorithm
from tests.agents.agents_tiny import recorded_observations, tiny_config
from tests.agents.toy_algorithm import SPEC, RandomSearchAgent

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")


@pytest.fixture
def registered():
    """Registers name -> spec for the test, and removes them after it."""
    names = []

    def register(name, spec):
        register_algorithm(name, spec)
        names.append(name)

    yield register
    for name in names:
        unregister_algorithm(name)


def toy_config(out, **fields):
    config = {"algo": "random_search", "scenario": "open_space", "modalities": ["goal"], "num_envs": 1, "episodes": 4,
              "seed": 0, "out": str(out), "overrides": {"max_steps": 40, "humans.count": 0}, "checkpoint_every": 2,
              "progress": False, "algo_kwargs": {"step_size": 0.005, "noise": 0.3}}
    return {**config, **fields}


def ppo_config(out, algo="ppo", **fields):
    """PPO on goal and velocity in an empty room: a few 40-step episodes, an update every 16 steps."""
    config = tiny_config(out, algo=algo, modalities=("goal", "velocity"), episodes=4, max_steps=40, checkpoint_every=2,
                         batch_size=16, algo_kwargs={"n_steps": 16, "n_epochs": 1})
    config["overrides"] = {"max_steps": 40, "humans.count": 0}
    return {**config, **fields}


def rows(run):
    with open(run / "episodes.csv", encoding="utf-8") as file:
        return [{key: value for key, value in row.items() if key != "seconds"} for row in csv.DictReader(file)]


def test_every_algorithm_gets_its_trainer_from_its_registered_builder(registered):
    from crowdnav.agents.sb3.algorithm import SB3_BUILDER
    from crowdnav.agents.training.algorithm_protocol import RunTrainer, builder_of
    from crowdnav.agents.training.config import config_from_mapping
    from crowdnav.agents.training.episode_loop import train_registered
    from crowdnav.agents.training.run import trainer_of

    registered("random_search", SPEC)
    for name in algorithm_names():
        trainer = trainer_of(config_from_mapping(toy_config("unused", algo=name, algo_kwargs={})))
        builder = builder_of(name)
        if ALGORITHM_SPECS[name].sb3:  # SB3's own loop (exact resume): the builder's train_run
            assert builder is SB3_BUILDER and isinstance(builder, RunTrainer) and trainer.args == (SB3_BUILDER,)
        else:  # sarl and the toy: crowdnav's episode loop around the agent's learn
            assert not isinstance(builder, RunTrainer) and trainer is train_registered
    assert builder_of("random_search") is RandomSearchAgent


def test_a_spec_without_a_builder_is_refused_in_one_line(registered):
    from crowdnav.agents.training.config import ConfigError, config_from_mapping
    from crowdnav.agents.training.run import trainer_of

    registered("nameonly", AlgorithmSpec("A name without a builder."))
    with pytest.raises(ConfigError, match="^algo: algorithm 'nameonly' has no builder: it cannot be trained or loaded$"):
        trainer_of(config_from_mapping(toy_config("unused", algo="nameonly")))


def test_an_sb3_algorithm_is_one_registry_entry_and_trains_bit_for_bit_as_the_built_in_one(tmp_path, registered):
    from crowdnav.agents import load_policy, train
    from crowdnav.agents.sb3.algorithm import SB3Algorithm
    from crowdnav.agents.sb3.factory import hyperparameters, model_class

    registered("ppo_again", replace(ALGORITHM_SPECS["ppo"], description="PPO once more, registered by a test."))
    assert model_class("ppo_again") is model_class("ppo")
    built_in, again = train(ppo_config(tmp_path / "ppo")), train(ppo_config(tmp_path / "again", algo="ppo_again"))
    assert rows(tmp_path / "ppo") == rows(tmp_path / "again") and len(rows(tmp_path / "ppo")) == 4
    for left, right in zip(built_in.model.policy.parameters(), again.model.policy.parameters(), strict=True):
        assert left.detach().numpy().tobytes() == right.detach().numpy().tobytes()
    policy = load_policy(tmp_path / "again")  # the checkpoint reader is the builder's, as for "ppo"
    assert isinstance(policy.agent, SB3Algorithm) and policy.model is policy.agent.model
    from crowdnav.agents.training.config import config_from_mapping

    assert hyperparameters(config_from_mapping(ppo_config("x", algo="ppo_again"))) == hyperparameters(config_from_mapping(ppo_config("x")))


def test_an_sb3_algorithm_trains_in_crowdnavs_episode_loop_like_the_toy_and_loads_and_exports_alike(tmp_path, registered):
    """The builder without a loop of its own (SB3Builder): the same train_registered, load_agent and export_module as the toy."""
    from crowdnav.agents import load_policy, train
    from crowdnav.agents.runs.onnx_export import actor_of
    from crowdnav.agents.sb3.algorithm import SB3Algorithm, SB3Builder
    from crowdnav.agents.training.seeding import train_seed

    registered("random_search", SPEC)
    registered("ppo_episodes", replace(ALGORITHM_SPECS["ppo"], description="PPO in crowdnav's episode loop.", builder=SB3Builder()))
    toy, sb3 = tmp_path / "toy", tmp_path / "sb3"
    train(toy_config(toy))
    result = train(ppo_config(sb3, algo="ppo_episodes"))
    assert result.episodes == 4 and isinstance(result.model, SB3Algorithm)
    for run in (toy, sb3):  # the same run folder: episodes seeded and logged by crowdnav, snapshots, algorithm/ checkpoint
        assert [int(row["seed"]) for row in rows(run)] == [train_seed(0, episode) for episode in range(4)]
        assert sorted(path.name for path in (run / "snapshots").iterdir()) == ["episode_00002", "episode_00004"]
    files = sorted(path.relative_to(sb3 / "checkpoint").as_posix() for path in (sb3 / "checkpoint").rglob("*") if path.is_file())
    assert files == ["algorithm/model.zip", "algorithm/sb3.json", "policy.json"]
    policy = load_policy(sb3)  # builder.load(checkpoint/algorithm): the tensors, no pickle
    assert isinstance(policy.agent, SB3Algorithm) and isinstance(load_policy(toy).agent, RandomSearchAgent)
    observations = recorded_observations(policy, steps=10)
    expected = result.model.predict(policy.preprocess(observations))[0]
    np.testing.assert_array_equal(policy(observations), expected)
    import torch

    module = actor_of(policy, list(observations), sb3).eval()  # the agent's export_module, as sarl's
    with torch.no_grad():
        traced = module(*(torch.as_tensor(value) for value in policy.preprocess(observations).values()))
    np.testing.assert_allclose(traced.numpy(), expected, atol=1e-6)
    resumed = train(ppo_config(sb3, algo="ppo_episodes", episodes=6), resume=True)  # a close resume: weights and optimisers
    assert resumed.episodes == 6 and [int(row["episode"]) for row in rows(sb3)] == list(range(6))
