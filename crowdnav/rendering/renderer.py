"""Draw a simulator state with pygame: to an ``rgb_array`` frame, or into a window.

Layout: a status bar on top (one line of heads-up text, cut to fit), the map below it, and a
panel beside it (below it for wide worlds such as corridors) holding the LEOG inset, a legend of
what is drawn and a scale bar in metres, so nothing covers the map. On the map: world bounds,
walls and furniture; humans as discs with a heading tick and a short trail; the robot with its heading and its path so far; its goal as a
filled disc of the goal radius with a cross; optional overlays (LIDAR rays, the closest-obstacle
point, the humans' goals). The map's scale is chosen from the world bounds so every scenario fits.

Frames are drawn off-screen on a plain pygame Surface, so ``rgb_array`` needs no display; a
window is opened only by :meth:`Renderer.show`. pygame is imported when the first renderer is
built, so importing crowdnav (and building an env without a render mode) never loads it.
"""

from __future__ import annotations

import math
import os
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from crowdnav.crowd.replay import empty_places
from crowdnav.rendering.group_links import draw_group_links
from crowdnav.sim.simulator import Simulator

if TYPE_CHECKING:
    import pygame

TRACK_ARROW = 1.0
"""Seconds of estimated velocity a track's arrow shows (the metres a tracked person walks in that time)."""


@dataclass(frozen=True)
class Palette:
    """The fixed colour scheme (RGB)."""

    background: tuple[int, int, int] = (248, 248, 245)
    outside: tuple[int, int, int] = (225, 225, 222)
    wall: tuple[int, int, int] = (70, 70, 80)
    furniture: tuple[int, int, int] = (160, 125, 90)
    human: tuple[int, int, int] = (66, 120, 200)
    human_trail: tuple[int, int, int] = (160, 190, 235)
    human_goal: tuple[int, int, int] = (120, 160, 220)
    robot: tuple[int, int, int] = (210, 60, 50)
    robot_path: tuple[int, int, int] = (235, 140, 130)
    goal: tuple[int, int, int] = (30, 150, 80)
    goal_fill: tuple[int, int, int] = (190, 232, 200)
    panel: tuple[int, int, int] = (236, 236, 232)
    lidar: tuple[int, int, int] = (235, 140, 20)
    lidar_ray: tuple[int, int, int] = (250, 225, 175)
    closest: tuple[int, int, int] = (190, 40, 190)
    track: tuple[int, int, int] = (0, 160, 170)
    """The people tracker's estimates (rings, velocity arrows)."""
    field_of_view: tuple[int, int, int] = (150, 210, 215)
    """The people tracker's field of view and range."""
    text: tuple[int, int, int] = (20, 20, 20)
    outline: tuple[int, int, int] = (30, 30, 30)
    groups: tuple[tuple[int, int, int], ...] = ((66, 120, 200), (215, 135, 40), (125, 80, 175), (70, 155, 90), (200, 80, 140), (110, 110, 110))
    robots: tuple[tuple[int, int, int], ...] = ((210, 60, 50), (0, 150, 150), (235, 175, 0), (150, 50, 200), (120, 70, 30), (255, 105, 180),
                                                (40, 40, 40), (0, 200, 90))
    """Several robots (``robots:``): robot k's colour (the first is ``robot``), its path and goal in the same hue."""
    """Colours of human groups without their own ``colour``, in file order (the first is ``human``)."""


@dataclass
class Overlays:
    """Optional sensor data drawn on top of the scene (robot frame data is placed by the renderer)."""

    lidar: tuple[np.ndarray, np.ndarray, float] | None = None
    """(bearings relative to the heading in rad, ranges in m, max range in m) of the beams."""
    leog: np.ndarray | None = None
    """(H, W) or (1, H, W) occupancy grid drawn as an inset (non-zero = occupied)."""
    closest_point: complex | None = None
    """Closest obstacle point in the robot frame (x forward, y left), metres."""
    human_goals: bool = False
    """Mark every human's goal."""
    tracks: tuple[np.ndarray, np.ndarray] | None = None
    """The people the robot's tracker reports: (estimated centres, estimated velocities), complex, world frame."""
    field_of_view: tuple[float, float] | None = None
    """The tracker's (field of view in rad, range in m), centred on the robot's heading."""


