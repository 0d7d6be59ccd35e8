"""The crowd part of a scenario file: social-force parameters, named groups, the crowd.

Part of the scenario schema (:mod:`crowdnav.scenario.schema` re-exports every name here).

A crowd is one or more **groups**. Files written before groups existed give one unnamed
population with ``humans.count`` / ``spawn`` / ``goal`` / ``goal_rule`` / ``on_goal``; that
is read as a single group named ``crowd`` and gives the same episodes as before. A file with
``humans.groups`` lists named groups instead, each with its own count, regions, speeds, goal
rule and colour; the body radius, ``see_robot`` and the social-force parameters stay shared.
Walking humans move by a **model**: the social force (the default) or ORCA (``humans.model``, which
a group's own ``model`` overrides; ORCA needs the optional package pyrvo).
A group with ``behaviour: stand`` is a standing conversation circle: its members stand still
all episode, evenly spaced on a circle whose centre is drawn from the group's ``spawn``.
A walking group with ``walk_together: true`` is a social group (friends, a family): its members
start on a small circle, share one goal (reached when the group's centre is within the goal
tolerance) and are kept together by the group terms of Moussaïd, Perozo, Garnier, Helbing and
Theraulaz (2010), "The walking behaviour of pedestrian social groups and its impact on crowd
dynamics", PLoS ONE 5(4): e10047, whose parameters are ``humans.group_force``.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BeforeValidator,
    Field,
    PrivateAttr,
    SerializerFunctionWrapHandler,
    ValidationError,
    WithJsonSchema,
    field_validator,
    model_serializer,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from crowdnav.paths import SAFE_NAME_EXPECTATION, is_safe_name
from crowdnav.scenario.crowd_presets import CROWD_PRESETS, DEFAULT_CROWD_PRESET, unknown_crowd_preset_message
from crowdnav.scenario.errors import show
from crowdnav.scenario.fields import (
    MAX_HUMANS,
    NonNegativeFloat,
    Point,
    PositiveFloat,
    Region,
    StrictModel,
    _count_shape,
    _pair_of,
)

# Decay lengths below 1 cm make exp(contact / range) overflow to inf (then inf * 0 = NaN) for
# human-sized radii, and no crowd model needs a force field thinner than that.
MIN_FORCE_RANGE = 0.01

CIRCLE_SPACING = 0.2
"""Default free space (m) between neighbours in a standing circle: people in conversation stand close."""

IMPLICIT_GROUP = "crowd"
"""Name of the single group a file without ``humans.groups`` describes."""

_COLOUR = re.compile(r"^#[0-9A-Fa-f]{6}$")
_GROUP_ONLY = ("count", "spawn", "goal_rule", "goal", "mirror_center", "on_goal")
"""Top-level crowd fields that belong to each group once ``humans.groups`` is used."""
_WALKING_ONLY = ("preferred_speed", "goal_rule", "goal", "mirror_center", "on_goal", "model", "walk_together")
"""A group's fields that a standing group must leave at their defaults."""


def _changed(model: StrictModel, fields: tuple[str, ...]) -> list[str]:
    """Those of ``fields`` whose value differs from the field's default (by value, not by whether the key was
    written: a dumped scenario, defaults included, loads again)."""
    return [f for f in fields if getattr(model, f) != type(model).model_fields[f].get_default(call_default_factory=True)]


def _field_error(field: str | tuple[str | int, ...], value: object, message: str) -> ValidationError:
    """A validation error located at ``field`` (a name or a path; a model validator's own errors sit at the model)."""
    error = PydanticCustomError("value_error", "Value error, {message}", {"message": message})  # worded like a ValueError
    loc = (field,) if isinstance(field, str) else field
    return ValidationError.from_exception_data("Humans", [InitErrorDetails(type=error, loc=loc, input=value)])


