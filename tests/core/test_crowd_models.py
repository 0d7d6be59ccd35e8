"""The crowd-model seam (crowdnav.crowd): a model added by the recipe of docs/architecture.md runs in both simulators.

The toy model here, "toward_goal", walks every human straight at its preferred speed toward its
goal (slowing so as not to pass it), whatever is in the way. It is added exactly as the recipe
says: a :class:`CrowdModel` subclass with a ``name`` and ``commands``, its class in
``CROWD_MODELS`` and its name in the schema's ``CROWD_MODEL_NAMES`` (patched here for the test
only). Then the single simulator uses it, the batched one gives the same episodes bit for bit,
and it mixes with the social force group by group.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

import numpy as np
import pytest

from crowdnav.crowd import CROWD_MODELS, Crowd, CrowdModel, CrowdView
from crowdnav.crowd.views import WorldView
from crowdnav.scenario import ScenarioError
from crowdnav.scenario import crowd as crowd_schema
from crowdnav.scenario.schema import Scenario
from crowdnav.sim.orca_solver import toward_goal
from crowdnav.sim.simulator import Simulator
from crowdnav.worlds.compiled import load_world
from tests.core.test_vector_env import check_batch_equals_singles


class TowardGoal(CrowdModel):
    """Constant velocity toward the goal: the recipe's minimum (``name`` and ``commands``; the batch runs it world by world)."""

    name = "toward_goal"

    def commands(self, view: CrowdView) -> np.ndarray:
        humans = view.agent_positions[..., view.robot_count :]
        return toward_goal(view.human_goals - humans, view.human_preferred_speed, self.dt)


class TowardGoalBatched(TowardGoal):
    """The same model with its own batched call: its arithmetic takes a leading world axis, so all worlds go at once."""

    name = "toward_goal_batched"

    def commands_batch(self, view: CrowdView, worlds: Sequence[CrowdModel]) -> np.ndarray:
        return self.commands(view)


@pytest.fixture
def toy_models(monkeypatch):
    """The recipe's two registrations: the class in CROWD_MODELS, the name in the scenario schema's CROWD_MODEL_NAMES."""
    for model in (TowardGoal, TowardGoalBatched):
        monkeypatch.setitem(CROWD_MODELS, model.name, model)
    monkeypatch.setattr(crowd_schema, "CROWD_MODEL_NAMES", (*crowd_schema.CROWD_MODEL_NAMES, TowardGoal.name, TowardGoalBatched.name))


def test_the_registry_and_the_schema_name_the_same_models_in_the_same_order():
    assert tuple(CROWD_MODELS) == crowd_schema.CROWD_MODEL_NAMES == ("social_force", "orca", "replay")
    assert all(cls.name == name for name, cls in CROWD_MODELS.items())
    schema = json.dumps(Scenario.model_json_schema())
    assert '"enum": ["social_force", "orca", "replay"]' in schema  # humans.model and a group's model list the registered names


@pytest.mark.usefixtures("toy_models")
def test_a_toy_model_added_by_the_recipe_moves_the_humans_of_a_single_simulator():
    sim = Simulator("open_space", {"humans.model": "toward_goal", "humans.count": 6})
    assert list(sim.crowd.models) == ["toward_goal"]
    sim.reset(seed=3)
    expected = toward_goal(sim.human_goals - sim.human_positions, sim.human_preferred_speed, sim.dt)
    assert np.array_equal(sim.crowd_commands(), expected)
    assert not np.array_equal(expected, sim.social_force_commands())  # the toy is not the social force: the check can fail
    before = sim.human_positions.copy()
    sim.step(np.zeros(2))
    assert np.allclose(sim.human_positions, before + expected * sim.dt)  # no overlaps in 6 humans' first step: the command as given


@pytest.mark.usefixtures("toy_models")
@pytest.mark.parametrize("model", ["toward_goal", "toward_goal_batched"])
@pytest.mark.parametrize(("scenario", "overrides"), [
    ("open_space", {"humans.count": [0, 6]}),  # crowd sizes differ across worlds, including none
    ("station_hall", {}),  # groups: walking ones take the toy model, standing ones never move
])
def test_a_toy_model_gives_batched_worlds_equal_to_single_simulators_bit_for_bit(model, scenario, overrides):
    key = "humans.model"
    check_batch_equals_singles(load_world(scenario, {**overrides, key: model}), worlds=4, first_seed=10, steps=80, rng_seed=4, scale=1.0)


@pytest.mark.usefixtures("toy_models")
def test_a_toy_model_mixes_with_the_social_force_group_by_group_in_both_simulators():
    overrides = {"humans.groups.0.model": "toward_goal"}  # station_hall's commuters; the other walking group keeps the social force
    sim = Simulator("station_hall", overrides)
    assert list(sim.crowd.models) == ["social_force", "toward_goal"]
    sim.reset(seed=2)
    sim.step(np.zeros(2))
    toy = sim.crowd.moved_by("toward_goal", sim.human_group)
    commands = sim.crowd_commands()
    assert np.array_equal(commands[toy], sim.crowd.models["toward_goal"].commands(WorldView(sim))[toy])
    assert np.array_equal(commands[~toy], sim.social_force_commands()[~toy]) and (~toy).any() and (sim.human_group[toy] == 0).any()
    check_batch_equals_singles(load_world("station_hall", overrides), worlds=3, first_seed=0, steps=80, rng_seed=5, scale=1.0)


def test_an_unknown_model_is_refused_by_the_schema_and_a_name_without_a_class_at_load(monkeypatch):
    with pytest.raises(ScenarioError, match=r"humans.model: expected one of 'social_force', 'orca', 'replay', got 'toward_goal'"):
        load_world("open_space", {"humans.model": "toward_goal"})
    monkeypatch.setattr(crowd_schema, "CROWD_MODEL_NAMES", (*crowd_schema.CROWD_MODEL_NAMES, "toward_goal"))  # the schema only
    world = load_world("open_space", {"humans.model": "toward_goal"})
    with pytest.raises(ScenarioError, match=r"crowd model 'toward_goal' has no class in crowdnav.crowd.CROWD_MODELS") as error:
        Crowd(world)
    assert "\n" not in str(error.value)
