"""Field types and the static-geometry models of a scenario file: points, regions, world, walls, furniture.

Part of the scenario schema (:mod:`crowdnav.scenario.schema` re-exports every name here). Shape
checks run before pydantic's own, so a wrong shape reads "expected a point [x, y] ..." rather
than pydantic's generic tuple or union message.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from crowdnav.scenario.errors import show

# Lengths, speeds, times and strengths beyond 10 km (or 10^4 of their unit) are typos that would
# only reach shapely or numpy as overflow or GEOS errors: refuse them here, naming the field.
MAX_MAGNITUDE = 10_000.0
PositiveFloat = Annotated[float, Field(gt=0, le=MAX_MAGNITUDE, allow_inf_nan=False)]
NonNegativeFloat = Annotated[float, Field(ge=0, le=MAX_MAGNITUDE, allow_inf_nan=False)]
FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
Coordinate = Annotated[float, Field(ge=-MAX_MAGNITUDE, le=MAX_MAGNITUDE, allow_inf_nan=False)]

# The shape checks below run before pydantic's own, so that a wrong shape reads
# "expected a point [x, y] ..." instead of pydantic's generic tuple/union messages.


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _pair_of(what: str) -> Callable[[Any], Any]:
    def check(value: Any) -> Any:
        if isinstance(value, (list, tuple)) and len(value) == 2:
            return tuple(value)  # YAML gives lists; the models are strict about tuples
        raise ValueError(f"expected {what}, got {show(value)}")

    return check


Point = Annotated[tuple[Coordinate, Coordinate], BeforeValidator(_pair_of("a point [x, y] of two numbers in metres"))]
"""A 2-D point ``[x, y]`` in metres, world frame."""
Size = Annotated[
    tuple[PositiveFloat, PositiveFloat], BeforeValidator(_pair_of("a size [w, h] of two positive numbers in metres"))
]
"""Width and depth ``[w, h]`` in metres."""


def _is_whole(value: Any) -> bool:
    # ints of any size (a 400-digit count must fail with its field's name, not overflow in float())
    return isinstance(value, int) and not isinstance(value, bool) or isinstance(value, float) and value.is_integer()


def _count_shape(value: Any) -> Any:
    whole = _is_whole(value)
    pair = isinstance(value, (list, tuple)) and len(value) == 2 and all(_is_whole(v) for v in value)
    if whole or pair:
        return tuple(int(v) for v in value) if pair else int(value)
    raise ValueError(f"expected a whole number of humans, or [min, max] sampled per episode, got {show(value)}")


def _heading_shape(value: Any) -> Any:
    if value in ("random", "toward_goal") or _is_number(value):
        return value
    raise ValueError(f"expected 'random', 'toward_goal' or an angle in degrees, got {show(value)}")


# Caps that keep loading any file under 2 s on a laptop (2,000 discs load in ~1 s); the library's
# busiest scenario has a few dozen obstacles.
MAX_OBSTACLES = 2_000
MAX_HUMANS = 10_000
MAX_VERTICES = 10_000


class StrictModel(BaseModel):
    """Base model: unknown keys are errors, values are checked on assignment too, and types are strict
    (no ``true`` or ``"1e3"`` where a number belongs: YAML's quoting must not change a value's meaning)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, strict=True)


# --------------------------------------------------------------------------- regions


class RectangleRegion(StrictModel):
    """Axis-aligned rectangle given by its two corners."""

    type: Literal["rectangle"] = Field(description="Region kind.")
    min: Point = Field(description="Lower-left corner [x, y] in metres.")
    max: Point = Field(description="Upper-right corner [x, y] in metres.")

    @model_validator(mode="after")
    def _corners_ordered(self) -> RectangleRegion:
        if not (self.min[0] < self.max[0] and self.min[1] < self.max[1]):
            raise ValueError(f"expected min < max on both axes, got min={list(self.min)} max={list(self.max)}")
        return self


class PolygonRegion(StrictModel):
    """Simple polygon given by its vertices."""

    type: Literal["polygon"] = Field(description="Region kind.")
    points: list[Point] = Field(min_length=3, description="Vertices [[x, y], ...] in metres, in order.")