class SocialForce(StrictModel):
    """Parameters of the humans' social-force model (see docs/simulator.md for the formulas)."""

    goal_weight: NonNegativeFloat = Field(default=1.0, description="Weight of the goal force (dimensionless).")
    goal_saturation_distance: PositiveFloat = Field(
        default=1.0, description="Distance to the goal (m) beyond which the goal force has unit magnitude."
    )
    human_strength: NonNegativeFloat = Field(default=2.0, description="Human-human repulsion at contact (dimensionless).")
    human_range: float = Field(
        default=0.3, ge=MIN_FORCE_RANGE, description="Decay length of human-human repulsion in metres (at least 1 cm)."
    )
    obstacle_strength: NonNegativeFloat = Field(default=3.0, description="Obstacle repulsion at contact (dimensionless).")
    obstacle_range: float = Field(
        default=0.2, ge=MIN_FORCE_RANGE, description="Decay length of obstacle repulsion in metres (at least 1 cm)."
    )
    robot_strength: NonNegativeFloat = Field(
        default=2.0, description="Repulsion from the robot at contact, used only when see_robot is on."
    )
    robot_range: float = Field(
        default=0.3, ge=MIN_FORCE_RANGE, description="Decay length of robot repulsion in metres (at least 1 cm)."
    )
    relaxation_time: PositiveFloat = Field(
        default=0.5, description="Time (s) over which a human adapts its velocity to the desired one."
    )
    max_speed_factor: Annotated[float, Field(ge=1.0, allow_inf_nan=False)] = Field(
        default=1.2, description="Speed cap as a multiple of the human's preferred speed."
    )
    goal_tolerance: PositiveFloat = Field(default=0.3, description="A human has reached its goal within this distance (m).")


class Stall(StrictModel):
    """When a walking human counts as stalled, and then takes a new goal (docs/simulator.md#stalled-humans)."""

    time: PositiveFloat | None = Field(
        default=60.0, description="Window (s): a walking human that came less than `progress` m closer to its goal over a whole window "
        "has stalled and takes a new goal by its group's goal rule (checked every window; null: never)."
    )
    progress: PositiveFloat = Field(default=0.5, description="Progress (m) toward its goal a human must make per stall window.")


class GroupForce(StrictModel):
    """The group terms of Moussaïd et al. (2010), PLoS ONE 5(4): e10047, for groups with ``walk_together``; defaults: the paper's
    calibrated values (docs/simulator.md#walking-groups)."""

    gaze_strength: NonNegativeFloat = Field(
        default=4.0, description="beta_1 (1/s): slows a member who must turn its head more than vision_angle to see the group's centre."
    )
    attraction_strength: NonNegativeFloat = Field(
        default=3.0, description="beta_2 (m/s^2): pull toward the group's centre of mass, on a member farther than the spread from it."
    )
    attraction_spread: NonNegativeFloat = Field(
        default=0.5, description="Metres per member beyond the first: the attraction acts beyond (N - 1) * this from the centre."
    )
    repulsion_strength: NonNegativeFloat = Field(
        default=1.0, description="beta_3 (m/s^2): push apart from each fellow member closer than repulsion_distance."
    )
    repulsion_distance: PositiveFloat = Field(default=0.8, description="d_0 (m): fellow members closer than this (centre to centre) push apart.")
    vision_angle: Annotated[float, Field(gt=0.0, le=180.0, allow_inf_nan=False)] = Field(
        default=90.0, description="phi (degrees): half-angle of the vision field about the walking direction."
    )


CROWD_MODEL_NAMES: tuple[str, ...] = ("social_force", "orca", "replay")
"""The crowd models a scenario may name (``humans.model``, a group's ``model``), the default first: one per class of
:data:`crowdnav.crowd.CROWD_MODELS`, in the same order (importing :mod:`crowdnav.crowd` checks it). A new model adds its name here."""


def _known_model(value: object) -> object:
    """A crowd model's name, read from :data:`CROWD_MODEL_NAMES` when validated (the message is the one a ``Literal`` gives)."""
    if not isinstance(value, str) or value not in CROWD_MODEL_NAMES:
        names = [repr(name) for name in CROWD_MODEL_NAMES]
        expected = " or ".join(names) if len(names) < 3 else f"{', '.join(names[:-1])} or {names[-1]}"
        raise PydanticCustomError("literal_error", "Input should be {expected}", {"expected": expected})
    return value


HumanModel = Annotated[str, BeforeValidator(_known_model), WithJsonSchema({"enum": list(CROWD_MODEL_NAMES), "type": "string"})]
"""How walking humans choose their velocity: a name of :data:`CROWD_MODEL_NAMES` (the social force, ORCA, ...)."""


