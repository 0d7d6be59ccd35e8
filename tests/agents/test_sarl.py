"""The SARL-style agent (``algo: sarl``, crowdnav/agents/sarl/): its lookahead from the observation, acting on one or
many observations, checkpoints without pickle, an exact resume, evaluation of its run and that V-learning learns."""

from __future__ import annotations

import csv

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

torch = pytest.importorskip("torch")

from crowdnav.agents.sarl.agent import SarlAgent  # noqa: E402
from crowdnav.agents.sarl.lookahead import Physics, action_set, decode, features, lookahead  # noqa: E402
from crowdnav.agents.sarl.network import evaluate  # noqa: E402

from crowdnav.scenario.library import library_names  # noqa: E402

PHYSICS = Physics(radius=0.3, max_speed=1.0, time_step=0.2, goal_radius=0.3, social_strength=2.0, social_range=0.3,
                  weights={"step": -0.1, "goal_progress": 5.0, "social": -1.0, "goal_reached": 25.0, "collision": -25.0})
EMPTY = {"humans.count": 0, "max_steps": 30, "robot.start": {"type": "points", "points": [[0.0, 0.0]]},
         "robot.goal": {"type": "points", "points": [[1.4, 0.0]]}, "robot.start_heading": 90,
         "robot.min_start_goal_distance": 1.0}


def observation(goal=(4.0, 0.0), velocity=(0.0, 0.0), humans=()):
    """A raw observation (robot frame): goal cartesian, humans as (x, y, vx, vy) absolute velocities."""
    rows = np.zeros((5, 6), dtype=np.float32)
    for index, (x, y, vx, vy) in enumerate(humans):
        rows[index] = (x, y, vx - velocity[0], vy - velocity[1], 0.3, 1.0)
    return {"goal": np.asarray(goal, dtype=np.float32), "velocity": np.asarray(velocity, dtype=np.float32), "humans": rows}


def ahead(obs):
    return lookahead(decode({key: value[None] for key, value in obs.items()}, {}), PHYSICS, action_set(1.0))


def test_action_set_is_stop_then_five_speeds_times_sixteen_headings_up_to_the_max_speed():
    actions = action_set(1.2)
    speeds = np.round(np.hypot(actions[:, 0], actions[:, 1]), 9)
    assert actions.shape == (81, 2) and speeds[0] == 0.0 and speeds.max() == 1.2
    assert len(set(speeds[1:])) == 5 and np.allclose(actions[1], (speeds[1], 0.0))  # heading 0: toward the goal


def test_lookahead_predicts_progress_collision_and_goal_from_the_observation_alone():
    free = ahead(observation())
    full = 1 + 4 * 16  # the fastest action toward the goal (goal along the robot's x axis)
    assert free["reward"][0, full] == pytest.approx(-0.1 + 5.0 * 0.2)
    np.testing.assert_allclose(free["commands"][0, full], (1.0, 0.0), atol=1e-6)
    assert not free["done"].any()
    # a human 0.9 m ahead walking toward the robot at 1 m/s: moving toward it at full speed touches it within the step
    blocked = ahead(observation(humans=[(0.9, 0.0, -1.0, 0.0)]))
    assert blocked["done"][0, full] and blocked["reward"][0, full] < -0.1 + 1.0 - 25.0
    assert not blocked["done"][0, 0]  # stopping does not touch it (0.9 - 0.2 > 0.6)
    # the social term: the next positions' repulsion costs something without a collision
    assert blocked["reward"][0, 0] < -0.1
    near_goal = ahead(observation(goal=(0.32, 0.0)))  # the slowest move covers 0.025 m
    assert near_goal["done"][0, 1] and near_goal["reward"][0, 1] > 24 and not near_goal["done"][0, 0]


def test_lookahead_rotates_with_the_goal_direction():
    """Heading 0 points at the goal whatever the robot frame: a goal to the left gives (0, 1) as the full-speed command."""
    result = ahead(observation(goal=(0.0, 3.0)))
    np.testing.assert_allclose(result["commands"][0, 1 + 4 * 16], (0.0, 1.0), atol=1e-6)


def config(out, **fields):
    document = {"algo": "sarl", "scenario": "open_space", "modalities": ["humans", "goal", "velocity"], "num_envs": 1,
                "episodes": 6, "seed": 0, "out": str(out), "overrides": {"humans.count": 3, "max_steps": 20},
                "checkpoint_every": 2, "progress": False,
                "algo_kwargs": {"batch_size": 16, "updates_per_episode": 3, "target_update_every": 2, "width": 16}}
    document.update(fields)
    return document


def rows(run):
    with open(run / "episodes.csv", encoding="utf-8") as file:
        return [{key: value for key, value in row.items() if key != "seconds"} for row in csv.DictReader(file)]


