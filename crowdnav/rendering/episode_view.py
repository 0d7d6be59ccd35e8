"""What an environment shows when it renders: the scene, sensor overlays and a heads-up line.

Both environments own one :class:`EpisodeView` when they have a ``render_mode``. It follows the
episode (trails, return, outcome) and draws overlays from the robot's own observation when the
modality is observed, or from a render-only sensor otherwise, so a LIDAR overlay does not
require a LIDAR observation.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, cast

import numpy as np

from crowdnav.rendering.renderer import Overlays, Renderer, RenderOptions
from crowdnav.sensors import build_modalities
from crowdnav.sensors.lidar import LidarModality
from crowdnav.sensors.tracked import sensed_people
from crowdnav.sim.simulator import Simulator, StepEvents

RENDER_MODES = ["human", "rgb_array"]
"""``human``: a pygame window at ``metadata["render_fps"]``; ``rgb_array``: uint8 (H, W, 3) frames."""


def render_options(options: RenderOptions | Mapping[str, Any] | None) -> RenderOptions:
    """Validate the ``render_options`` env option."""
    if options is None or isinstance(options, RenderOptions):
        return options or RenderOptions()
    known = {field.name for field in dataclasses.fields(RenderOptions)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"unknown render_options {unknown}; expected any of: {', '.join(sorted(known))}")
    return RenderOptions(**options)


class EpisodeView:
    """Renders one environment's episodes in ``render_mode`` (see :data:`RENDER_MODES`)."""

    def __init__(self, sim: Simulator, render_mode: str, options: RenderOptions | Mapping[str, Any] | None = None):
        if render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode={render_mode!r} is not supported; expected None or one of {RENDER_MODES}")
        self.sim = sim
        self.render_mode = render_mode
        self.options = render_options(options)
        self.renderer = Renderer(sim, self.options)
        wanted = [key for key, on in (("lidar", self.options.lidar), ("leog", self.options.leog),
                                      ("closest_obstacle", self.options.closest_obstacle)) if on]
        # Render-only sensors with the scenario's settings, used when the robot does not observe them.
        self._sensors = build_modalities(wanted, sim.world, sim.scenario.sensors) if wanted else {}
        self.fps = 1.0 / sim.scenario.time_step
        self._return = 0.0
        self._last_reward: float | None = None
        self._outcome: str | None = None

    def on_reset(self) -> None:
        self.renderer.reset()
        self.renderer.record()
        self._return, self._last_reward, self._outcome = 0.0, None, None

    def on_step(self, reward: float, events: StepEvents) -> None:
        self.renderer.record()
        self._return += reward
        self._last_reward = reward
        self._outcome = events.outcome

    def render(self, observation: Mapping[str, np.ndarray] | None = None) -> np.ndarray | None:
        """An rgb frame (``rgb_array``) or a window update (``human``, returns None)."""
        overlays = self._overlays(observation or {})
        hud = self._hud()
        if self.render_mode == "rgb_array":
            return self.renderer.frame(overlays, hud)
        self.renderer.show(overlays, hud, fps=self.fps)
        return None

    def close(self) -> None:
        self.renderer.close()

    def _reading(self, key: str, observation: Mapping[str, np.ndarray]) -> np.ndarray | None:
        if key in observation:
            return observation[key]
        sensor = self._sensors.get(key)
        return sensor.observe(self.sim.robot_view(0)) if sensor is not None else None  # several robots: it sees the others

    def _overlays(self, observation: Mapping[str, np.ndarray]) -> Overlays:
        overlays = Overlays(human_goals=self.options.human_goals)
        tracker = self.sim.scenario.sensors.tracker.values
        if tracker is not None and self.options.tracks:  # what the robot sees of the crowd, beside the true crowd
            people = sensed_people(self.sim)
            shown = ~np.isnan(people.positions[1:])
            overlays.tracks = (people.positions[1:][shown], people.velocities[1:][shown])
            overlays.field_of_view = (math.radians(tracker.fov_deg), tracker.max_range)
        lidar = self._reading("lidar", observation) if self.options.lidar else None
        if lidar is not None:
            sensor = cast(LidarModality, self._sensors["lidar"])  # the registry's "lidar"
            overlays.lidar = (sensor.angles, np.asarray(lidar, dtype=float) * sensor.max_range, sensor.max_range)
        if self.options.leog:
            overlays.leog = self._reading("leog", observation)
        closest = self._reading("closest_obstacle", observation) if self.options.closest_obstacle else None
        if closest is not None:
            settings = self._sensors["closest_obstacle"].settings
            if settings.frame == "polar":
                distance, sine, cosine = (float(v) for v in closest)
                point = distance * complex(cosine, sine) if distance < settings.max_range else None
            else:
                point = complex(float(closest[0]), float(closest[1]))
                point = point if abs(point) < settings.max_range else None
            overlays.closest_point = point
        return overlays

    def _hud(self) -> str:
        parts = [f"step {self.sim.step_count}"]
        if self._last_reward is not None and math.isfinite(self._last_reward):
            parts.append(f"reward {self._last_reward:+.1f}")
            parts.append(f"return {self._return:+.1f}")
        if self._outcome:  # one of crowdnav.sim.simulator.OUTCOMES: SUCCESS, COLLISION, OUT OF BOUNDS, TRUNCATED
            parts.append(self._outcome.replace("_", " ").upper())
        return "   ".join(parts)
