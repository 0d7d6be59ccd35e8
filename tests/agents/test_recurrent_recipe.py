"""docs/architecture.md's recipe "Adding a recurrent agent", followed: a toy agent with a memory (tests/agents/toy_recurrent.py)
registered through the algorithm seam trains through ``crowdnav train``, and ``crowdnav evaluate``, ``crowdnav render`` and
``crowdnav export`` carry its state per world and start it afresh with each episode, as a loop written by hand does."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import yaml

from crowdnav.cli import main
from crowdnav.registry import register_algorithm, unregister_algorithm
from tests.agents.toy_recurrent import SPEC, RunningMeanAgent

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

CONFIG = {"algo": "running_mean", "scenario": "open_space", "modalities": ["goal", "velocity"], "num_envs": 2, "episodes": 8, "seed": 0,
          "overrides": {"max_steps": 30, "humans.count": 4}, "checkpoint_every": 4, "progress": False,
          "algo_kwargs": {"step_size": 0.05, "noise": 0.5}}
"""A few humans, so that test episodes end at different steps (a batch's rows must stay its worlds)."""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A run of the registered toy, trained through the command line on 2 worlds (the algorithm stays registered for the module)."""
    register_algorithm("running_mean", SPEC)
    folder = tmp_path_factory.mktemp("recurrent_recipe")
    path = folder / "toy.yaml"
    path.write_text(yaml.safe_dump({**CONFIG, "out": str(folder / "run")}), encoding="utf-8")
    assert main(["train", "--config", str(path)]) == 0
    yield folder / "run"
    unregister_algorithm("running_mean")


def played_by_hand(policy, env, seed, *, memory=True):
    """The reference loop: one env, the state returned given back at the next step, the episode's start flagged once
    (``memory=False``: the state dropped at every step). (actions, outcome, steps, return)."""
    observation, _ = env.reset(seed=seed)
    state, start, actions, total = None, np.array([True]), [], 0.0
    while True:
        action, state = policy.predict({key: np.asarray(value)[None] for key, value in observation.items()}, state if memory else None, start)
        start = np.array([False])
        actions.append(action[0])
        observation, reward, terminated, truncated, info = env.step(action[0])
        total += float(reward)
        if terminated or truncated:
            return np.stack(actions), info["outcome"], len(actions), total


def test_a_registered_recurrent_agent_trains_through_crowdnav_train_and_loads_as_recurrent(run):
    from crowdnav.agents import load_policy
    from crowdnav.agents.runs.checkpoint import RecurrentPolicyError

    with open(run / "episodes.csv", encoding="utf-8") as file:
        assert [int(row["episode"]) for row in csv.DictReader(file)] == list(range(8))
    files = sorted(path.relative_to(run / "checkpoint").as_posix() for path in (run / "checkpoint").rglob("*") if path.is_file())
    assert files == ["algorithm/state.json", "algorithm/weights.npz", "policy.json"]  # arrays and JSON: no memory, no pickle
    policy = load_policy(run)
    assert isinstance(policy.model, RunningMeanAgent) and policy.recurrent and np.any(policy.model.weights != 0)
    observation, _ = policy.make_env().reset(seed=0)
    with pytest.raises(RecurrentPolicyError, match="carries a state between steps"):
        policy(observation)  # a call would drop the memory: refused


def test_the_agents_memory_changes_its_actions_and_an_episode_start_forgets_it(run):
    from crowdnav.agents import load_policy

    policy = load_policy(run)
    observation, _ = policy.make_env().reset(seed=1)
    batch = {key: np.repeat(np.asarray(value)[None], 2, axis=0) for key, value in observation.items()}
    first, state = policy.predict(batch, None, np.array([True, True]))
    kept = state.copy()
    _, later = policy.predict({key: value + 1.0 for key, value in batch.items()}, state, np.array([False, False]))
    np.testing.assert_array_equal(state, kept)  # the state is the caller's: predict returns a new one
    again, _ = policy.predict(batch, later, np.array([False, True]))
    assert np.array_equal(again[1], first[1]) and not np.array_equal(again[0], first[0])  # row 1 starts afresh, row 0 remembers


def test_crowdnav_evaluate_carries_the_state_per_world_and_starts_each_episode_afresh(run, tmp_path):
    from crowdnav.agents import load_policy

    from crowdnav.envs import CrowdNavEnv

    assert main(["evaluate", str(run), "--scenario", "open_space", "--episodes", "6", "--out", str(tmp_path), "--no-progress"]) == 0
    table = next(tmp_path.glob("evaluate/*/seeds_0-5/test_episodes.csv"))
    with open(table, encoding="utf-8") as file:
        rows = list(csv.DictReader(file))
    env = CrowdNavEnv(**json.loads((table.parent / "meta.json").read_text(encoding="utf-8"))["env"])
    policy = load_policy(run)
    expected = [played_by_hand(policy, env, seed) for seed in range(6)]
    assert [(row["outcome"], int(row["steps"]), row["return"]) for row in rows] == [
        (outcome, steps, repr(total)) for _, outcome, steps, total in expected]
    assert len({steps for _, _, steps, _ in expected}) > 1  # the episodes end at different steps: rows that shifted would show
    forgetful = [played_by_hand(policy, env, seed, memory=False)[3] for seed in range(6)]
    assert [repr(total) for total in forgetful] != [row["return"] for row in rows]  # the memory matters: a dropped state would show


def recorded_actions(monkeypatch) -> list[list[np.ndarray]]:
    """The actions the env of ``render_episodes`` is given, one list per episode (filled as it plays)."""
    import crowdnav.rendering.episodes as episodes

    played: list[list[np.ndarray]] = []

    class Recorded(episodes.CrowdNavEnv):
        def reset(self, **kwargs):
            played.append([])
            return super().reset(**kwargs)

        def step(self, action):
            played[-1].append(np.array(action))
            return super().step(action)

    monkeypatch.setattr(episodes, "CrowdNavEnv", Recorded)
    return played


def assert_each_episode_from_a_fresh_memory(run, played):
    from crowdnav.agents import load_policy

    policy = load_policy(run)
    assert len(played) == 2
    for seed, actions in enumerate(played):  # episode 2 with episode 1's memory, or none, would act otherwise
        np.testing.assert_array_equal(np.stack(actions), played_by_hand(policy, policy.make_env(), seed)[0])


def test_rendering_carries_the_state_through_an_episode_and_forgets_it_at_the_next(run, tmp_path, monkeypatch):
    from crowdnav.agents.runs.render import render_policy

    played = recorded_actions(monkeypatch)
    paths = render_policy("open_space", str(run), episodes=2, out=tmp_path, progress=False, video_format="gif")
    assert len(paths) == 2 and all(path.stat().st_size > 0 for path in paths)
    assert_each_episode_from_a_fresh_memory(run, played)


def test_crowdnav_render_from_the_command_line_carries_the_state_too(run, tmp_path, monkeypatch):
    played = recorded_actions(monkeypatch)
    argv = ["render", "open_space", "--policy", str(run), "--episodes", "2", "--format", "gif", "--out", str(tmp_path), "--no-progress"]
    assert main(argv) == 0
    assert len(list(tmp_path.glob("open_space_run_seed[01]_*.gif"))) == 2
    assert_each_episode_from_a_fresh_memory(run, played)


def test_crowdnav_export_writes_the_state_into_the_graph_and_out_of_it(run, tmp_path):
    ort = pytest.importorskip("onnxruntime")
    from crowdnav.agents import load_policy
    from crowdnav.agents.runs.onnx_export import EPISODE_START_INPUT

    assert main(["export", str(run), "--out", str(tmp_path / "policy.onnx")]) == 0
    session = ort.InferenceSession(str(tmp_path / "policy.onnx"), providers=["CPUExecutionProvider"])
    assert [i.name for i in session.get_inputs()][-2:] == ["memory", EPISODE_START_INPUT]
    assert [o.name for o in session.get_outputs()] == ["action", "next_memory"]
    policy = load_policy(run)
    size = sum(int(np.prod(shape)) for shape in policy.model.shapes.values()) + 1  # the observation's sum and the count
    assert json.loads(session.get_modelmeta().custom_metadata_map["crowdnav.state"]) == {"memory": [1, 1, size]}
    envs = [policy.make_env() for _ in range(2)]
    observations = [env.reset(seed=seed)[0] for env, seed in zip(envs, (3, 4), strict=True)]
    state, memory = None, np.zeros((1, 2, size), np.float32)
    for step in range(20):
        start = np.array([step == 0, step in (0, 10)])  # world 1 is told a new episode begins at step 10
        batch = {key: np.stack([o[key] for o in observations]) for key in observations[0]}
        expected, state = policy.predict(batch, state, start)
        action, memory = session.run(None, {**batch, "memory": memory, EPISODE_START_INPUT: start.astype(np.float32)})
        np.testing.assert_allclose(action, expected, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(memory, state, rtol=1e-5, atol=1e-5)
        observations = [env.step(a)[0] for env, a in zip(envs, expected, strict=True)]
