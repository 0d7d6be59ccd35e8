"""Typed schema of a scenario file.

A scenario YAML is validated into :class:`Scenario`. Every model forbids unknown keys,
and every field carries a one-line description (units included) that also ends up in the
JSON Schema printed by ``crowdnav scenario schema``.

Geometry that needs shapely (valid polygons, regions inside the world, crowd capacity)
is checked when the scenario is compiled into a world, see :mod:`crowdnav.worlds.compiled`.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, Field, field_validator, model_serializer, model_validator

from crowdnav.config_errors import FieldProblems
from crowdnav.paths import SAFE_NAME_EXPECTATION, is_safe_name
from crowdnav.scenario.crowd import (  # noqa: F401  (re-exported: the schema's public names)
    CIRCLE_SPACING,
    IMPLICIT_GROUP,
    MAX_REPLAY_CELLS,
    MIN_FORCE_RANGE,
    HumanGroup,
    HumanModel,
    Humans,
    Orca,
    SocialForce,
    Stall,
    replay_cells,
)
from crowdnav.scenario.fields import (  # noqa: F401  (re-exported: the schema's public names)
    MAX_HUMANS,
    MAX_MAGNITUDE,
    MAX_OBSTACLES,
    MAX_VERTICES,
    CircleFurniture,
    CircleRegion,
    Coordinate,
    FiniteFloat,
    Furniture,
    NonNegativeFloat,
    Point,
    PointsRegion,
    PolygonFurniture,
    PolygonRegion,
    PositiveFloat,
    RectangleFurniture,
    RectangleRegion,
    Region,
    Size,
    StrictModel,
    Wall,
    World,
    _count_shape,
    _heading_shape,
    _is_number,
    _pair_of,
)
from crowdnav.scenario.reward_presets import DEFAULT_PRESET, REWARD_PRESETS, REWARD_TERMS, unknown_preset_message
from crowdnav.scenario.tracker import PERFECT, TRACKER_PROFILES, TrackerProfile, TrackerSettings  # noqa: F401  (re-exported)

# ----------------------------------------------------------------------------- agents


class Robot(StrictModel):
    """The learning robot."""

    radius: PositiveFloat = Field(default=0.3, description="Body radius in metres.")
    kinematics: Literal["holonomic", "unicycle"] = Field(
        default="holonomic", description="holonomic: action is a velocity (vx, vy) in the robot frame; unicycle: (v, omega)."
    )
    max_speed: PositiveFloat = Field(default=1.0, description="Maximum linear speed in m/s.")
    max_angular_speed: PositiveFloat | None = Field(
        default=None, description="Maximum angular speed in rad/s (unicycle only, required there)."
    )
    start: Region = Field(description="Region the start position is sampled from.")
    goal: Region = Field(description="Region the goal position is sampled from.")
    goal_radius: float = Field(
        default=0.3, ge=0.01, le=MAX_MAGNITUDE, description="The goal is reached when the centre is this close (m, at least 1 cm)."
    )
    min_start_goal_distance: NonNegativeFloat = Field(
        default=0.0, description="Minimum straight-line distance between start and goal in metres."
    )
    start_heading: Annotated[Literal["random", "toward_goal"] | FiniteFloat, BeforeValidator(_heading_shape)] = Field(
        default="random", description="Initial heading: 'random', 'toward_goal', or a fixed angle in degrees."
    )


MAX_ROBOTS = 8
"""Most robots one scenario may declare under ``robots:``."""
ROBOT_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}$")
"""What a robot's name may be: it becomes a PettingZoo agent name and part of file names."""


class TeamRobot(Robot):
    """One of several robots (``robots:``): a robot's fields, plus a name and its own modalities."""

    name: str | None = Field(
        default=None, description="Agent name (lowercase letters, digits, _; default robot_<i>, i its place in the list)."
    )
    modalities: list[str] | None = Field(
        default=None, description="This robot's observation keys (default: sensors.modalities); settings stay in sensors."
    )

    @field_validator("name")
    @classmethod
    def _agent_name(cls, name: str | None) -> str | None:
        if name is not None and (not ROBOT_NAME.match(name) or name == "robot" or name.startswith("human_")):
            raise ValueError(f"expected lowercase letters, digits and _ (at most 32, not 'robot' nor human_<i>), got {name!r}")
        return name


