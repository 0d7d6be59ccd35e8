"""The social-force model as a policy for the ``human_<i>`` agents of the multi-agent env.

It reads only the humans' observations (see :mod:`crowdnav.envs.human_observation`) and uses
the functions of :mod:`crowdnav.sim.forces`, the same ones the simulator's built-in crowd
uses, so driving every human with this policy reproduces the built-in crowd (to float32
precision, the observations' precision).

Replacing some humans by another policy is a dict merge::

    env = crowdnav.parallel_env("room_furniture")
    crowd = crowdnav.SocialForcePolicy(env.scenario)
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = crowd(observations)                              # every human
        actions["human_0"] = my_policy(observations["human_0"])   # override some of them
        actions["robot"] = robot_policy(observations["robot"])
        observations, rewards, terminations, truncations, infos = env.step(actions)
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from crowdnav.scenario.schema import Scenario
from crowdnav.sim import forces as sf

_UNUSED_DISTANCE = 1.0
"""Distance given to padding slots and zero offsets: any positive value (a zero offset pushes with zero force)."""


def _complex(xy: np.ndarray) -> np.ndarray:
    """float array (..., 2) -> complex128 array (...)."""
    return np.ascontiguousarray(xy, dtype=np.float64).view(np.complex128)[..., 0]


def _distance(offset: np.ndarray) -> np.ndarray:
    """|offset|, with zero lengths (an inactive human's all-zero observation) replaced to keep 0 / 0 out."""
    distance = np.abs(offset)
    return np.where(distance > 0, distance, _UNUSED_DISTANCE)


def _stack(arrays: list[np.ndarray]) -> np.ndarray:
    """np.stack for equal-shape arrays; one concatenate is about twice as fast for many small ones."""
    return np.concatenate(arrays).reshape(len(arrays), *np.shape(arrays[0]))


class SocialForcePolicy:
    """Maps all humans' observations to their actions in one vectorized call.

    ``scenario`` supplies the model parameters (``humans.social_force``) and the time step
    (``env.scenario`` of the env the observations come from). An action is the velocity
    command in m/s divided by the human's max speed: a (2,) float32 in [-1, 1], world frame.
    Every action is finite: a human whose ``max_speed`` is 0 (members of a standing group,
    ``behaviour: stand``; inactive humans of ``fixed_agents=True``, whose observation is zero)
    gets the action 0.
    """

    def __init__(self, scenario: Scenario):
        force = scenario.humans.social_force
        self._goal_weight = force.goal_weight
        self._goal_saturation = force.goal_saturation_distance
        self._human = (force.human_strength, force.human_range)
        self._obstacle = (force.obstacle_strength, force.obstacle_range)
        self._robot = (force.robot_strength, force.robot_range)
        self._relax = min(1.0, scenario.time_step / force.relaxation_time)

    def __call__(self, observations: Mapping[str, Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """``{agent: observation}`` (non-human agents such as ``robot`` are ignored) -> ``{human: action}``."""
        humans = [agent for agent in observations if agent.startswith("human_")]
        if not humans:
            return {}
        keys = observations[humans[0]].keys()
        batch = {key: _stack([observations[agent][key] for agent in humans]) for key in keys}
        return dict(zip(humans, self.act(batch), strict=True))

    def act(self, batch: Mapping[str, np.ndarray]) -> np.ndarray:
        """Stacked observations (each key with a leading axis over humans) -> (n, 2) float32 actions."""
        radius = np.asarray(batch["radius"], dtype=np.float64)[:, 0]
        velocity = _complex(batch["velocity"])
        force = sf.goal_force(_complex(batch["goal"]) - _complex(batch["position"]), self._goal_weight, self._goal_saturation)

        mask = np.asarray(batch["humans_mask"]) > 0.5
        if mask.size:
            offset = _complex(batch["humans_offset"])
            distance = np.where(mask, np.abs(offset), _UNUSED_DISTANCE)
            strength, decay = self._human
            contact = radius[:, None] + np.asarray(batch["humans_radius"], dtype=np.float64)
            gain = np.where(mask, sf.repulsion_gain(strength, contact, decay), 0.0)
            force += sf.repulsion(offset, distance, gain, -1.0 / decay)

        obstacles = _complex(batch["obstacles_offset"])
        if obstacles.size:
            strength, decay = self._obstacle
            gain = sf.repulsion_gain(strength, radius[:, None], decay)
            force += sf.repulsion(obstacles, _distance(obstacles), gain, -1.0 / decay)

        if "robot_offset" in batch:  # present only when the scenario's humans see the robot
            offset = _complex(batch["robot_offset"])[:, None]
            strength, decay = self._robot
            contact = radius + np.asarray(batch["robot_radius"], dtype=np.float64)[:, 0]
            gain = sf.repulsion_gain(strength, contact, decay)[:, None]
            force += sf.repulsion(offset, _distance(offset), gain, -1.0 / decay)

        preferred = np.asarray(batch["preferred_speed"], dtype=np.float64)[:, 0]
        max_speed = np.asarray(batch["max_speed"], dtype=np.float64)[:, 0]
        # A human with max speed 0 (a standing group's member, or an inactive slot of
        # fixed_agents) cannot move: its action is 0. A cap of 1 keeps 0 / 0 out of the formula.
        moving = max_speed > 0
        cap = np.where(moving, max_speed, 1.0)
        command = np.where(moving, sf.velocity_command(force, velocity, preferred, cap, self._relax) / cap, 0.0)
        return np.stack([command.real, command.imag], axis=-1).astype(np.float32)
