"""``algo_kwargs.human_margin``: the SARL lookahead counts a move predicted to pass a tracked human closer than the
margin as a collision (people leave the constant-velocity line within a step); 0 keeps every published network's
choices; the option is bounded and the ONNX export carries it."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

torch = pytest.importorskip("torch")

from crowdnav.agents.sarl.lookahead import Physics, action_set, decode, lookahead  # noqa: E402
from crowdnav.agents.training.config import ConfigError  # noqa: E402

WEIGHTS = {"step": -0.01, "goal_progress": 0.1, "social": 0.0, "goal_reached": 1.0, "collision": -1.0}
PHYSICS = Physics(0.3, 1.0, 0.2, 0.3, 0.0, 1.0, WEIGHTS)
FULL_SPEED_TO_GOAL = 1 + 4 * 16  # stop, then 5 speeds x 16 headings: the fastest move, heading 0 (the goal)


def passing_human(lateral: float) -> dict[str, np.ndarray]:
    """Goal 4 m ahead (+x); one standing human of radius 0.3 at (0.4, ``lateral``): the full-speed move (0.2 m) ends at
    a surface gap of hypot(0.2, ``lateral``) - 0.6 m from it."""
    humans = np.zeros((1, 1, 6))
    humans[0, 0] = [0.4, lateral, 0.0, 0.0, 0.3, 1.0]
    return decode({"goal": np.array([[4.0, 0.0, 1.0]]), "velocity": np.zeros((1, 2)), "humans": humans}, {})


@pytest.mark.parametrize(("margin", "collides"), [(0.0, False), (0.04, False), (0.06, True), (0.1, True)])
def test_a_move_passing_a_human_closer_than_the_margin_is_a_predicted_collision(margin, collides):
    ahead = lookahead(passing_human(0.62), PHYSICS, action_set(1.0), margin)  # gap 0.05 m where the move ends
    assert bool(ahead["done"][0, FULL_SPEED_TO_GOAL]) is collides
    assert bool(ahead["reward"][0, FULL_SPEED_TO_GOAL] < WEIGHTS["collision"] + 0.05) is collides
    assert not ahead["done"][0, 0]  # standing still keeps a gap of 0.14 m


def test_a_human_beyond_the_margin_changes_nothing():
    state = passing_human(1.5)
    plain, wide = lookahead(state, PHYSICS, action_set(1.0)), lookahead(state, PHYSICS, action_set(1.0), 0.2)
    assert np.array_equal(plain["done"], wide["done"]) and np.array_equal(plain["reward"], wide["reward"])


@pytest.mark.parametrize("margin", [-0.1, 1.5, float("nan"), "wide", True])
def test_a_margin_outside_0_to_1_metre_is_refused_in_one_line(tmp_path, margin):
    from crowdnav.agents import train

    from tests.agents.test_sarl import config

    with pytest.raises(ConfigError, match=r"^algo_kwargs.human_margin: 'sarl' takes metres from 0 to 1, got .+$"):
        train(config(tmp_path / "run", algo_kwargs={"human_margin": margin}))
    assert not (tmp_path / "run").exists()


def test_an_agent_with_a_margin_acts_as_the_same_network_without_it_wherever_no_human_is_near(tmp_path):
    from crowdnav.agents import load_policy, train

    from tests.agents.test_sarl import config

    train(config(tmp_path / "run", episodes=2, algo_kwargs={"batch_size": 16, "updates_per_episode": 3, "width": 16, "human_margin": 0.1}))
    policy = load_policy(tmp_path / "run")
    agent = policy.model
    assert agent.options["human_margin"] == 0.1
    env = policy.make_env()
    observation, _ = env.reset(seed=3)
    far = {key: np.asarray(value) for key, value in observation.items()}
    far["humans"] = np.zeros_like(far["humans"])  # nobody tracked: the margin has nothing to act on
    with_margin = agent.act(far)
    agent.options["human_margin"] = 0.0
    assert np.array_equal(with_margin, agent.act(far))