# ---------------------------------------------------------------- sensors and reward


class GoalSensor(StrictModel):
    """Relative goal observation."""

    frame: Literal["polar", "cartesian"] = Field(
        default="polar", description="polar: (distance, sin, cos) of the bearing; cartesian: (x, y) in the robot frame."
    )


class ClosestObstacleSensor(StrictModel):
    """Nearest point of any obstacle (human disc or static polygon)."""

    frame: Literal["polar", "cartesian"] = Field(
        default="polar", description="polar: (distance, sin, cos) of the bearing; cartesian: (x, y) in the robot frame."
    )
    max_range: PositiveFloat = Field(default=10.0, description="Distances are clipped to this range in metres.")


class LidarSensor(StrictModel):
    """2-D raycast scan."""

    beams: Annotated[int, Field(ge=1, le=4096)] = Field(default=360, description="Number of beams.")
    fov_deg: Annotated[float, Field(gt=0, le=360)] = Field(default=360.0, description="Field of view in degrees.")
    max_range: PositiveFloat = Field(default=5.0, description="Maximum range in metres; readings are range / max_range.")


class LeogSensor(StrictModel):
    """Local egocentric occupancy grid."""

    size: PositiveFloat = Field(default=6.0, description="Side length of the square grid in metres.")
    resolution: PositiveFloat = Field(default=0.1, description="Cell side in metres.")

    @model_validator(mode="after")
    def _whole_cells(self) -> LeogSensor:
        cells = self.size / self.resolution
        if abs(cells - round(cells)) > 1e-6 or round(cells) < 2 or round(cells) > 512:
            raise ValueError(
                f"expected size / resolution to be a whole number of cells in [2, 512], got {cells:g}"
            )
        return self


class HumansSensor(StrictModel):
    """The k nearest humans as a tracker reports them: robot-frame position, relative velocity, radius."""

    count: Annotated[int, Field(ge=1, le=64)] = Field(default=5, description="Number of human slots k (the nearest k humans).")
    max_range: PositiveFloat = Field(
        default=5.0, description="Humans whose surface (centre distance - radius) is farther than this (m) are absent."
    )


class ObstaclesSensor(StrictModel):
    """The nearest walls and pieces of furniture, from the map and the robot's pose: each one's nearest surface point."""

    count: Annotated[int, Field(ge=1, le=64)] = Field(default=8, description="Number of shape slots (the nearest shapes).")
    max_range: PositiveFloat = Field(
        default=4.0, description="Shapes whose nearest surface point is farther than this (m) are absent."
    )
    world_edge: bool = Field(
        default=False,
        description="Without boundary walls, also list the world rectangle's four sides (leaving it ends the episode) as shapes.",
    )


class GeodesicSensor(StrictModel):
    """The distance to the goal around walls and furniture (the map's), on a grid of points centred on the robot."""

    size: Annotated[int, Field(ge=1, le=33)] = Field(default=9, description="Points per side of the grid (odd: the centre is the robot).")
    spacing: PositiveFloat = Field(default=0.1, description="Distance between neighbouring grid points in metres.")

    @model_validator(mode="after")
    def _odd_size(self) -> GeodesicSensor:
        if self.size % 2 == 0:
            raise ValueError(f"expected an odd size (the robot at the centre point), got {self.size}")
        return self


class Sensors(StrictModel):
    """Default settings of the robot's sensing modalities (env options may override)."""

    modalities: list[str] = Field(
        default_factory=lambda: ["goal", "lidar"], description="Observation keys the robot gets by default."
    )
    goal: GoalSensor = Field(default_factory=GoalSensor, description="Relative goal settings.")
    closest_obstacle: ClosestObstacleSensor = Field(
        default_factory=ClosestObstacleSensor, description="Closest-obstacle settings."
    )
    lidar: LidarSensor = Field(default_factory=LidarSensor, description="LIDAR settings.")
    leog: LeogSensor = Field(default_factory=LeogSensor, description="Occupancy-grid settings.")
    humans: HumansSensor = Field(default_factory=HumansSensor, description="Nearest-humans settings.")
    obstacles: ObstaclesSensor = Field(default_factory=ObstaclesSensor, description="Nearest walls and furniture settings.")
    geodesic: GeodesicSensor = Field(default_factory=GeodesicSensor, description="Distance-to-goal-around-obstacles settings.")
    tracker: TrackerSettings = Field(
        default_factory=TrackerSettings,
        description="The people tracker behind humans, plan, the shield and baseline:onboard: a profile name (default perfect) "
                    "or profile and overrides (docs/sensors.md#the-people-tracker).",
    )


