"""Draw a simulator state with pygame: to an ``rgb_array`` frame, or into a window.

What is drawn: world bounds, walls and furniture; humans as discs with a heading tick and a short
trail; the robot with its heading, its goal and its path so far; optional overlays (LIDAR rays,
the LEOG as an inset, the closest-obstacle point, the humans' goals); a one-line heads-up text.
The scale is chosen from the world bounds so every scenario fits the frame.

Frames are drawn off-screen on a plain pygame Surface, so ``rgb_array`` needs no display; a
window is opened only by :meth:`Renderer.show`. pygame is imported when the first renderer is
built, so importing crowdnav (and building an env without a render mode) never loads it.
"""

from __future__ import annotations

import math
import os
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from crowdnav.simulator import Simulator

if TYPE_CHECKING:
    import pygame


def _pygame():
    """pygame, imported on first use (without its greeting on stdout)."""
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    import pygame

    return pygame


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
    lidar: tuple[int, int, int] = (235, 140, 20)
    lidar_ray: tuple[int, int, int] = (250, 225, 175)
    closest: tuple[int, int, int] = (190, 40, 190)
    text: tuple[int, int, int] = (20, 20, 20)
    outline: tuple[int, int, int] = (30, 30, 30)


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


@dataclass
class RenderOptions:
    """Which overlays the environments add when rendering."""

    max_side: int = 640
    """Longest side of the frame in pixels (rounded to a multiple of 16 for video codecs)."""
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


@dataclass
class _History:
    robot: list[complex] = field(default_factory=list)
    humans: deque = field(default_factory=lambda: deque(maxlen=12))