class Orca(StrictModel):
    """Parameters of ORCA, for humans with ``model: orca`` and the ORCA robot baseline (docs/simulator.md)."""

    neighbour_distance: PositiveFloat = Field(default=10.0, description="Other agents farther than this (m, centre to centre) are ignored.")
    max_neighbours: Annotated[int, Field(ge=1, le=1000)] = Field(default=10, description="At most this many nearest agents are avoided.")
    time_horizon: PositiveFloat = Field(
        default=5.0, description="Velocities are chosen collision-free with other agents for this long (s)."
    )
    # 2 s, not RVO2's customary 5: in furnished rooms 5 s makes every edge within ~7 m a constraint,
    # which halved the humans' goal arrivals and doubled the step's cost (benchmarks/bench_orca.py)
    time_horizon_obstacles: PositiveFloat = Field(
        default=2.0, description="Velocities are chosen collision-free with walls and furniture for this long (s)."
    )
    safety_margin: NonNegativeFloat = Field(default=0.01, description="Added to every body radius ORCA sees (m).")


MAX_REPLAY_CELLS = 2_000_000
"""Most (place, step) cells of one replay episode: the replaying group's count x (max_steps + 1), each about 56 bytes of
episode state (positions, velocities, targets, holders), checked before any is allocated: e.g. 1,000 places over 2,000
steps, or 100 over 20,000."""


def replay_cells(humans: Humans, max_steps: int) -> tuple[str, int] | None:
    """(the replaying group's count field, its places x (max_steps + 1)) when a group replays (None: no group does)."""
    for path, group in humans.crowd:
        if not group.standing and group.model == "replay" and isinstance(group.count, int):
            field = "humans.count" if path == "humans" else f"{path}.count"
            return field, group.count * (max_steps + 1)
    return None


class Replay(StrictModel):
    """The recording that humans with ``model: replay`` follow (docs/simulator.md#recorded-crowds)."""

    file: str = Field(
        min_length=1, max_length=4096, description="The recording: an ETH/UCY obsmat.txt, a 'frame id x y' text file or TrajNet++ ndjson; "
        "a relative path is read from the scenario file's folder and must stay inside it.",
    )
    format: Literal["auto", "obsmat", "frames", "trajnet"] = Field(
        default="auto", description="The file's layout; auto: TrajNet++ for .ndjson/.json or JSON lines, else by the column count (8 or 4)."
    )
    annotation_step: PositiveFloat = Field(
        default=0.4, description="Seconds between two annotations (ETH/UCY: 0.4); a TrajNet++ file's scene fps overrides it."
    )
    offset: Point = Field(default=(0.0, 0.0), description="Added to every recorded position [x, y] (m), to place the recording in the world.")
    react_within: PositiveFloat | None = Field(
        default=None, description="null: pure replay (people ignore the robot). A distance (m): a recorded person whose centre comes "
        "within it of a robot's switches to the social force toward its recorded future position for the rest of its track.",
    )
    react_lookahead: PositiveFloat = Field(
        default=2.0, description="Seconds ahead on its own recording that a reacting person walks toward (with react_within).",
    )


def _check_count(count: int | tuple[int, int]) -> int | tuple[int, int]:
    low, high = count if isinstance(count, tuple) else (count, count)
    if low < 0 or low > high or high > MAX_HUMANS:
        raise ValueError(f"expected a count from 0 to {MAX_HUMANS:,}, or [min, max] with 0 <= min <= max <= {MAX_HUMANS:,}, got {show(count)}")
    return count


def _check_speed(speed: tuple[float, float] | None) -> tuple[float, float] | None:
    if speed is not None and speed[0] > speed[1]:
        raise ValueError(f"expected [min, max] with min <= max, got {list(speed)}")
    return speed


Count = Annotated[int | tuple[int, int], BeforeValidator(_count_shape), AfterValidator(_check_count)]
"""A number of humans, or [min, max] drawn per episode."""
SpeedRange = Annotated[
    tuple[PositiveFloat, PositiveFloat],
    BeforeValidator(_pair_of("a speed range [min, max] of two positive numbers in m/s")),
    AfterValidator(_check_speed),
]
"""[min, max] walking speed in m/s."""


