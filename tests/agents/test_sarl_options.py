"""Training options of the SARL-style agent: a value ensemble (``algo_kwargs.ensemble``: members averaged, each
regressing on the same target), ``learning_rate_schedule: linear`` (Adam's rate falls to 0 over the episode budget)
and ``algo_kwargs.value_bound`` (V capped by the largest return reachable from the goal distance). Each survives
checkpoints and resume bit for bit and exports as predict acts."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

torch = pytest.importorskip("torch")

from crowdnav.agents import load_policy, train  # noqa: E402
from crowdnav.agents.sarl.network import ValueEnsemble, ValueNetwork, evaluate  # noqa: E402
from crowdnav.agents.training.config import ConfigError  # noqa: E402

from crowdnav.errors import CrowdNavError  # noqa: E402
from crowdnav.scenario.library import library_names  # noqa: E402
from tests.agents.test_sarl import assert_acts, config, rows  # noqa: E402


def ensemble_config(out, **fields):
    base = config(out, **fields)
    base["algo_kwargs"] = {**base["algo_kwargs"], "ensemble": 3, **fields.get("algo_kwargs", {})}
    return base


def weights(network):
    return [value.clone() for value in network.state_dict().values()]


def assert_exports_as_predict(policy):
    """The agent's export module chooses predict's actions, bit for bit, on the first observations of 4 episodes."""
    env = policy.make_env()
    observations = [policy.preprocess(env.reset(seed=seed)[0]) for seed in range(4)]
    batch = {key: np.stack([obs[key] for obs in observations]) for key in observations[0]}
    module = policy.model.export_module(list(batch)).eval()
    with torch.no_grad():
        traced = module(*(torch.as_tensor(batch[key]) for key in batch)).numpy()
    np.testing.assert_array_equal(traced, policy.model.predict(batch)[0])


def test_an_ensemble_values_a_state_at_its_members_mean_and_every_member_learns(tmp_path):
    train(ensemble_config(tmp_path / "run", episodes=4))
    early, final = load_policy(tmp_path / "run" / "snapshots" / "episode_00002"), load_policy(tmp_path / "run")
    network = final.model.network
    assert isinstance(network, ValueEnsemble) and len(network.members) == 3
    first, second = (weights(member) for member in network.members[:2])
    assert any(not torch.equal(a, b) for a, b in zip(first, second, strict=True))  # initialised apart
    for before, after in zip(early.model.network.members, network.members, strict=True):
        assert any(not torch.equal(a, b) for a, b in zip(weights(before), weights(after), strict=True))
    robot = np.random.default_rng(0).random((7, 3), dtype=np.float32)
    humans = np.random.default_rng(1).random((7, 5, 7), dtype=np.float32)
    humans[..., -1] = 1.0
    members = np.stack([evaluate(member, robot, humans) for member in network.members])
    np.testing.assert_allclose(evaluate(network, robot, humans), members.mean(axis=0), rtol=1e-6)


def test_an_ensemble_run_resumes_bit_for_bit_and_exports_as_predict_acts(tmp_path):
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    train(ensemble_config(whole, episodes=6))
    train(ensemble_config(cut, episodes=3))
    train(ensemble_config(cut, episodes=6), resume=True)
    assert rows(cut) == rows(whole)
    mine, theirs = load_policy(cut).model.network, load_policy(whole).model.network
    for a, b in zip(weights(mine), weights(theirs), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    policy = load_policy(whole)
    assert_exports_as_predict(policy)


def test_one_member_is_the_plain_network_of_the_published_runs(tmp_path):
    result = train(config(tmp_path / "run", episodes=2, algo_kwargs={**config("x")["algo_kwargs"], "ensemble": 1}))
    plain = train(config(tmp_path / "plain", episodes=2))
    assert type(result.model.network) is ValueNetwork
    assert rows(tmp_path / "run") == rows(tmp_path / "plain")
    for a, b in zip(weights(result.model.network), weights(plain.model.network), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)


def adam_rate(folder):
    return [group["lr"] for group in load_policy(folder).model.optimizer.param_groups]


def test_linear_schedule_takes_adams_rate_to_zero_at_the_budget_and_constant_keeps_it(tmp_path):
    linear, constant = tmp_path / "linear", tmp_path / "constant"
    train(config(linear, episodes=4, learning_rate=0.01, learning_rate_schedule="linear"))
    train(config(constant, episodes=4, learning_rate=0.01))
    # the updates after episode N (1-based) use 0.01 * (1 - N / 4)
    assert adam_rate(linear / "snapshots" / "episode_00002") == [pytest.approx(0.005)]
    assert adam_rate(linear) == [0.0]
    assert adam_rate(constant) == [0.01]
    assert rows(linear)[:1] == rows(constant)[:1]  # the first episode is played before any update


class Killed(Exception):
    pass


def kill_at(point):
    def on_checkpoint(episodes):
        if episodes == point:
            raise Killed

    return on_checkpoint


def test_a_killed_linear_schedule_run_resumes_bit_for_bit_and_a_larger_budget_stretches_the_schedule(tmp_path):
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    fields = {"learning_rate_schedule": "linear", "learning_rate": 0.01}
    train(config(whole, episodes=6, **fields))
    with pytest.raises(Killed):
        train(config(cut, episodes=6, **fields), on_checkpoint=kill_at(4))
    train(config(cut, episodes=6, **fields), resume=True)
    assert rows(cut) == rows(whole)
    for a, b in zip(weights(load_policy(cut).model.network), weights(load_policy(whole).model.network), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    # a finished run resumed with twice the budget: the rate falls to 0 at the new budget (as SB3's schedules)
    train(config(cut, episodes=12, **fields), resume=True)
    assert adam_rate(cut / "snapshots" / "episode_00008") == [pytest.approx(0.01 * (1 - 8 / 12))]
    assert adam_rate(cut) == [0.0]


def test_an_ensemble_size_out_of_range_is_refused_in_one_line(tmp_path):
    with pytest.raises(ConfigError, match="^algo_kwargs.ensemble: 'sarl' takes an integer from 1 to 8, got 0$"):
        train(ensemble_config(tmp_path / "a", algo_kwargs={"ensemble": 0}))
    assert not (tmp_path / "a").exists()


def test_the_value_ceiling_bounds_every_discounted_return_of_a_straight_drive_and_is_tight_one_step_out():
    from crowdnav.agents.sarl.lookahead import value_ceiling

    from tests.agents.test_sarl import PHYSICS

    discount = 0.9 ** (PHYSICS.time_step * PHYSICS.max_speed)
    w, step = PHYSICS.weights, PHYSICS.max_speed * PHYSICS.time_step
    for start in (0.31, 0.55, 1.0, 2.37, 8.0):
        distances = [start]
        while distances[-1] > PHYSICS.goal_radius:  # full speed straight at the goal: the fastest way in
            distances.append(max(distances[-1] - step, 0.0))
        rewards = [w["step"] + w["goal_progress"] * (a - b) for a, b in zip(distances[:-1], distances[1:], strict=True)]
        rewards[-1] += w["goal_reached"]
        for index, distance in enumerate(distances[:-1]):
            achieved = sum(discount ** t * r for t, r in enumerate(rewards[index:]))
            ceiling = float(value_ceiling(np.asarray(distance), PHYSICS, discount))
            assert achieved <= ceiling + 1e-9, (start, distance, achieved, ceiling)
    # one step out, from 0.45 m: the full-speed step lands 0.25 m short of the centre; the bound adds only its 0.25 m
    achieved = w["step"] + w["goal_progress"] * step + w["goal_reached"]
    assert float(value_ceiling(np.asarray(0.45), PHYSICS, discount)) == pytest.approx(achieved + w["goal_progress"] * 0.25)


def test_value_bound_trains_acts_and_exports_as_predict_and_refuses_unbounded_rewards(tmp_path):
    kwargs = {**config("x")["algo_kwargs"], "value_bound": True}
    train(config(tmp_path / "run", episodes=3, algo_kwargs=kwargs))
    policy = load_policy(tmp_path / "run")
    assert policy.model.options["value_bound"] is True
    assert_exports_as_predict(policy)
    with pytest.raises(ConfigError, match="^algo_kwargs.value_bound: 'sarl' bounds V only with step, social and collision weights"):
        train(config(tmp_path / "a", algo_kwargs=kwargs, reward_weights={"step": 0.1}))
    with pytest.raises(ConfigError, match="^algo_kwargs.value_bound: 'sarl' takes true or false, got 1$"):
        train(config(tmp_path / "b", algo_kwargs={**kwargs, "value_bound": 1}))
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@pytest.mark.parametrize("scenario", library_names())
def test_every_option_together_trains_acts_and_exports_in_every_library_scenario_sarl_drives(tmp_path, scenario):
    kwargs = {**config("x")["algo_kwargs"], "ensemble": 2, "value_bound": True}
    try:
        train(config(tmp_path / "run", scenario=scenario, episodes=2, overrides={"max_steps": 10}, checkpoint_every=1,
                     learning_rate_schedule="linear", algo_kwargs=kwargs))
    except CrowdNavError as error:  # a robot it cannot drive (test_sarl.py checks which): one line
        assert "\n" not in str(error) and "holonomic" in str(error), str(error)
        return
    policy = load_policy(tmp_path / "run")
    assert isinstance(policy.model.network, ValueEnsemble)
    learnt = policy.model.memory.size >= kwargs["batch_size"]  # short episodes (a crowd ends them) may leave no update yet
    assert adam_rate(tmp_path / "run") == ([0.0] if learnt else [pytest.approx(1e-3)])
    assert_acts(policy)
    assert_exports_as_predict(policy)
