"""The evaluation protocol: schedule of evaluations and the held-out test-seed set."""

from __future__ import annotations

import pytest
from crowdnav.agents import train_seed
from crowdnav.evaluation.experiment import load_experiment, shipped_experiments
from crowdnav.evaluation.protocol import QUICK, Protocol, quick


def test_default_protocol_is_the_papers_14_evaluations_of_20_test_episodes_up_to_700_episodes():
    protocol = Protocol()
    assert protocol.evaluation_points == list(range(50, 701, 50))
    assert protocol.evaluations == 14
    assert protocol.evaluations * protocol.test_episodes == 280
    assert protocol.run_seeds == [0, 1, 2, 3, 4]


def test_evaluation_points_stop_at_the_training_budget():
    assert Protocol(train_episodes=120, eval_every=50).evaluation_points == [50, 100]
    assert Protocol(train_episodes=4, eval_every=2).evaluation_points == [2, 4]


def test_test_seeds_are_fixed_and_disjoint_from_every_runs_training_seeds():
    protocol = Protocol()
    assert protocol.test_seeds == list(range(20))
    assert Protocol(seeds=3).test_seeds == protocol.test_seeds  # the same set whatever else changes
    protocol.check_disjoint()
    for run_seed in protocol.run_seeds:
        training = {train_seed(run_seed, episode) for episode in range(protocol.train_episodes)}
        assert training == set(protocol.training_seeds(run_seed))
        assert not training & set(protocol.test_seeds)


def test_test_seeds_overlapping_training_seeds_are_refused():
    protocol = Protocol(test_seed_base=train_seed(1, 10), seeds=2)
    with pytest.raises(ValueError, match="also training seeds of run seed 1"):
        protocol.check_disjoint()


def test_every_configuration_and_seed_of_an_experiment_gets_the_same_test_seeds(tmp_path):
    for name in shipped_experiments():
        experiment = load_experiment(name)
        seeds = {tuple(Protocol(**spec.protocol).test_seeds) for spec, _ in experiment.units(tmp_path)}
        assert seeds == {tuple(experiment.protocol.test_seeds)}


def test_quick_preset_shrinks_the_schedule_and_keeps_the_test_seed_base():
    shrunk = quick(Protocol(test_seed_base=7))
    assert shrunk.train_episodes == QUICK["train_episodes"] and shrunk.test_seed_base == 7
    assert shrunk.evaluation_points == [10, 20]


@pytest.mark.parametrize("fields, message", [
    ({"eval_every": 0}, "eval_every: expected an integer >= 1"),
    ({"test_episodes": 2.5}, "test_episodes: expected an integer >= 1"),
    ({"train_episodes": 10, "eval_every": 20}, "no evaluation would run"),
    ({"test_seed_base": -1}, "test_seed_base: expected an integer >= 0"),
])
def test_invalid_protocol_values_are_refused_with_the_field_name(fields, message):
    with pytest.raises(ValueError, match=message):
        Protocol(**fields)
