"""crowdnav: a multi-modal training environment for human-aware social robot navigation."""

from crowdnav.scenario import Scenario, ScenarioError, load_scenario
from crowdnav.simulator import Collision, Simulator, StepEvents

__all__ = ["Collision", "Scenario", "ScenarioError", "Simulator", "StepEvents", "load_scenario"]
__version__ = "0.1.0"
