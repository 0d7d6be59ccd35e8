"""The people tracker behind the robot's ``humans`` sensing: named profiles and the scenario's ``sensors.tracker`` section.

Everything that reads the robot's tracker (the ``humans`` and ``plan`` modalities, the shield,
``baseline:onboard``) sees the people its tracker reports. ``perfect`` (the default) reports every
human within the ``humans`` range exactly, through walls and people, as crowdnav always did; the
other profiles model a real people detector and tracker: a field of view, occlusion, noisy
positions, missed detections, lost tracks and velocities estimated from the noisy positions
(:mod:`crowdnav.sensors.tracker`). docs/sensors.md#the-people-tracker gives every value's source.

A scenario picks a profile with ``sensors.tracker: NAME`` (or ``sensors.tracker.profile: NAME``,
also as ``--set``); any field given beside it overrides that profile's value.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from types import MappingProxyType
from typing import Annotated, Any

from pydantic import Field, field_validator, model_serializer, model_validator

from crowdnav.config_errors import FieldProblems
from crowdnav.scenario.fields import NonNegativeFloat, PositiveFloat, StrictModel
from crowdnav.suggest import unknown_name_message

PERFECT = "perfect"
"""The profile without a tracker: every human within range, exact (crowdnav's sensing before profiles)."""


@dataclass(frozen=True)
class TrackerProfile:
    """A tracker's values (the fields of :class:`TrackerSettings`, resolved)."""

    fov_deg: float
    max_range: float
    occlusion: bool
    min_visible: float
    detection_probability: float
    position_noise: float
    position_noise_per_m: float
    drop_probability: float
    max_missed: int
    confirm_hits: int
    window: int


TRACKER_PROFILES: Mapping[str, TrackerProfile | None] = MappingProxyType({
    PERFECT: None,
    # a 2-D LiDAR at knee height all around the robot with a DR-SPAAM-class detector (JRDB: 360 degrees, AP0.5 0.85)
    "lidar_tracker": TrackerProfile(fov_deg=360.0, max_range=8.0, occlusion=True, min_visible=1 / 3, detection_probability=0.85,
                                    position_noise=0.1, position_noise_per_m=0.0, drop_probability=0.01, max_missed=3,
                                    confirm_hits=2, window=5),
    # a forward RGB-D camera (RealSense D435 colour field of view, 69.4 degrees) with a CNN person detector
    "camera_front": TrackerProfile(fov_deg=69.4, max_range=6.0, occlusion=True, min_visible=2 / 3, detection_probability=0.9,
                                   position_noise=0.05, position_noise_per_m=0.01, drop_probability=0.01, max_missed=3,
                                   confirm_hits=2, window=5),
})
"""Profile name -> its values (None: ``perfect``, no tracker). docs/sensors.md#the-people-tracker cites each value."""

VALUE_FIELDS = tuple(TrackerProfile.__dataclass_fields__)
"""The fields a profile sets (and a scenario may override)."""


def _profile_value(description: str) -> Any:
    """A field that, when not given, takes the profile's value (filled in by :class:`TrackerSettings`)."""
    return Field(default=None, description=f"{description} Default: the profile's value.", json_schema_extra=_no_default)


def _no_default(schema: dict[str, Any]) -> None:
    schema.pop("default", None)  # its None only marks "not given"


Probability = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]


class TrackerSettings(StrictModel):
    """The robot's people tracker: a named profile, and fields overriding its values (``perfect``: none)."""

    profile: str = Field(
        default=PERFECT,
        description=f"Named tracker: {', '.join(TRACKER_PROFILES)} (docs/sensors.md#the-people-tracker).",
        json_schema_extra={"enum": list(TRACKER_PROFILES)},
    )
    fov_deg: Annotated[float, Field(gt=0, le=360)] | None = _profile_value("Field of view in degrees, centred on the heading.")
    max_range: PositiveFloat | None = _profile_value("People whose centre is farther than this (m) are not detected.")
    occlusion: bool | None = _profile_value("Walls, furniture and other people hide a person (exact ray casts).")
    min_visible: Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)] | None = _profile_value(
        "Fraction of a person's width (3 rays: centre and either side) that must be in sight to detect it.")
    detection_probability: Probability | None = _profile_value("Probability that a person in sight is detected at a step.")
    position_noise: NonNegativeFloat | None = _profile_value("Standard deviation (m, per axis) of a detection's position.")
    position_noise_per_m: NonNegativeFloat | None = _profile_value("Added to position_noise per metre of distance (m/m).")
    drop_probability: Annotated[float, Field(ge=0, lt=1, allow_inf_nan=False)] | None = _profile_value(
        "Probability per step that the tracker loses a track it holds (a false drop).")
    max_missed: Annotated[int, Field(ge=0, le=1000)] | None = _profile_value(
        "Steps a track coasts at its estimated velocity without a detection before it is dropped.")
    confirm_hits: Annotated[int, Field(ge=1, le=100)] | None = _profile_value("Detections before a new track is reported.")
    window: Annotated[int, Field(ge=2, le=16)] | None = _profile_value(
        "Last detections of a track its velocity is fitted over (least squares).")

    @model_validator(mode="before")
    @classmethod
    def _profile_name_alone(cls, value: Any) -> Any:
        return {"profile": value} if isinstance(value, str) else value  # `sensors.tracker: lidar_tracker`

    @field_validator("profile")
    @classmethod
    def _known_profile(cls, profile: str) -> str:
        if profile not in TRACKER_PROFILES:
            raise ValueError(unknown_name_message("tracker profile", profile, TRACKER_PROFILES))
        return profile

    @model_validator(mode="after")
    def _fill_from_profile(self) -> TrackerSettings:
        values = TRACKER_PROFILES[self.profile]
        given = [name for name in VALUE_FIELDS if name in self.model_fields_set]
        if values is None:
            if given:
                trackers = ", ".join(name for name, profile in TRACKER_PROFILES.items() if profile is not None)
                raise FieldProblems([(given[0], f"the {PERFECT!r} profile reports every human exactly and has no values to set; "
                                      f"choose a tracker profile ({trackers}) to override its {given[0]}")])
            return self
        for name, value in asdict(values).items():
            if name not in self.model_fields_set:
                self.__dict__[name] = value  # not setattr: that would validate (and call this) again
        return self

    @model_serializer(mode="wrap")
    def _dump_as_written(self, handler: Any) -> dict[str, Any]:
        dumped = handler(self)
        return {key: value for key, value in dumped.items() if key == "profile" or key in self.model_fields_set}

    @property
    def values(self) -> TrackerProfile | None:
        """The tracker's resolved values (None: ``perfect``, no tracker)."""
        if TRACKER_PROFILES[self.profile] is None:
            return None
        return TrackerProfile(**{name: getattr(self, name) for name in VALUE_FIELDS})
