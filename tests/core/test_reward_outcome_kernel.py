"""The reward and the outcome precedence are written once: one world (Python scalars) and K worlds (arrays) agree bit for bit."""

from __future__ import annotations

import itertools

import numpy as np

from crowdnav.envs.reward import reward_terms
from crowdnav.sim.events import OUTCOME_PRECEDENCE, Collision, StepEvents, outcome_of, outcomes

EVENTS = list(itertools.product([False, True], repeat=4))  # (collided, left_world, goal_reached, truncated)


def test_outcome_precedence_is_collision_then_out_of_bounds_then_success_then_truncated():
    assert OUTCOME_PRECEDENCE == ("collision", "out_of_bounds", "success", "truncated")
    assert outcome_of(True, True, True, True) == "collision"
    assert outcome_of(False, True, True, True) == "out_of_bounds"
    assert outcome_of(False, False, True, True) == "success"
    assert outcome_of(False, False, False, True) == "truncated"
    assert outcome_of(False, False, False, False) is None


def test_outcomes_of_k_worlds_equal_outcome_of_each_world_for_every_event_combination():
    flags = np.array(EVENTS).T
    assert list(outcomes(*flags)) == [outcome_of(*events) for events in EVENTS]


def test_step_events_outcome_follows_the_precedence():
    hit = Collision("human", "human_0", -0.01)
    for collided, left, goal, truncated in EVENTS:
        events = StepEvents(goal_reached=goal, collision=hit if collided else None, truncated=truncated, left_world=left)
        assert events.outcome == outcome_of(collided, left, goal, truncated)


def test_reward_terms_of_k_worlds_equal_each_world_bit_for_bit():
    rng = np.random.default_rng(0)
    weights = {"step": -0.013, "goal_progress": 1.7, "social": -0.31, "goal_reached": 10.0, "collision": -7.5}
    k = len(EVENTS)
    previous, distance, force = rng.uniform(0, 12, k), rng.uniform(0, 12, k), rng.uniform(0, 3, k)
    outcome = outcomes(*np.array(EVENTS).T)
    reward, terms = reward_terms(weights, previous, distance, force, outcome)
    for i in range(k):
        one_reward, one_terms = reward_terms(weights, float(previous[i]), float(distance[i]), float(force[i]), outcome[i])
        assert type(one_reward) is float and list(one_terms) == list(terms)
        assert np.float64(one_reward).tobytes() == reward[i].tobytes()
        assert all(np.float64(one_terms[t]).tobytes() == terms[t][i].tobytes() for t in terms)
        paid = {"success": "goal_reached", "collision": "collision", "out_of_bounds": "collision"}.get(outcome[i])
        assert all((one_terms[t] != 0.0) == (t == paid) for t in ("goal_reached", "collision"))
