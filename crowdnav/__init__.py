"""crowdnav: a multi-modal training environment for human-aware social robot navigation.

The core's packages, by concept: ``sim`` (the simulation step and its parts), ``worlds`` (a
scenario's world compiled at load time), ``crowd`` (the crowd models), ``scenario`` (the YAML
schema and loader), ``sensors``, ``envs`` (Gymnasium and PettingZoo), ``batch`` (K worlds at once),
``planning`` (the planners and the scripted robot policies), ``rendering`` and ``cli``.
:mod:`crowdnav.legacy_paths` keeps the module paths of the flat root before ``sim``, ``worlds`` and
``planning.scripted`` importable (``crowdnav.simulator``, ``crowdnav.world``, ``crowdnav.policies``, ...).
"""

from types import ModuleType

from crowdnav import legacy_paths
from crowdnav.envs import CrowdNavEnv, CrowdNavParallelEnv, SocialForcePolicy, env, parallel_env  # registers the Gymnasium ids
from crowdnav.errors import CrowdNavError
from crowdnav.scenario import Scenario, ScenarioError, load_scenario
from crowdnav.sim.simulator import Collision, SimulationError, Simulator, StepEvents

legacy_paths.install()

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


def __getattr__(name: str) -> ModuleType:
    """An old module path of the root as an attribute (``crowdnav.policies``), imported on first use."""
    return legacy_paths.old_attribute(__name__, name)