def _preset_term(description: str) -> Any:
    """A term weight that, when not given, takes the preset's value (filled in by RewardWeights)."""
    return Field(default=None, description=f"{description} Default: the preset's value.", json_schema_extra=_no_default)


def _no_default(schema: dict[str, Any]) -> None:
    """The JSON Schema of a preset term shows no default (its ``None`` only marks "not given")."""
    schema.pop("default", None)


class RewardWeights(StrictModel):
    """Weights of the named reward terms: a preset's, with the terms given here overriding it."""

    # Every term holds its resolved number (scenario.reward.social; `terms` gives all five). A
    # dump (model_dump) holds what was written: the preset and the terms given explicitly, so
    # that loading it again, also with another preset as override, resolves the same way.

    preset: str = Field(
        default=DEFAULT_PRESET,
        description=f"Named set of weights the terms not given here take: {', '.join(REWARD_PRESETS)} (docs/agents.md#reward).",
        json_schema_extra={"enum": list(REWARD_PRESETS)},
    )
    step: FiniteFloat = _preset_term("Added every step (negative: a penalty).")
    goal_progress: FiniteFloat = _preset_term("Times the decrease of the distance to the goal in the step (m).")
    social: FiniteFloat = _preset_term("Times the magnitude of the humans' social force on the robot (negative: a penalty).")
    goal_reached: FiniteFloat = _preset_term("Added once when the goal is reached.")
    collision: FiniteFloat = _preset_term("Added once on a collision (negative: a penalty).")

    @field_validator("preset")
    @classmethod
    def _known_preset(cls, preset: str) -> str:
        if preset not in REWARD_PRESETS:
            raise ValueError(unknown_preset_message(preset))
        return preset

    @model_validator(mode="after")
    def _fill_from_preset(self) -> RewardWeights:
        # Runs after construction and after every assignment: terms never given follow the preset.
        for term, weight in REWARD_PRESETS[self.preset].weights.items():
            if term not in self.model_fields_set:
                self.__dict__[term] = weight  # not setattr: that would validate (and call this) again
        return self

    @model_serializer(mode="wrap")
    def _dump_as_written(self, handler: Any) -> dict[str, Any]:
        dumped = handler(self)
        return {key: value for key, value in dumped.items() if key == "preset" or key in self.model_fields_set}

    @property
    def terms(self) -> dict[str, float]:
        """Every term's resolved weight, in summation order."""
        return {term: getattr(self, term) for term in REWARD_TERMS}


# ---------------------------------------------------------------------------- scenario


