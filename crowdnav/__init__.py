"""crowdnav: a multi-modal training environment for human-aware social robot navigation."""

from crowdnav.envs import CrowdNavEnv, CrowdNavParallelEnv, SocialForcePolicy, env, parallel_env  # registers the Gymnasium ids
from crowdnav.errors import CrowdNavError
from crowdnav.scenario import Scenario, ScenarioError, load_scenario
from crowdnav.simulator import Collision, SimulationError, Simulator, StepEvents

__all__ = [
    "Collision",
    "CrowdNavError",
    "CrowdNavEnv",
    "CrowdNavParallelEnv",
    "Scenario",
    "ScenarioError",
    "SimulationError",
    "Simulator",
    "SocialForcePolicy",
    "StepEvents",
    "env",
    "load_scenario",
    "parallel_env",
]
__version__ = "0.1.0"