@dataclass
class RenderOptions:
    """Which overlays the environments add when rendering."""

    max_side: int = 640
    """Longest side of the frame in pixels: status bar, map and side panel (sizes are multiples of 16 for video codecs)."""
    lidar: bool = True
    """Draw the LIDAR rays."""
    leog: bool = True
    """Draw the occupancy grid as an inset."""
    closest_obstacle: bool = True
    """Mark the closest obstacle point."""
    human_goals: bool = False
    """Mark the humans' goals."""
    trail_length: int = 12
    """Steps of trail behind each human."""
    tracks: bool = True
    """With a tracker profile (``sensors.tracker``): draw the people it reports, their estimated velocities and its field of view."""


@dataclass
class _History:
    robot: list[complex] = field(default_factory=list)
    humans: deque[np.ndarray] = field(default_factory=lambda: deque(maxlen=12))
    robots: list[np.ndarray] = field(default_factory=list)
    """Several robots: every robot's centre per record (:data:`crowdnav.sim.robots.PARKED` once it left)."""


class Renderer:
    """Draws one scenario's states; call :meth:`reset` at each episode start, :meth:`frame` per step."""

    def __init__(self, sim: Simulator, options: RenderOptions | None = None):
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # pygame's first import: no greeting on stdout
        import pygame  # (imported here, not at the top: an env without a render mode never loads it)

        self.sim = sim
        self.options = options or RenderOptions()
        self.palette = Palette()
        self._group_colours = _group_colours(sim, self.palette)
        world = sim.scenario.world
        margin = 0.4 + (world.boundary_thickness if world.boundary_walls else 0.0)
        self._x0, self._y1 = world.min[0] - margin, world.max[1] + margin
        span_x, span_y = world.max[0] - world.min[0] + 2 * margin, world.max[1] - world.min[1] + 2 * margin
        side = self.options.max_side
        pygame.font.init()
        self._font = pygame.font.Font(None, max(14, side // 36))
        self._row = self._font.get_linesize() + 4  # legend row height
        self._bar = self._font.get_linesize() + 8  # status bar height
        # Wide worlds (corridors) get the panel below the map, the others beside it.
        self._below = span_x > 1.6 * span_y
        if self._below:
            inset = _floor_16(0.22 * side)
            panel_h = inset + self._row + 24
            scale = min(side / span_x, (side - self._bar - panel_h) / span_y)
        else:
            panel_w = _multiple_of_16(max(176, 0.28 * side))
            inset = panel_w - 24
            # the map takes what the bar and the panel leave of a max_side x max_side frame
            scale = min((side - panel_w) / span_x, (side - self._bar) / span_y)
        map_w, map_h = _floor_16(span_x * scale), _floor_16(span_y * scale)
        self.scale = min(map_w / span_x, map_h / span_y)
        self._map_rect = pygame.Rect(0, self._bar, map_w, map_h)
        self._inset_side = inset
        if self._below:
            self.size = (map_w, _ceil_16(self._bar + map_h + panel_h))
            self._panel_rect = pygame.Rect(0, self._bar + map_h, map_w, self.size[1] - self._bar - map_h)
        else:
            tallest = 8 + inset + self._row + 10 + 10 * self._row + 3 * self._row  # inset, every legend entry, scale bar
            self.size = (map_w + panel_w, _ceil_16(self._bar + max(map_h, tallest)))
            self._panel_rect = pygame.Rect(map_w, self._bar, panel_w, self.size[1] - self._bar)
        self._static = self._draw_static()
        self._history = _History(humans=deque(maxlen=self.options.trail_length))
        self._window: pygame.Surface | None = None
        self._clock: pygame.time.Clock | None = None

    # ------------------------------------------------------------------ public

    def reset(self) -> None:
        """Forget trails and the robot's path (a new episode starts)."""
        self._history = _History(humans=deque(maxlen=self.options.trail_length))

    def record(self) -> None:
        """Append the current positions to the trails; call once per reset/step."""
        team = self.sim.team
        if team is None or team.state.active[0]:  # the first robot's path ends where it left
            self._history.robot.append(self.sim.robot_position)
        self._history.humans.append(self.sim.human_positions.copy())
        if team is not None:
            self._history.robots.append(self.sim.robot_positions)

    def frame(self, overlays: Overlays | None = None, hud: str = "") -> np.ndarray:
        """The current state as a ``uint8`` array of shape (H, W, 3)."""
        import pygame

        surface = self._draw(overlays or Overlays(), hud)
        return np.ascontiguousarray(pygame.surfarray.pixels3d(surface).transpose(1, 0, 2))

    def show(self, overlays: Overlays | None = None, hud: str = "", fps: float = 10.0) -> None:
        """Draw into a window (opened on first use) and wait to keep ``fps``."""
        import pygame

        surface = self._draw(overlays or Overlays(), hud)
        if self._window is None or self._clock is None:  # (both are set together)
            pygame.display.init()
            pygame.display.set_caption(f"crowdnav: {self.sim.scenario.name}")
            self._window = pygame.display.set_mode(self.size)
            self._clock = pygame.time.Clock()
        pygame.event.pump()  # keeps the window responsive
        self._window.blit(surface, (0, 0))
        pygame.display.flip()
        self._clock.tick(fps)

    def close(self) -> None:
        import pygame

        if self._window is not None:
            pygame.display.quit()
            self._window = None

    def to_pixels(self, points: np.ndarray | complex) -> np.ndarray:
        """World points (complex) -> (..., 2) pixel coordinates (x right, y down)."""
        z = np.asarray(points, dtype=complex)
        return np.stack([(z.real - self._x0) * self.scale, self._bar + (self._y1 - z.imag) * self.scale], axis=-1)

    # ---------------------------------------------------------------- drawing

    def _draw_static(self) -> pygame.Surface:
        import pygame

        surface = pygame.Surface(self.size)
        surface.fill(self.palette.panel)
        surface.fill(self.palette.outside, self._map_rect)
        surface.set_clip(self._map_rect)
        world = self.sim.scenario.world
        corners = self.to_pixels(np.array([complex(*world.min), complex(world.max[0], world.min[1]),
                                           complex(*world.max), complex(world.min[0], world.max[1])]))
        pygame.draw.polygon(surface, self.palette.background, _xy(corners))
        obstacles = self.sim.obstacles
        for polygon, label in zip(obstacles.polygons, obstacles.labels, strict=True):
            colour = self.palette.furniture if label.startswith("furniture") else self.palette.wall
            if label == "world.outside":  # the solid part of a polygon world: not floor, not a wall
                colour = self.palette.outside
            for ring in [polygon.exterior, *polygon.interiors]:
                xy = np.asarray(ring.coords)
                pygame.draw.polygon(surface, colour, _xy(self.to_pixels(xy[:, 0] + 1j * xy[:, 1])))
        for centre, radius in zip(obstacles.disc_center, obstacles.disc_radius, strict=True):
            pygame.draw.circle(surface, self.palette.furniture, _xy(self.to_pixels(centre)), radius * self.scale)
        surface.set_clip(None)
        edge = (self._panel_rect.topright if self._below else self._panel_rect.bottomleft)
        pygame.draw.line(surface, self.palette.outline, self._panel_rect.topleft, edge, 1)
        self._draw_scale_bar(surface)
        return surface

    def _draw(self, overlays: Overlays, hud: str) -> pygame.Surface:
        import pygame

        sim, palette, scale = self.sim, self.palette, self.scale
        surface = self._static.copy()
        surface.set_clip(self._map_rect)  # nothing drawn on the map spills into the bar or the panel
        robot = sim.robot_position
        heading = sim.robot_heading
        shown = ~empty_places(sim.human_positions)  # an empty place of a recorded crowd is nobody: nothing is drawn for it
        if overlays.human_goals:
            for goal in self.to_pixels(sim.human_goals[shown]):
                _cross(surface, palette.human_goal, goal, 4)
        if len(self._history.humans) > 1:
            history = np.array(self._history.humans)  # (T, n)
            if history.shape[1] == sim.n_humans:
                trails = self.to_pixels(history)  # (T, n, 2)
                for i, first, stop in present_runs(~empty_places(history)):  # no line from a parking place to a person
                    pygame.draw.lines(surface, palette.human_trail, False, _xy(trails[first:stop, i]), 2)
        if len(self._history.robot) > 1:
            pygame.draw.lines(surface, palette.robot_path, False, _xy(self.to_pixels(np.array(self._history.robot))), 2)
        if overlays.lidar is not None:
            bearings, ranges, max_range = overlays.lidar
            ends = self.to_pixels(robot + ranges * np.exp(1j * (bearings + heading)))
            start = self.to_pixels(robot)
            for end in ends:
                pygame.draw.line(surface, palette.lidar_ray, _xy(start), _xy(end), 1)
            for end in ends[ranges < max_range]:  # beams that hit something
                pygame.draw.circle(surface, palette.lidar, _xy(end), 2)
        if overlays.field_of_view is not None:
            self._draw_field_of_view(surface, *overlays.field_of_view)
        # the goal above the LIDAR rays and trails, below the agents
        goal, goal_px = self.to_pixels(sim.robot_goal), max(6.0, sim.scenario.robot.goal_radius * scale)
        if sim.team is None or sim.team.state.active[0]:
            pygame.draw.circle(surface, palette.goal_fill, _xy(goal), goal_px)
            pygame.draw.circle(surface, palette.goal, _xy(goal), goal_px, 3)
            _cross(surface, palette.goal, goal, max(5.0, goal_px * 0.6))
        radius = sim.scenario.humans.radius * scale
        colours = self._group_colours
        draw_group_links(surface, sim, colours, self.to_pixels)  # who walks together, under the discs
        for position, velocity, group in zip(self.to_pixels(sim.human_positions[shown]), sim.human_velocities[shown],
                                             sim.human_group[shown], strict=True):
            pygame.draw.circle(surface, colours[group], _xy(position), radius)
            pygame.draw.circle(surface, palette.outline, _xy(position), radius, 1)
            if abs(velocity) > 1e-6:
                tip = position + radius * np.array([velocity.real, -velocity.imag]) / abs(velocity)
                pygame.draw.line(surface, palette.outline, _xy(position), _xy(tip), 2)
        if overlays.tracks is not None:  # what the robot believes, over the true crowd
            estimates, velocities = overlays.tracks
            for position, tip in zip(self.to_pixels(estimates), self.to_pixels(estimates + velocities * TRACK_ARROW), strict=True):
                pygame.draw.circle(surface, palette.track, _xy(position), radius, 2)
                pygame.draw.line(surface, palette.track, _xy(position), _xy(tip), 2)
        centre = self.to_pixels(robot)
        robot_radius = sim.scenario.robot.radius * scale
        if sim.team is not None:
            self._draw_robots(surface)
        else:
            pygame.draw.circle(surface, palette.robot, _xy(centre), robot_radius)
            pygame.draw.circle(surface, palette.outline, _xy(centre), robot_radius, 2)
            pygame.draw.line(surface, palette.outline, _xy(centre), _xy(centre + robot_radius * np.array([math.cos(heading), -math.sin(heading)])), 3)
        if overlays.closest_point is not None:
            point = self.to_pixels(robot + overlays.closest_point * complex(math.cos(heading), math.sin(heading)))
            pygame.draw.line(surface, palette.closest, _xy(centre), _xy(point), 2)
            pygame.draw.circle(surface, palette.closest, _xy(point), 4)
        surface.set_clip(None)
        left, top = self._panel_rect.left + 12, self._panel_rect.top + 8
        if overlays.leog is not None:
            right, bottom = self._draw_inset(surface, np.asarray(overlays.leog), left, top)
            left, top = (right + 24, top) if self._below else (left, bottom)
        self._draw_legend(surface, overlays, left, top)
        if hud:
            surface.blit(self._font.render(_fit(self._font, hud, self.size[0] - 12), True, palette.text), (6, 4))
        return surface

    def _draw_field_of_view(self, surface: pygame.Surface, angle: float, reach: float) -> None:
        """The tracker's field of view: a wedge (a circle all around) of its range, centred on the heading."""
        import pygame

        robot, heading = self.sim.robot_position, self.sim.robot_heading
        edge = robot + reach * np.exp(1j * (heading + np.linspace(-angle / 2, angle / 2, max(8, int(angle * 12)))))
        outline = edge if angle >= 2 * math.pi else np.concatenate([[robot], edge])
        pygame.draw.lines(surface, self.palette.field_of_view, True, _xy(self.to_pixels(outline)), 2)

    def _draw_inset(self, surface: pygame.Surface, grid: np.ndarray, left: int, top: int) -> tuple[int, int]:
        """The LEOG in the panel with its caption; returns its right edge and the y below the caption."""
        import pygame

        grid = grid.reshape(grid.shape[-2], grid.shape[-1])
        side = self._inset_side
        pixels = np.where(grid > 0, 30, 235).astype(np.uint8)
        image = pygame.surfarray.make_surface(np.repeat(pixels.T[:, :, None], 3, axis=2))
        surface.blit(pygame.transform.scale(image, (side, side)), (left, top))
        pygame.draw.rect(surface, self.palette.outline, (left, top, side, side), 1)
        cx, cy = left + side / 2, top + side / 2  # the robot sits at the centre, facing up
        pygame.draw.polygon(surface, self.palette.robot, [(cx, cy - 5), (cx - 4, cy + 4), (cx + 4, cy + 4)])
        caption = self._font.render(_fit(self._font, "LEOG, heading up", side), True, self.palette.text)
        surface.blit(caption, (left, top + side + 3))
        return left + side, top + side + caption.get_height() + 10

    def robot_colour(self, index: int) -> tuple[int, int, int]:
        """Robot ``index``'s colour (several robots; the palette's colours repeat after eight)."""
        colours = self.palette.robots
        return colours[index % len(colours)]

    def _draw_robots(self, surface: pygame.Surface) -> None:
        """Several robots: each active one in its colour with its name, its goal (a ring in its colour) and its path."""
        import pygame

        sim, palette, scale = self.sim, self.palette, self.scale
        team = sim.team
        assert team is not None  # drawn for several robots only
        active, names = team.state.active, team.names
        path = np.array(self._history.robots) if len(self._history.robots) > 1 else None
        for k, (position, goal, heading) in enumerate(zip(sim.robot_positions, sim.robot_goals, sim.robot_headings, strict=True)):
            if not active[k]:
                continue
            colour, radius = self.robot_colour(k), float(team.all_radii[k]) * scale
            if path is not None and k:  # the first robot's path is drawn with the robot's own (record() keeps both)
                here = path[:, k]
                here = here[np.abs(here) < 1e6]  # not the points after it left
                if len(here) > 1:
                    pygame.draw.lines(surface, colour, False, _xy(self.to_pixels(here)), 2)
            ring = max(6.0, float(sim.robot_scenario(k).robot.goal_radius) * scale)
            pygame.draw.circle(surface, colour, _xy(self.to_pixels(goal)), ring, 3)
            centre = self.to_pixels(position)
            pygame.draw.circle(surface, colour, _xy(centre), radius)
            pygame.draw.circle(surface, palette.outline, _xy(centre), radius, 2)
            pygame.draw.line(surface, palette.outline, _xy(centre), _xy(centre + radius * np.array([math.cos(heading), -math.sin(heading)])), 3)
            label = self._font.render(names[k], True, palette.text)
            surface.blit(label, (centre[0] + radius + 2, centre[1] - radius - label.get_height() / 2))

    def _legend_entries(self, overlays: Overlays) -> list[tuple[str, str, tuple[int, int, int]]]:
        palette = self.palette
        entries = [("disc", "robot", palette.robot), ("goal", "robot goal", palette.goal)]
        if self.sim.team is not None:  # one entry per robot, in its colour; its goal is a ring of the same colour
            entries = [("disc", name, self.robot_colour(k)) for k, name in enumerate(self.sim.team.names)]
            entries.append(("goal", "first robot's goal", palette.goal))
        if self.sim.scenario.humans.groups:  # one entry per named group
            entries += [("disc", f"{group.name}{' (standing)' if group.standing else ' (together)' if group.walk_together else ''}", colour)
                        for group, colour in zip(self.sim.groups, self._group_colours, strict=True)]
        else:
            entries.append(("disc", "human", palette.human))
        if overlays.human_goals:
            entries.append(("cross", "human goal", palette.human_goal))
        entries += [("line", "robot path", palette.robot_path), ("line", "human trail", palette.human_trail),
                    ("box", "wall", palette.wall), ("box", "furniture", palette.furniture)]
        if overlays.lidar is not None:
            entries.append(("line", "LIDAR beam, hit", palette.lidar))
        if overlays.closest_point is not None:
            entries.append(("line", "closest obstacle", palette.closest))
        if overlays.tracks is not None:
            entries.append(("ring", "tracked (estimate)", palette.track))
        if overlays.field_of_view is not None:
            entries.append(("line", "tracker's view", palette.field_of_view))
        return entries

    def _draw_legend(self, surface: pygame.Surface, overlays: Overlays, left: int, top: int) -> None:
        """One entry per row from (left, top); below the map, in columns that fit the panel's height."""
        import pygame

        row, column_width = self._row, 150
        entries = self._legend_entries(overlays)
        if self._below:
            rows = max(1, (self._panel_rect.bottom - top - 8) // row)
        else:  # one column above the scale bar: rows close up when there are many groups
            rows = len(entries)
            row = max(self._font.get_height(), min(row, (self._panel_rect.bottom - _SCALE_BAR_ROOM - top) // max(1, rows)))
        for k, (kind, label, colour) in enumerate(entries):
            x, cy = left + (k // rows) * column_width, top + (k % rows) * row + row // 2
            if kind == "disc":
                pygame.draw.circle(surface, colour, (x + 8, cy), 7)
                pygame.draw.circle(surface, self.palette.outline, (x + 8, cy), 7, 1)
            elif kind == "goal":
                pygame.draw.circle(surface, self.palette.goal_fill, (x + 8, cy), 7)
                pygame.draw.circle(surface, colour, (x + 8, cy), 7, 2)
            elif kind == "cross":
                _cross(surface, colour, np.array([x + 8, cy]), 5)
            elif kind == "ring":
                pygame.draw.circle(surface, colour, (x + 8, cy), 7, 2)
            elif kind == "box":
                pygame.draw.rect(surface, colour, (x + 1, cy - 6, 14, 12))
            else:
                pygame.draw.line(surface, colour, (x, cy), (x + 16, cy), 3)
            surface.blit(self._font.render(label, True, self.palette.text), (x + 24, cy - self._font.get_height() // 2))

    def _draw_scale_bar(self, surface: pygame.Surface) -> None:
        """A bar of a round number of metres at the panel's bottom (right end below the map)."""
        import pygame

        room = 160 if self._below else self._panel_rect.width - 24
        metres = max((m for m in (0.5, 1, 2, 5, 10, 20, 50, 100) if m * self.scale <= room), default=0.5)
        length = metres * self.scale
        x = self.size[0] - 12 - length if self._below else self._panel_rect.left + 12
        y = self.size[1] - 14
        pygame.draw.line(surface, self.palette.outline, (x, y), (x + length, y), 3)
        for end in (x, x + length):
            pygame.draw.line(surface, self.palette.outline, (end, y - 5), (end, y + 5), 2)
        label = self._font.render(f"{metres:g} m", True, self.palette.text)
        surface.blit(label, (x, y - 8 - label.get_height()))


_SCALE_BAR_ROOM = 40
"""Pixels at the panel's bottom kept for the scale bar and its label."""


def present_runs(present: np.ndarray) -> list[tuple[int, int, int]]:
    """``(column, first, stop)`` of every run of two or more consecutive True rows of each column of ``present`` (T, n): the
    stretches of a trail to draw (a place of a recorded crowd stays empty a step between two people, so a run is one person)."""
    edges = np.diff(np.pad(present.astype(np.int8), ((1, 1), (0, 0))), axis=0)  # +1 where a run starts, -1 after it ends
    starts, ends = np.nonzero(edges.T == 1), np.nonzero(edges.T == -1)  # column-major: both in the same (column, row) order
    return [(int(i), int(a), int(b)) for i, a, b in zip(starts[0], starts[1], ends[1], strict=True) if b - a > 1]


def _fit(font: pygame.font.Font, text: str, width: int) -> str:
    """``text`` cut (with an ellipsis) to fit ``width`` pixels."""
    if font.size(text)[0] <= width:
        return text
    while text and font.size(text + "...")[0] > width:
        text = text[:-1]
    return text + "..."


def _group_colours(sim: Simulator, palette: Palette) -> list[tuple[int, int, int]]:
    """Each group's drawing colour: its own ``colour``, else the palette's group colours in turn."""
    return [_rgb(group.colour) if group.colour else palette.groups[k % len(palette.groups)] for k, group in enumerate(sim.groups)]


def _rgb(colour: str) -> tuple[int, int, int]:
    """``"#rrggbb"`` -> (r, g, b)."""
    return int(colour[1:3], 16), int(colour[3:5], 16), int(colour[5:7], 16)


def _cross(surface: pygame.Surface, colour: tuple[int, int, int], centre: np.ndarray, half: float) -> None:
    import pygame

    x, y = centre
    pygame.draw.line(surface, colour, (x - half, y - half), (x + half, y + half), 2)
    pygame.draw.line(surface, colour, (x - half, y + half), (x + half, y - half), 2)


def _xy(pixels: np.ndarray) -> Sequence[Any]:
    """Pixel coordinates, (2,) or (k, 2), as the sequence pygame's stubs name (pygame reads an array as one; no copy)."""
    return cast(Sequence[Any], pixels)


def _ceil_16(pixels: float) -> int:
    return int(math.ceil(pixels / 16)) * 16


def _floor_16(pixels: float) -> int:
    return max(16, int(pixels // 16) * 16)


def _multiple_of_16(pixels: float) -> int:
    return max(16, int(round(pixels / 16)) * 16)