class PointsRegion(StrictModel):
    """An explicit list of candidate positions; one is picked per agent."""

    type: Literal["points"] = Field(description="Region kind.")
    points: list[Point] = Field(min_length=1, description="Candidate positions [[x, y], ...] in metres.")


class CircleRegion(StrictModel):
    """A disc, or only its perimeter (for circle-crossing layouts)."""

    type: Literal["circle"] = Field(description="Region kind.")
    center: Point = Field(description="Centre [x, y] in metres.")
    radius: PositiveFloat = Field(description="Radius in metres.")
    perimeter: bool = Field(default=False, description="Sample on the circle itself instead of inside the disc.")


Region = Annotated[
    RectangleRegion | PolygonRegion | PointsRegion | CircleRegion,
    Field(discriminator="type"),
]

# ------------------------------------------------------------------- static geometry


class World(StrictModel):
    """Extent of the simulated world."""

    min: Point = Field(default=(-5.0, -5.0), description="Lower-left corner [x, y] of the world in metres.")
    max: Point = Field(default=(5.0, 5.0), description="Upper-right corner [x, y] of the world in metres.")
    boundary_walls: bool = Field(default=True, description="Surround the world with walls (false: open space).")
    boundary_thickness: PositiveFloat = Field(default=0.1, description="Thickness of the boundary walls in metres.")
    points: list[Point] | None = Field(
        default=None, min_length=3, max_length=MAX_VERTICES,
        description="Floor polygon [[x, y], ...] (an L, a T, rooms joined by doors); the rest of [min, max] is solid. "
                    "min/max default to its bounds.",
    )

    @model_validator(mode="before")
    @classmethod
    def _bounds_of_the_floor(cls, data: Any) -> Any:
        # a polygon world needs no corners written twice: its bounding box is the world's extent
        if isinstance(data, dict) and isinstance(data.get("points"), list) and data["points"]:
            try:
                xs, ys = zip(*[(float(p[0]), float(p[1])) for p in data["points"]], strict=True)
            except (TypeError, ValueError, IndexError):
                return data  # the field's own validation reports the shape
            data = {"min": [min(xs), min(ys)], "max": [max(xs), max(ys)], **data}
        return data

    @model_validator(mode="after")
    def _corners_ordered(self) -> World:
        if not (self.min[0] < self.max[0] and self.min[1] < self.max[1]):
            raise ValueError(f"expected min < max on both axes, got min={list(self.min)} max={list(self.max)}")
        return self


class Wall(StrictModel):
    """A wall: a polyline thickened into a polygon."""

    points: list[Point] = Field(min_length=2, max_length=MAX_VERTICES, description="Polyline vertices [[x, y], ...] in metres (at most 10,000).")
    thickness: PositiveFloat = Field(default=0.1, description="Wall thickness in metres.")
    name: str | None = Field(default=None, description="Optional label.")


class PolygonFurniture(StrictModel):
    """Furniture of arbitrary polygonal shape."""

    type: Literal["polygon"] = Field(description="Shape kind.")
    points: list[Point] = Field(min_length=3, description="Vertices [[x, y], ...] in metres, in order.")
    name: str | None = Field(default=None, description="Optional label, e.g. 'sofa'.")


class RectangleFurniture(StrictModel):
    """A (possibly rotated) rectangular piece of furniture."""

    type: Literal["rectangle"] = Field(description="Shape kind.")
    center: Point = Field(description="Centre [x, y] in metres.")
    size: Size = Field(description="Width and depth [w, h] in metres.")
    angle: FiniteFloat = Field(default=0.0, description="Rotation in degrees, counter-clockwise.")
    name: str | None = Field(default=None, description="Optional label, e.g. 'table'.")


class CircleFurniture(StrictModel):
    """A round piece of furniture (kept as an exact circle)."""

    type: Literal["circle"] = Field(description="Shape kind.")
    center: Point = Field(description="Centre [x, y] in metres.")
    radius: PositiveFloat = Field(description="Radius in metres.")
    name: str | None = Field(default=None, description="Optional label, e.g. 'round table'.")


Furniture = Annotated[
    PolygonFurniture | RectangleFurniture | CircleFurniture,
    Field(discriminator="type"),
]