class Renderer:
    """Draws one scenario's states; call :meth:`reset` at each episode start, :meth:`frame` per step."""

    def __init__(self, sim: Simulator, options: RenderOptions | None = None):
        pygame = _pygame()
        self.sim = sim
        self.options = options or RenderOptions()
        self.palette = Palette()
        world = sim.scenario.world
        margin = 0.4 + (world.boundary_thickness if world.boundary_walls else 0.0)
        self._x0, self._y1 = world.min[0] - margin, world.max[1] + margin
        span_x, span_y = world.max[0] - world.min[0] + 2 * margin, world.max[1] - world.min[1] + 2 * margin
        scale = self.options.max_side / max(span_x, span_y)
        self.size = (_multiple_of_16(span_x * scale), _multiple_of_16(span_y * scale))
        self.scale = min(self.size[0] / span_x, self.size[1] / span_y)
        pygame.font.init()
        self._font = pygame.font.Font(None, max(14, self.size[1] // 36))
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
        self._history.robot.append(self.sim.robot_position)
        self._history.humans.append(self.sim.human_positions.copy())

    def frame(self, overlays: Overlays | None = None, hud: str = "") -> np.ndarray:
        """The current state as a ``uint8`` array of shape (H, W, 3)."""
        pygame = _pygame()
        surface = self._draw(overlays or Overlays(), hud)
        return np.ascontiguousarray(pygame.surfarray.pixels3d(surface).transpose(1, 0, 2))

    def show(self, overlays: Overlays | None = None, hud: str = "", fps: float = 10.0) -> None:
        """Draw into a window (opened on first use) and wait to keep ``fps``."""
        pygame = _pygame()
        surface = self._draw(overlays or Overlays(), hud)
        if self._window is None:
            pygame.display.init()
            pygame.display.set_caption(f"crowdnav: {self.sim.scenario.name}")
            self._window = pygame.display.set_mode(self.size)
            self._clock = pygame.time.Clock()
        pygame.event.pump()  # keeps the window responsive
        self._window.blit(surface, (0, 0))
        pygame.display.flip()
        self._clock.tick(fps)

    def close(self) -> None:
        pygame = _pygame()
        if self._window is not None:
            pygame.display.quit()
            self._window = None

    def to_pixels(self, points: np.ndarray | complex) -> np.ndarray:
        """World points (complex) -> (..., 2) pixel coordinates (x right, y down)."""
        z = np.asarray(points, dtype=complex)
        return np.stack([(z.real - self._x0) * self.scale, (self._y1 - z.imag) * self.scale], axis=-1)

    # ---------------------------------------------------------------- drawing

    def _draw_static(self) -> pygame.Surface:
        pygame = _pygame()
        surface = pygame.Surface(self.size)
        surface.fill(self.palette.outside)
        world = self.sim.scenario.world
        corners = self.to_pixels(np.array([complex(*world.min), complex(world.max[0], world.min[1]),
                                           complex(*world.max), complex(world.min[0], world.max[1])]))
        pygame.draw.polygon(surface, self.palette.background, corners)
        obstacles = self.sim.obstacles
        for polygon, label in zip(obstacles.polygons, obstacles.labels, strict=True):
            colour = self.palette.furniture if label.startswith("furniture") else self.palette.wall
            for ring in [polygon.exterior, *polygon.interiors]:
                xy = np.asarray(ring.coords)
                pygame.draw.polygon(surface, colour, self.to_pixels(xy[:, 0] + 1j * xy[:, 1]))
        for centre, radius in zip(obstacles.disc_center, obstacles.disc_radius, strict=True):
            pygame.draw.circle(surface, self.palette.furniture, self.to_pixels(centre), radius * self.scale)
        return surface

    def _draw(self, overlays: Overlays, hud: str) -> pygame.Surface:
        pygame = _pygame()
        sim, palette, scale = self.sim, self.palette, self.scale
        surface = self._static.copy()
        robot = sim.robot_position
        heading = sim.robot_heading
        goal_radius = sim.scenario.robot.goal_radius
        pygame.draw.circle(surface, palette.goal, self.to_pixels(sim.robot_goal), max(3, goal_radius * scale), 2)
        _cross(surface, palette.goal, self.to_pixels(sim.robot_goal), 5)
        if overlays.human_goals:
            for goal in self.to_pixels(sim.human_goals):
                _cross(surface, palette.human_goal, goal, 4)
        if len(self._history.humans) > 1:
            trails = self.to_pixels(np.array(self._history.humans))  # (T, n, 2)
            if trails.shape[1] == sim.n_humans:
                for i in range(trails.shape[1]):
                    pygame.draw.lines(surface, palette.human_trail, False, trails[:, i], 2)
        if len(self._history.robot) > 1:
            pygame.draw.lines(surface, palette.robot_path, False, self.to_pixels(np.array(self._history.robot)), 2)
        if overlays.lidar is not None:
            bearings, ranges, max_range = overlays.lidar
            ends = self.to_pixels(robot + ranges * np.exp(1j * (bearings + heading)))
            start = self.to_pixels(robot)
            for end in ends:
                pygame.draw.line(surface, palette.lidar_ray, start, end, 1)
            for end in ends[ranges < max_range]:  # beams that hit something
                pygame.draw.circle(surface, palette.lidar, end, 2)
        radius = sim.scenario.humans.radius * scale
        for position, velocity in zip(self.to_pixels(sim.human_positions), sim.human_velocities, strict=True):
            pygame.draw.circle(surface, palette.human, position, radius)
            pygame.draw.circle(surface, palette.outline, position, radius, 1)
            if abs(velocity) > 1e-6:
                tip = position + radius * np.array([velocity.real, -velocity.imag]) / abs(velocity)
                pygame.draw.line(surface, palette.outline, position, tip, 2)
        centre = self.to_pixels(robot)
        robot_radius = sim.scenario.robot.radius * scale
        pygame.draw.circle(surface, palette.robot, centre, robot_radius)
        pygame.draw.circle(surface, palette.outline, centre, robot_radius, 2)
        pygame.draw.line(surface, palette.outline, centre, centre + robot_radius * np.array([math.cos(heading), -math.sin(heading)]), 3)
        if overlays.closest_point is not None:
            point = self.to_pixels(robot + overlays.closest_point * complex(math.cos(heading), math.sin(heading)))
            pygame.draw.line(surface, palette.closest, centre, point, 2)
            pygame.draw.circle(surface, palette.closest, point, 4)
        if overlays.leog is not None:
            self._draw_inset(surface, np.asarray(overlays.leog))
        if hud:
            surface.blit(self._font.render(hud, True, palette.text), (6, 4))
        return surface

    def _draw_inset(self, surface: pygame.Surface, grid: np.ndarray) -> None:
        pygame = _pygame()
        grid = grid.reshape(grid.shape[-2], grid.shape[-1])
        side = max(48, self.size[1] // 4)
        pixels = np.where(grid > 0, 30, 235).astype(np.uint8)
        image = pygame.surfarray.make_surface(np.repeat(pixels.T[:, :, None], 3, axis=2))
        image = pygame.transform.scale(image, (side, side))
        position = (self.size[0] - side - 6, 6)
        surface.blit(image, position)
        pygame.draw.rect(surface, self.palette.outline, (*position, side, side), 1)
        cx, cy = position[0] + side / 2, position[1] + side / 2  # the robot sits at the centre, facing up
        pygame.draw.polygon(surface, self.palette.robot, [(cx, cy - 5), (cx - 4, cy + 4), (cx + 4, cy + 4)])


def _cross(surface: pygame.Surface, colour, centre: np.ndarray, half: float) -> None:
    pygame = _pygame()
    x, y = centre
    pygame.draw.line(surface, colour, (x - half, y - half), (x + half, y + half), 2)
    pygame.draw.line(surface, colour, (x - half, y + half), (x + half, y - half), 2)


def _multiple_of_16(pixels: float) -> int:
    return max(16, int(round(pixels / 16)) * 16)