def test_predict_takes_one_observation_or_a_batch_and_agrees_between_them(tmp_path):
    from crowdnav.agents import load_policy, train

    train(config(tmp_path / "run", episodes=2))
    policy = load_policy(tmp_path / "run")
    env = policy.make_env()
    observations = []
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        observations.append(policy.preprocess(obs))
    single = np.stack([policy.model.predict(obs)[0] for obs in observations])
    batch = policy.model.predict({key: np.stack([obs[key] for obs in observations]) for key in observations[0]})[0]
    assert single.shape == (3, 2) and batch.shape == (3, 2) and single.dtype == np.float32
    np.testing.assert_allclose(batch, single, atol=1e-6)
    assert np.all(np.hypot(batch[:, 0], batch[:, 1]) <= 1.0 + 1e-6)


def test_depth_two_scores_the_best_one_step_actions_by_their_best_second_step(tmp_path):
    """lookahead_depth 2: each of the lookahead_width best one-step actions scores r1 + discount * max over a second step
    (r2 + discount * V), computed here action by action from the one-step lookahead; the others are never chosen."""
    from crowdnav.agents import load_policy, train

    train(config(tmp_path / "run", episodes=2))
    agent = load_policy(tmp_path / "run").model
    agent.scales = {}  # the raw observation below (cartesian goal), not the run's normalised one
    obs = observation(goal=(3.0, 1.0), velocity=(0.5, 0.0), humans=[(1.2, 0.3, -0.8, 0.0), (2.0, -1.0, 0.0, 0.9)])
    batch = {key: value[None] for key, value in obs.items()}
    one, _ = agent.scores(batch)
    agent.options.update(lookahead_depth=2, lookahead_width=5)
    two, commands = agent.scores(batch, depth=2)
    first = lookahead(decode(batch, agent.scales), agent.physics, agent.actions)
    best = np.argsort(-one[0], kind="stable")[:5]
    for action in range(81):
        if action not in best:
            assert two[0, action] == -np.inf
            continue
        state = {key: value[:, action] for key, value in first["next"].items()}
        further = lookahead(state, agent.physics, agent.actions)
        values = evaluate(agent.network, *features(further["next"], agent.physics))
        backup = (further["reward"] + agent.discount * values * ~further["done"]).max()
        expected = first["reward"][0, action] + (0.0 if first["done"][0, action] else agent.discount * backup)
        assert two[0, action] == pytest.approx(expected, rel=1e-6, abs=1e-9)
    assert np.argmax(two[0]) in best
    np.testing.assert_array_equal(agent.predict(obs)[0], commands[0, np.argmax(two[0])])  # greedy acting searches deeper
    agent.rng = np.random.default_rng(0)
    agent.options.update(epsilon_start=0.0, epsilon_end=0.0)  # no random action: the training-time choice
    np.testing.assert_array_equal(agent.act(obs, deterministic=False), commands[0, np.argmax(one[0])])  # one step


def test_save_and_load_round_trip_without_pickle(tmp_path):
    from crowdnav.agents import load_policy, train

    result = train(config(tmp_path / "run", episodes=3, algo_kwargs={**config("x")["algo_kwargs"], "imitation_episodes": 2}))
    agent = result.model
    folder = tmp_path / "saved"
    folder.mkdir()
    agent.save(folder)
    assert sorted(path.name for path in folder.iterdir()) == ["demonstrations.npz", "memory.npz", "state.json", "weights.npz"]
    for path in folder.glob("*.npz"):
        with np.load(path, allow_pickle=False) as arrays:  # raises on any object array
            assert all(arrays[key].dtype != object for key in arrays.files)
    loaded = SarlAgent.load(folder)
    for mine, theirs in zip(agent.network.state_dict().values(), loaded.network.state_dict().values(), strict=True):
        torch.testing.assert_close(mine, theirs, rtol=0, atol=0)
    assert loaded.memory.size == agent.memory.size > 0 and len(loaded.demonstrations) == len(agent.demonstrations) > 0
    assert loaded.rng.bit_generator.state == agent.rng.bit_generator.state and loaded.episodes == agent.episodes == 3
    policy = load_policy(tmp_path / "run")
    env = policy.make_env()
    for seed in range(3):
        obs = policy.preprocess(env.reset(seed=seed)[0])
        np.testing.assert_array_equal(loaded.predict(obs)[0], agent.predict(obs)[0])