class HumanGroup(StrictModel):
    """One named group of the crowd, with its own size, regions, speeds, goal rule and colour."""

    name: str = Field(description="Group name, unique in the file (shown in legends and per-agent infos).")
    count: Count = Field(description="Group size: a number, or [min, max] sampled uniformly per episode.")
    behaviour: Literal["walk", "stand"] = Field(
        default="walk", description="walk: members walk to goals (by the group's model); stand: a standing circle that never moves."
    )
    model: HumanModel | None = Field(
        default=None, description="social_force or orca: how members choose their velocity (default: humans.model; walk only)."
    )
    preferred_speed: SpeedRange | None = Field(
        default=None, description="[min, max] preferred walking speed in m/s, per member (default: humans.preferred_speed; walk only)."
    )
    spawn: list[Region] = Field(
        min_length=1, description="walk: regions members start in; stand: regions the circle's centre is drawn from."
    )
    goal_rule: Literal["sample", "mirror"] = Field(
        default="sample", description="sample: goals drawn from `goal`; mirror: the start mirrored through mirror_center (walk only)."
    )
    goal: list[Region] = Field(default_factory=list, description="Regions goals are sampled from (walk, goal_rule: sample).")
    mirror_center: Point | None = Field(
        default=None, description="Centre of the mirror rule [x, y] in metres (default: world centre; walk only)."
    )
    on_goal: Literal["new_goal", "stop", "respawn"] = Field(
        default="new_goal", description="What a member does at its goal: take a new goal, stop there, or respawn (walk only)."
    )
    circle_radius: PositiveFloat | None = Field(
        default=None,
        description=f"Radius (m) of the standing circle's member centres (stand only; default: {CIRCLE_SPACING:g} m between neighbours).",
    )
    colour: str | None = Field(default=None, description="Drawing colour '#rrggbb' (default: one of the renderer's group colours).")
    walk_together: bool = Field(
        default=False, description="Members walk as one social group: one shared goal, kept together by humans.group_force (walk only)."
    )

    @field_validator("name")
    @classmethod
    def _safe_name(cls, name: str) -> str:
        if not is_safe_name(name):
            raise ValueError(f"expected {SAFE_NAME_EXPECTATION}, got {name!r}")
        return name

    @field_validator("colour")
    @classmethod
    def _hex_colour(cls, colour: str | None) -> str | None:
        if colour is not None and not _COLOUR.match(colour):
            raise ValueError(f"expected a colour '#rrggbb' (six hex digits), got {colour!r}")
        return colour

    @model_validator(mode="after")
    def _walking_fields_only_when_walking(self) -> HumanGroup:
        if self.behaviour == "stand":
            walking = _changed(self, _WALKING_ONLY)
            if walking:
                raise ValueError(f"a standing group does not walk; remove {', '.join(walking)} (or set behaviour: walk)")
        elif self.circle_radius is not None:
            raise ValueError("circle_radius only applies to standing groups; remove it or set behaviour: stand")
        elif self.walk_together and self.on_goal == "respawn":
            raise ValueError("a group that walks together cannot respawn one by one; expected on_goal: new_goal or stop")
        return self

    @property
    def min_count(self) -> int:
        return self.count[0] if isinstance(self.count, tuple) else self.count

    @property
    def max_count(self) -> int:
        return self.count[1] if isinstance(self.count, tuple) else self.count

    @property
    def standing(self) -> bool:
        return self.behaviour == "stand"

    @property
    def on_circle(self) -> bool:
        """Members start on a circle around one drawn centre: a standing circle, or a group that walks together."""
        return self.behaviour == "stand" or self.walk_together

    def circle_radius_for(self, human_radius: float) -> float:
        """Radius (m) of the circle members start on: the given one, or neighbours CIRCLE_SPACING apart at the largest count."""
        if self.circle_radius is not None:
            return self.circle_radius
        n = self.max_count
        if n < 2:
            return 0.0
        return (2 * human_radius + CIRCLE_SPACING) / (2 * math.sin(math.pi / n))


