"""The robot's sensing modalities: one observation key each, in the robot's frame.

``build_modalities(names, world, sensors)`` returns ``{key: Modality}``; each modality has a
fixed ``space()`` (a gymnasium Box) and ``observe(sim)``. Built-in keys: ``goal``,
``closest_obstacle``, ``lidar``, ``leog``, ``velocity``, ``humans``, ``obstacles``, ``geodesic``, ``plan``. See docs/sensors.md.
"""

from crowdnav.sensors.base import MODALITIES, Modality, build_modalities, register_modality
from crowdnav.sensors.closest_obstacle import ClosestObstacleModality
from crowdnav.sensors.geodesic import GeodesicModality
from crowdnav.sensors.goal import GoalModality
from crowdnav.sensors.humans import HumansModality
from crowdnav.sensors.leog import LeogModality
from crowdnav.sensors.lidar import LidarModality
from crowdnav.sensors.obstacles import ObstaclesModality
from crowdnav.sensors.plan import PlanModality
from crowdnav.sensors.velocity import VelocityModality

__all__ = [
    "MODALITIES",
    "ClosestObstacleModality",
    "GeodesicModality",
    "GoalModality",
    "HumansModality",
    "LeogModality",
    "LidarModality",
    "Modality",
    "ObstaclesModality",
    "PlanModality",
    "VelocityModality",
    "build_modalities",
    "register_modality",
]