def test_resume_gives_the_uninterrupted_runs_episodes_and_weights(tmp_path):
    from crowdnav.agents import load_policy, train

    kwargs = {**config("x")["algo_kwargs"], "imitation_episodes": 2, "imitation_epochs": 2}
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    train(config(whole, episodes=6, algo_kwargs=kwargs))
    train(config(cut, episodes=3, algo_kwargs=kwargs))  # checkpointed at 2 (the imitation's end) and at 3
    resumed = train(config(cut, episodes=6, algo_kwargs=kwargs), resume=True)
    assert resumed.episodes == 6 and isinstance(resumed.model, SarlAgent)
    assert rows(cut) == rows(whole)
    resumed_weights, whole_weights = load_policy(cut).model.network.state_dict(), load_policy(whole).model.network.state_dict()
    for mine, theirs in zip(resumed_weights.values(), whole_weights.values(), strict=True):
        torch.testing.assert_close(mine, theirs, rtol=0, atol=0)


def test_crowdnav_evaluate_plays_a_sarl_run(tmp_path):
    from crowdnav.agents import train

    from crowdnav.cli import main

    run = tmp_path / "run"
    train(config(run, episodes=1))
    results = tmp_path / "results"
    argv = ["evaluate", str(run), "--scenario", "open_space", "--episodes", "2", "--set", "humans.count=3", "--out", str(results), "--no-progress"]
    assert main(argv) == 0
    assert list(results.glob("evaluate/*/seeds_*/*"))


def test_settings_it_cannot_use_are_refused_in_one_line(tmp_path):
    from crowdnav.agents import train
    from crowdnav.agents.training.config import ConfigError

    with pytest.raises(ConfigError, match="^modalities: algorithm 'sarl' reads humans, goal and velocity; add velocity$"):
        train(config(tmp_path / "a", modalities=["humans", "goal"]))
    with pytest.raises(ConfigError, match="^algo_kwargs: 'sarl' has no option 'tau'"):
        train(config(tmp_path / "b", algo_kwargs={"tau": 0.1}))
    with pytest.raises(ConfigError, match="^algo_kwargs.imitation_teacher: 'nobody' is not one of"):
        train(config(tmp_path / "c", algo_kwargs={"imitation_episodes": 1, "imitation_teacher": "nobody"}))
    with pytest.raises(ConfigError, match="^algo_kwargs.lookahead_depth: 'sarl' takes an integer from 1 to 2, got 3$"):
        train(config(tmp_path / "d", algo_kwargs={"lookahead_depth": 3}))
    with pytest.raises(ConfigError, match="^algo_kwargs.lookahead_width: 'sarl' takes an integer from 1 to 81, got 0.5$"):
        train(config(tmp_path / "e", algo_kwargs={"lookahead_width": 0.5}))
    assert not any((tmp_path / name).exists() for name in "abcde")  # refused before a run folder is made


def greedy_successes(policy, seeds):
    env = policy.make_env()
    successes = 0
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(policy(obs))
            done = terminated or truncated
        successes += info["outcome"] == "success"
    return successes


@pytest.mark.slow
def test_v_learning_learns_to_reach_a_goal_it_is_only_paid_for_reaching(tmp_path):
    """Empty space, no progress reward: the lookahead alone sees nothing to gain (it stands still); learned values do."""
    from crowdnav.agents import load_policy, train

    kwargs = {"batch_size": 64, "updates_per_episode": 10, "target_update_every": 10, "width": 32, "epsilon_start": 1.0,
              "epsilon_end": 0.1, "epsilon_decay_episodes": 100}
    train(config(tmp_path / "run", episodes=150, overrides=EMPTY, reward_weights={"goal_progress": 0.0}, algo_kwargs=kwargs,
                 checkpoint_every=150))
    trained, untrained = load_policy(tmp_path / "run"), load_policy(tmp_path / "run")
    for parameter in untrained.model.network.parameters():
        torch.nn.init.zeros_(parameter)
    assert greedy_successes(untrained, range(5)) == 0  # V = 0: every move costs the same step, it stands still
    assert greedy_successes(trained, range(5)) == 5


@pytest.mark.parametrize("scenario", library_names())
def test_sarl_trains_and_acts_in_every_library_scenario_or_refuses_in_one_line(tmp_path, scenario):
    from crowdnav.agents import load_policy, train

    from crowdnav.errors import CrowdNavError

    try:
        train(config(tmp_path / "run", scenario=scenario, episodes=1, overrides={"max_steps": 10}, checkpoint_every=1))
    except CrowdNavError as error:  # a robot it cannot drive: one line that says why
        assert "\n" not in str(error) and "holonomic" in str(error), str(error)
        return
    assert_acts(load_policy(tmp_path / "run"))


def assert_acts(policy, steps: int = 3) -> None:
    """The loaded policy drives its own env a few steps with finite 2-D actions."""
    env = policy.make_env()
    obs, _ = env.reset(seed=0)
    for _ in range(steps):
        action = policy(obs)
        assert action.shape == (2,) and np.all(np.isfinite(action))
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