class Scenario(StrictModel):
    """One family of episodes: world, robot, crowd, timing, sensors and reward."""

    name: str | None = Field(default=None, description="Scenario name, folder-safe (defaults to the file name); it names videos.")
    description: str = Field(min_length=1, description="One-line description shown by `crowdnav scenario list`.")
    world: World = Field(default_factory=World, description="World extent and boundary.")
    walls: list[Wall] = Field(default_factory=list, max_length=MAX_OBSTACLES, description="Interior walls (at most 2,000).")
    furniture: list[Furniture] = Field(default_factory=list, max_length=MAX_OBSTACLES, description="Static furniture (at most 2,000 pieces).")
    robot: Robot = Field(  # type: ignore[assignment]  # None only until _one_robot_field fills it
        default=None, description="The robot (give either robot or robots; with robots, the first of them).",
        json_schema_extra=_no_default,
    )
    robots: list[TeamRobot] | None = Field(
        default=None, min_length=2, max_length=MAX_ROBOTS,
        description="Several robots sharing the world (2 to 8; one robot: use robot), each an agent (docs/environments.md#several-robots).",
    )
    humans: Humans = Field(default_factory=Humans, description="The crowd.")
    time_step: PositiveFloat = Field(default=0.2, description="Simulation time step in seconds.")
    max_steps: Annotated[int, Field(ge=1, le=100_000)] = Field(default=150, description="Steps before an episode is truncated (at most 100,000).")
    sensors: Sensors = Field(default_factory=Sensors, description="Default sensor settings.")
    reward: RewardWeights = Field(
        default_factory=RewardWeights, description="Reward weights: a preset (default: 'default') and terms overriding it."
    )

    @model_validator(mode="after")
    def _one_robot_field(self) -> Scenario:
        # `robot` stays the first (ego) robot's spec either way, so one-robot code reads it unchanged
        if self.robots is None:
            if self.robot is None:
                raise FieldProblems([("robot", "required field is missing (one robot; or several under robots:)")])
            return self
        if "robot" in self.model_fields_set and self.robot is not None:
            raise FieldProblems([("robots", "give either robot (one robot) or robots (several), not both")])
        names = self.robot_names
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise FieldProblems([("robots", f"expected unique robot names, got {', '.join(map(repr, repeated))} more than once")])
        self.__dict__["robot"] = self.robots[0]  # not setattr: that would validate (and call this) again
        return self

    @model_validator(mode="after")
    def _one_robot_tracker(self) -> Scenario:
        if self.robots is not None and self.sensors.tracker.profile != PERFECT:  # each robot would need its own tracker state
            raise FieldProblems([("sensors.tracker", f"profile {self.sensors.tracker.profile!r} tracks people for one robot; "
                                  f"a scenario with robots: uses {PERFECT!r}")])
        return self

    @model_validator(mode="after")
    def _replay_state_bounded(self) -> Scenario:
        replay = replay_cells(self.humans, self.max_steps)
        if replay is not None and replay[1] > MAX_REPLAY_CELLS:  # the episode's state, refused before the model allocates it
            raise FieldProblems([(replay[0], f"model replay: {replay[1]:,} (place, step) positions an episode (count x "
                                  f"(max_steps + 1)), more than {MAX_REPLAY_CELLS:,}; expected fewer places or a smaller max_steps")])
        return self

    @model_serializer(mode="wrap")
    def _dump_as_written(self, handler: Any) -> dict[str, Any]:
        dumped: dict[str, Any] = handler(self)
        if self.robots is None:
            dumped.pop("robots", None)
        else:
            dumped.pop("robot", None)  # filled from robots: writing it would declare both
        return dumped

    @property
    def robot_specs(self) -> list[Robot]:
        """Every robot, the ego robot (``robot``) first: ``robots`` or ``[robot]``."""
        return list(self.robots) if self.robots is not None else [self.robot]

    @property
    def robot_names(self) -> list[str]:
        """Every robot's agent name: ``["robot"]`` for one robot, each ``name`` or ``robot_<i>`` for several."""
        if self.robots is None:
            return ["robot"]
        return [robot.name or f"robot_{i}" for i, robot in enumerate(self.robots)]

    @property
    def robot_paths(self) -> list[str]:
        """Where each robot is written in the file: ``robot``, or ``robots.<i>``."""
        return ["robot"] if self.robots is None else [f"robots.{i}" for i in range(len(self.robots))]

    @field_validator("name")
    @classmethod
    def _folder_safe_name(cls, name: str | None) -> str | None:
        # the name becomes part of video file names: no separators, no "..", no absolute paths
        if name is not None and not is_safe_name(name):
            raise ValueError(f"expected {SAFE_NAME_EXPECTATION}, got {name!r}")
        return name

    @property
    def world_center(self) -> Point:
        return ((self.world.min[0] + self.world.max[0]) / 2, (self.world.min[1] + self.world.max[1]) / 2)

    @property
    def world_diagonal(self) -> float:
        return math.hypot(self.world.max[0] - self.world.min[0], self.world.max[1] - self.world.min[1])


JSON_SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"
"""The JSON Schema draft pydantic generates."""


def scenario_json_schema() -> dict[str, Any]:
    """JSON Schema of a scenario file, for editors (yaml-language-server) and other tools."""
    schema = Scenario.model_json_schema()
    schema.pop("title", None)
    schema["oneOf"] = [{"required": ["robot"]}, {"required": ["robots"]}]  # exactly one way to declare the robots
    return {"$schema": JSON_SCHEMA_DIALECT, "title": "crowdnav scenario", **schema}
