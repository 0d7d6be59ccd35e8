"""``baseline:onboard``: the ``plan`` modality's move executed, the same bits the env observes, from the robot's own sensing only."""

from __future__ import annotations

import numpy as np
import pytest

from crowdnav import Simulator
from crowdnav.envs import CrowdNavEnv
from crowdnav.planning import PlannerUnavailable
from crowdnav.planning.onboard import OnboardPlanner
from crowdnav.planning.predictive import CrowdEstimate, PredictivePlanner, moves_to_actions
from crowdnav.planning.scripted import SCRIPTED_POLICIES
from tests.core.multi_robot_scenes import HALL, hall

FIGURE4 = {"humans.count": 5, "humans.preferred_speed": [0.5, 1.2]}


@pytest.mark.parametrize(("overrides", "sensors"), [
    (FIGURE4, None),  # the tracker sees every human
    ({**FIGURE4, "humans.count": 8}, {"humans": {"count": 3, "max_range": 2.0}}),  # it misses some: the planner never hears of them
])
def test_the_onboard_action_is_the_plan_observation_bit_for_bit_at_every_step(overrides, sensors):
    seeds = [0, 1, 2, 3]
    envs = [CrowdNavEnv(scenario="room_furniture", modalities=["goal", "plan"], overrides=overrides, sensors=sensors) for _ in seeds]
    planner = SCRIPTED_POLICIES["onboard"]()  # one planner drives every env, as the evaluation plays it (lock-step)
    observations = [env.reset(seed=seed)[0] for env, seed in zip(envs, seeds, strict=True)]
    running, steps = list(range(len(seeds))), 0
    while running:
        still = []
        for i in running:
            action = planner(envs[i].simulator)
            assert action.dtype == np.float32 and action.tobytes() == observations[i]["plan"].tobytes()
            observations[i], _, terminated, truncated, _ = envs[i].step(action)
            steps += 1
            if not (terminated or truncated):
                still.append(i)
        running = still
    assert steps > 100


def test_the_onboard_planner_reads_only_what_the_tracker_reports():
    """With the tracker's range under a hand's width it plans as in an empty room; the privileged planner sees everyone."""
    env = CrowdNavEnv(scenario="room_furniture", modalities=["goal"], overrides={**FIGURE4, "humans.count": 12},
                      sensors={"humans": {"max_range": 0.01}})
    onboard, privileged = OnboardPlanner(), PredictivePlanner()
    differs = 0
    for seed in range(3):
        env.reset(seed=seed)
        sim = env.simulator
        for _ in range(40):
            nobody = CrowdEstimate.from_tracker(np.array([sim.robot_position]), np.array([sim.robot_heading]),
                                                np.array([complex(sim.velocities[0])]), np.array([sim.robot_goal]), np.zeros((1, 5, 6), np.float32))
            alone = moves_to_actions(PredictivePlanner().plan(sim.world, sim.dt, nobody), np.array([sim.robot_heading]),
                                     sim.scenario.robot.max_speed * sim.dt)[0]
            action = onboard(sim)
            assert action.tobytes() == alone.tobytes()
            differs += not np.array_equal(action, privileged(sim))
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    assert differs


def test_every_robot_of_several_plans_as_its_own_plan_observation_the_other_robots_left_out():
    robots = [dict(HALL["robots"][0], start={"type": "points", "points": [[-4, 0.5]]}),
              dict(HALL["robots"][1], radius=0.25, max_speed=0.8)]  # its own spec: its own map and moves
    env = CrowdNavEnv(hall(robots=robots, humans={**HALL["humans"], "count": 6}), modalities=["goal", "plan"], other_robots="onboard")
    env.reset(seed=3)
    sim, planner = env.simulator, OnboardPlanner()
    assert sim.robot_scenario(1).robot.radius == 0.25
    for _ in range(40):
        for k in range(len(sim.scenario.robot_specs)):
            view = sim.robot_view(k)
            people, reference = view.without_robots(), sim.robot_view(k, with_robots=False)
            for name in ("positions", "velocities", "radii", "robot_offset", "robot_distance", "human_max_speed"):
                assert getattr(people, name).tobytes() == getattr(reference, name).tobytes(), name
            assert planner(view).tobytes() == env.core.observe_robot(k)["plan"].tobytes()
        _, _, terminated, truncated, _ = env.step(planner(sim.robot_view(0)))
        if terminated or truncated:
            break


def test_the_onboard_planner_refuses_a_unicycle_in_one_line():
    sim = Simulator("room_furniture", {**FIGURE4, "robot.kinematics": "unicycle", "robot.max_angular_speed": 2.0})
    sim.reset(seed=0)
    with pytest.raises(PlannerUnavailable, match="the onboard planner plans lattice moves for a holonomic robot") as error:
        OnboardPlanner()(sim)
    assert "\n" not in str(error.value)