class Humans(StrictModel):
    """The crowd: one population (count, spawn, goal, ...) or named ``groups``; radius and model parameters are shared."""

    count: Count = Field(default=0, description="Crowd size: a number, or [min, max] sampled uniformly per episode.")
    radius: PositiveFloat = Field(default=0.3, description="Body radius of every human in metres.")
    preferred_speed: SpeedRange = Field(
        default=(0.8, 1.2), description="[min, max] preferred walking speed in m/s, sampled per human (groups' default)."
    )
    spawn: list[Region] = Field(default_factory=list, description="Regions humans start in.")
    goal_rule: Literal["sample", "mirror"] = Field(
        default="sample", description="sample: goals drawn from `goal`; mirror: goal is the start mirrored through mirror_center."
    )
    goal: list[Region] = Field(default_factory=list, description="Regions goals are sampled from (goal_rule: sample).")
    mirror_center: Point | None = Field(
        default=None, description="Centre of the mirror rule [x, y] in metres (default: world centre)."
    )
    on_goal: Literal["new_goal", "stop", "respawn"] = Field(
        default="new_goal", description="What a human does at its goal: take a new goal, stop there, or respawn."
    )
    groups: list[HumanGroup] = Field(
        default_factory=list, max_length=64,
        description="Named groups (at most 64), instead of count/spawn/goal/goal_rule/mirror_center/on_goal above.",
    )
    see_robot: bool = Field(default=False, description="Whether humans avoid the robot (off as in the paper).")
    routing: Literal["straight", "geodesic"] = Field(
        default="straight",
        description="How social-force humans head for their goal: straight at it (the paper), or geodesic: along the shortest "
                    "path around walls and furniture when the straight line is blocked (docs/simulator.md#routing-around-furniture).",
    )
    model: HumanModel = Field(
        default="social_force",
        description="How walking humans choose their velocity: social_force or orca (needs the orca extra: "
                    "pip install -e \".[orca]\" in crowdnav's clone); groups may override.",
    )
    preset: str = Field(
        default=DEFAULT_CROWD_PRESET, json_schema_extra={"enum": list(CROWD_PRESETS)},
        description="Named crowd values the preferred_speed and social_force fields not given here take: paper (the schema's "
                    "defaults) or calibrated (normal preferred speeds, parameters fitted to pedestrians; docs/simulator.md#crowd-presets).",
    )
    social_force: SocialForce = Field(default_factory=SocialForce, description="Social-force model parameters.")
    group_force: GroupForce = Field(
        default_factory=GroupForce, description="Group terms (Moussaid et al. 2010) of the groups with walk_together: true."
    )
    stall: Stall = Field(default_factory=Stall, description="Stalled humans: no progress toward their goal for a while gives them a new goal.")
    orca: Orca = Field(default_factory=Orca, description="ORCA parameters (humans with model: orca, the ORCA robot baseline).")
    replay: Replay | None = Field(default=None, description="The recording humans with model: replay follow (null: none).")
    _from_preset: frozenset[str] = PrivateAttr(default=frozenset())
    """The fields the preset filled in (``preferred_speed``, ``social_force.<name>``): left out of dumps, so a dump loads the same."""

    @field_validator("preset")
    @classmethod
    def _known_preset(cls, preset: str) -> str:
        if preset not in CROWD_PRESETS:
            raise ValueError(unknown_crowd_preset_message(preset))
        return preset

    @model_validator(mode="after")
    def _fill_from_preset(self) -> Humans:
        # fields never given take the preset's values (not setattr: that would validate again)
        preset, filled = CROWD_PRESETS[self.preset], set()
        if preset.preferred_speed is not None and "preferred_speed" not in self.model_fields_set:
            self.__dict__["preferred_speed"] = preset.preferred_speed
            filled.add("preferred_speed")
        for name, value in preset.social_force.items():
            if name not in self.social_force.model_fields_set:
                self.social_force.__dict__[name] = value
                filled.add(f"social_force.{name}")
        self._from_preset = frozenset(filled)
        return self

    @model_serializer(mode="wrap")
    def _dump_as_written(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        dumped: dict[str, Any] = handler(self)
        if self.preset == DEFAULT_CROWD_PRESET and "preset" not in self.model_fields_set:
            dumped.pop("preset", None)  # files without a preset dump as they always did
        for name in self._from_preset:
            if name.startswith("social_force."):
                dumped["social_force"].pop(name.removeprefix("social_force."), None)
            else:
                dumped.pop(name, None)
        return dumped

    @property
    def speed_normals(self) -> list[tuple[float, float] | None]:
        """Per group of :attr:`crowd`: the (mean, sd) of the normal its walkers draw preferred speeds from, clipped to their
        range, when they take the preset's range (None: uniform in the range)."""
        normal = CROWD_PRESETS[self.preset].speed_normal
        if normal is None or "preferred_speed" not in self._from_preset:
            return [None] * len(self.crowd)
        if not self.groups:
            return [normal]
        return [None if group.standing or group.preferred_speed is not None else normal for group in self.groups]

    @model_validator(mode="after")
    def _replay_has_a_recording(self) -> Humans:
        replaying = [(path, group) for path, group in self.crowd if not group.standing and group.model == "replay"]
        if not replaying:
            return self
        path = replaying[0][0]
        where = "model" if path == "humans" else f"{path.removeprefix('humans.')}.model"
        if self.replay is None:
            raise _field_error(tuple(where.split(".")) if "." in where else where, "replay",
                               "model replay needs a recording: add humans.replay with its file")
        if len(replaying) > 1:
            raise _field_error(tuple(replaying[1][0].removeprefix("humans.").split(".")) + ("model",), "replay",
                               "one group may replay the recording; expected model replay on one group only")
        if isinstance(replaying[0][1].count, tuple):
            raise _field_error(tuple(path.removeprefix("humans.").split(".")) + ("count",) if path != "humans" else "count",
                               list(replaying[0][1].count), "the replaying group's count is its number of places for recorded "
                               "people (those present at once); expected one number, not a range")
        return self

    @model_validator(mode="after")
    def _one_way_to_describe_the_crowd(self) -> Humans:
        if self.groups:
            both = _changed(self, _GROUP_ONLY)
            if both:  # reported at the first such field, so its line (or "from override") is named
                fields = ", ".join(f"humans.{f}" for f in both)
                raise _field_error(both[0], getattr(self, both[0]), f"give the crowd either as humans.groups or with {fields}, "
                                   "not both; move these fields into each group")
            names = [group.name for group in self.groups]
            repeated = sorted({name for name in names if names.count(name) > 1})
            if repeated:
                raise ValueError(f"expected unique group names, got {', '.join(map(repr, repeated))} more than once")
            if sum(group.max_count for group in self.groups) > MAX_HUMANS:
                raise ValueError(f"expected at most {MAX_HUMANS:,} humans over all groups")
            for i, group in enumerate(self.groups):
                if group.walk_together and (group.model or self.model) == "orca":
                    raise _field_error(("groups", i, "walk_together"), True, "a group walks together by the social-force group "
                                       "terms; expected model: social_force for it (or walk_together: false)")
        return self

    @property
    def crowd(self) -> list[tuple[str, HumanGroup]]:
        """Every group with the dotted path of its fields in the file (``humans.groups.1`` or, for a
        file without groups, ``humans`` for the implicit group ``crowd``); walking groups' speeds and model filled in."""
        if not self.groups:
            implicit = HumanGroup.model_construct(
                name=IMPLICIT_GROUP, count=self.count, behaviour="walk", preferred_speed=self.preferred_speed, spawn=self.spawn,
                goal_rule=self.goal_rule, goal=self.goal, mirror_center=self.mirror_center, on_goal=self.on_goal,
                circle_radius=None, colour=None, model=self.model,
            )
            return [("humans", implicit)]
        return [(f"humans.groups.{i}", self._filled_in(group)) for i, group in enumerate(self.groups)]

    def _filled_in(self, group: HumanGroup) -> HumanGroup:
        """A walking group with the crowd's defaults for what it leaves out (speeds, model)."""
        if group.standing:
            return group
        missing: dict[str, object] = {"preferred_speed": self.preferred_speed} if group.preferred_speed is None else {}
        if group.model is None:
            missing["model"] = self.model
        return group.model_copy(update=missing) if missing else group

    @property
    def min_count(self) -> int:
        return sum(group.min_count for _, group in self.crowd)

    @property
    def max_count(self) -> int:
        return sum(group.max_count for _, group in self.crowd)

    @property
    def max_preferred_speed(self) -> float:
        """The fastest preferred speed any walking member can draw (m/s; humans.preferred_speed's max without walkers)."""
        # walkers always have one once filled in (:meth:`_filled_in`); the None test is for the type
        speeds = [group.preferred_speed[1] for _, group in self.crowd if not group.standing and group.preferred_speed is not None]
        return max(speeds, default=self.preferred_speed[1])
