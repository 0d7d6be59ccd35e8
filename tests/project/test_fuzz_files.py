"""Property-based fuzzing: mutated scenario, training-config and experiment files either fail with
one clean error naming the file and the field, or give a world that resets and steps with finite
values. A few dozen cases per kind run in the default suite; ``-m slow`` runs thousands.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from crowdnav.agents.training.config import ConfigError, load_config
from crowdnav.evaluation.experiment import EXPERIMENTS_DIR, ExperimentError, load_experiment
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from crowdnav import CrowdNavParallelEnv, ScenarioError, SimulationError
from crowdnav.scenario.library import library_dir, library_names
from crowdnav.worlds.placement import PlacementError

VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.integers(), st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-20, 20), st.text(max_size=8), st.lists(st.floats(-20, 20), max_size=3), st.just([]), st.just({}),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)


def _paths(node, prefix=()):
    """Every path to a value in a YAML document (dict keys and list indices)."""
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, (*prefix, key))
    elif isinstance(node, list):
        for index, value in enumerate(node):
            yield from _paths(value, (*prefix, index))


@st.composite
def mutated(draw, documents):
    name = draw(st.sampled_from(sorted(documents)))
    document = copy.deepcopy(documents[name])
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(document) if p]
        path = draw(st.sampled_from(paths))
        parent = document
        for part in path[:-1]:
            parent = parent[part]
        action = draw(st.sampled_from(["set", "delete", "add"]))
        if action == "delete" and isinstance(parent, dict):
            del parent[path[-1]]
        elif action == "add" and isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=6))] = draw(VALUES)
        else:
            parent[path[-1]] = draw(VALUES)
    return name, document


SCENARIOS = {name: yaml.safe_load((library_dir() / f"{name}.yaml").read_text()) for name in library_names()}
EXPERIMENTS = {path.stem: yaml.safe_load(path.read_text()) for path in sorted(Path(EXPERIMENTS_DIR).glob("*.yaml"))}
TRAIN = {"train": {"scenario": "open_space", "modalities": ["lidar", "goal"], "algo": "sac", "episodes": 10, "net_arch": [64, 64],
                   "overrides": {"humans.count": 3}, "reward_weights": {"preset": "default"}, "encoder": {"mode": "scratch"}}}


def _one_clean_line(error: Exception, path: Path) -> None:
    message = str(error)
    assert str(path) in message, message
    first = message.splitlines()[0]
    assert ": " in first[len(str(path)):], message  # FILE[:LINE]: field: expectation


def check_scenario(document, tmp_path: Path) -> None:
    path = tmp_path / "fuzzed.yaml"
    path.write_text(yaml.safe_dump(document))
    try:
        env = CrowdNavParallelEnv(str(path), modalities=["goal", "lidar", "closest_obstacle"])
    except ScenarioError as error:
        _one_clean_line(error, path)
        return
    for seed in (0, 1):
        observations, _ = env.reset(seed=seed)  # validation accepted it: every seed must reset
        for _ in range(5):
            if not env.agents:
                break
            actions = {agent: env.action_space(agent).sample() for agent in env.agents}
            observations, rewards, *_ = env.step(actions)
            assert all(np.isfinite(value).all() for value in observations["robot"].values()) if "robot" in observations else True
            assert all(np.isfinite(reward) for reward in rewards.values())


def check_file(load, error_type, document, tmp_path: Path) -> None:
    path = tmp_path / "fuzzed.yaml"
    path.write_text(yaml.safe_dump(document))
    try:
        load(path)
    except error_type as error:
        _one_clean_line(error, path)


FAST = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
LONG = settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@FAST
@given(case=mutated(SCENARIOS))
def test_mutated_scenarios_fail_cleanly_or_reset_and_step_finite(tmp_path, case):
    check_scenario(case[1], tmp_path)


@FAST
@given(case=mutated(TRAIN))
def test_mutated_training_configs_fail_cleanly_or_load(tmp_path, case):
    check_file(load_config, ConfigError, case[1], tmp_path)


@FAST
@given(case=mutated(EXPERIMENTS))
def test_mutated_experiment_files_fail_cleanly_or_load(tmp_path, case):
    check_file(load_experiment, ExperimentError, case[1], tmp_path)


@pytest.mark.slow
@LONG
@given(case=mutated(SCENARIOS))
def test_many_mutated_scenarios_fail_cleanly_or_reset_and_step_finite(tmp_path, case):
    check_scenario(case[1], tmp_path)


@pytest.mark.slow
@LONG
@given(case=mutated(EXPERIMENTS))
def test_many_mutated_experiment_files_fail_cleanly_or_load(tmp_path, case):
    check_file(load_experiment, ExperimentError, case[1], tmp_path)


_ = (SimulationError, PlacementError)  # the errors a failure here would surface as


ACTIONS = st.one_of(
    st.none(), st.text(max_size=4), st.floats(allow_nan=True, allow_infinity=True), st.complex_numbers(max_magnitude=5),
    st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-5, 5), st.booleans(), st.text(max_size=2),
                       st.complex_numbers(max_magnitude=5)), max_size=4),
    st.lists(st.lists(st.floats(-2, 2), max_size=3), max_size=3),
)


@FAST
@given(action=ACTIONS)
def test_fuzzed_actions_step_or_fail_with_one_clear_line_in_both_envs(action):
    import gymnasium as gym

    single = gym.make("crowdnav/OpenSpace-v0", modalities=["goal"]).unwrapped
    single.reset(seed=0)
    parallel = CrowdNavParallelEnv("open_space", modalities=["goal"])
    parallel.reset(seed=0)
    for step in (lambda: single.step(action),
                 lambda: parallel.step({agent: action if agent in ("robot", "human_0") else np.zeros(2) for agent in parallel.agents})):
        try:
            step()
        except (ValueError, TypeError) as error:
            message = str(error)
            assert message and "\n" not in message and "Traceback" not in message
