"""The crowd-model protocol: how a model of walking humans gives their velocity commands, in one world or K.

A *crowd model* (the social force, ORCA, ...) turns the crowd's state into every human's velocity
command (m/s, complex ``x + 1j*y``) at each step. A scenario chooses one per walking group
(``humans.model``, a group's ``model``); :class:`crowdnav.crowd.Crowd` builds the models a
scenario uses and composes their commands, each human taking its own group's model's command.
Both simulators call the same model, so a model is written once:

- :class:`crowdnav.Simulator` calls :meth:`CrowdModel.commands` with a :class:`CrowdView` of its
  world (arrays ``(n,)`` over the humans, ``(R,)`` over the robots);
- :class:`crowdnav.batch.simulator.BatchSimulator` calls :meth:`CrowdModel.commands_batch` with a
  view of K worlds (the same names, a leading ``(K,)`` axis) and the K worlds' own model
  instances (each world's simulator builds its own: a model may keep per-world state, such as
  ORCA's solver). The default runs :meth:`CrowdModel.commands` world by world on
  :meth:`CrowdView.world` views, which is bit for bit the single path; a model whose arithmetic
  takes a leading world axis overrides it to do all worlds at once.

A model's commands must depend only on what the view shows and on the model's own state set by
:meth:`CrowdModel.start_episode` (never on a clock or a global generator): the same seed gives
the same episode, and world k of a batch equals a single simulator given the same seed.
The recipe for adding a model is in docs/architecture.md ("How to add a crowd model").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, Protocol

import numpy as np

from crowdnav.worlds.compiled import CompiledWorld


def action_commands(actions: np.ndarray, max_speed: np.ndarray) -> np.ndarray:
    """The (n,) complex commands (m/s) of humans given (n, 2) ``actions`` in [-1, 1] instead of a model's.

    Each action is clipped per axis, shrunk to length 1 at most and scaled by that human's
    ``max_speed`` ((n,) m/s): :meth:`crowdnav.Simulator.step` with ``human_actions``.
    """
    actions = np.asarray(actions, dtype=float)
    if actions.shape != (len(max_speed), 2):
        raise ValueError(f"human_actions must have shape ({len(max_speed)}, 2), got {actions.shape}")
    if not np.isfinite(actions).all():
        raise ValueError("human_actions must be finite")
    command = np.clip(actions[:, 0], -1, 1) + 1j * np.clip(actions[:, 1], -1, 1)
    command /= np.maximum(np.abs(command), 1.0)
    scaled: np.ndarray = command * max_speed
    return scaled


class CrowdView(Protocol):
    """The crowd as a model reads it at a step (or at an episode's start): one world, or K worlds with a leading axis.

    Arrays are read-only for a model (they may be the simulator's own). Agents are ordered robots
    first (the ego robot, then a ``robots:`` scenario's others), then the humans.
    """

    @property
    def robot_count(self) -> int:
        """R: the robots in ``agent_positions`` before the humans."""

    @property
    def agent_positions(self) -> np.ndarray:
        """(..., R+n) complex: every agent's position (m), robots first."""

    @property
    def agent_velocities(self) -> np.ndarray:
        """(..., R+n) complex: every agent's current velocity (m/s), robots first."""

    @property
    def human_goals(self) -> np.ndarray:
        """(..., n) complex: each human's goal (m)."""

    @property
    def human_preferred_speed(self) -> np.ndarray:
        """(..., n) float: each human's preferred speed (m/s; 0 for standing members)."""

    @property
    def human_max_speed(self) -> np.ndarray:
        """(..., n) float: each human's speed limit (m/s)."""

    @property
    def human_group(self) -> np.ndarray:
        """(..., n) int: each human's group (index into the scenario's ``humans.crowd``)."""

    @property
    def agent_radii(self) -> np.ndarray:
        """(R+n,) float: every agent's body radius (m), robots first (shared by the K worlds of a view)."""

    @property
    def robot_max_speeds(self) -> np.ndarray:
        """(R,) float: every robot's max speed (m/s)."""

    @property
    def step_count(self) -> int | np.ndarray:
        """Steps taken this episode: an int, or (K,) ints."""

    def social_force(self) -> np.ndarray:
        """(..., n) complex: the social force's commands (m/s) in this state: the simulators' kernel
        (:mod:`crowdnav.sim.forces`, on the geometry the step measured), computed once per view."""

    def world(self, k: int) -> CrowdView:
        """World ``k`` of a K-world view as a one-world view (its arrays views of row ``k``)."""


SHARED_BY_WORLDS = frozenset({"robot_count", "agent_radii", "robot_max_speeds"})
"""The :class:`CrowdView` properties that have no world axis: the same for every world of a K-world view."""


class CrowdModel:
    """A crowd model: one instance per simulator (per world), built once when the simulator is.

    Subclasses set :attr:`name` (its value in ``humans.model``) and implement :meth:`commands`;
    they may override :meth:`start_episode` and :meth:`commands_batch`.
    """

    name: ClassVar[str]
    """The model's name in a scenario (``humans.model`` / a group's ``model``) and in :data:`crowdnav.crowd.CROWD_MODELS`."""
    places: ClassVar[bool] = False
    """Whether the model puts its humans where they are (:meth:`place`) instead of commanding their velocity."""

    def __init__(self, world: CompiledWorld):
        """Read what the model needs from the compiled world (parameters, obstacles).

        Raise a :class:`crowdnav.errors.CrowdNavError` for a model that cannot run (a missing
        optional package): the simulator reports it in one line at the scenario field that asked for the model.
        """
        self.world = world
        self.dt = world.scenario.time_step

    def copy(self) -> CrowdModel:
        """This model for a clone of its simulator (:meth:`crowdnav.Simulator.clone`): a model whose state changes during an
        episode returns a copy holding its own state; default: the same instance (state set at every step, or none)."""
        return self

    def start_episode(self, view: CrowdView, rng: np.random.Generator) -> None:
        """A new episode was drawn (one-world ``view``; ``rng``: the episode's generator, for any draw): set any
        per-episode state (default: none)."""

    def episode_state(self) -> dict[str, Any]:
        """What this model's commands depend on besides the view and the world's generator (its episode state so far), as
        new arrays and JSON scalars only (None, bool, int, float, text; nested in dicts with text keys, tuples and lists):
        a checkpoint stores it without pickle (:mod:`crowdnav.envs.engines.world_state_codec`, which refuses anything else), and
        :meth:`resume` takes it back (:mod:`crowdnav.envs.engines.world_state`). Default: nothing."""
        return {}

    def resume(self, view: CrowdView, state: Mapping[str, Any]) -> None:
        """Go on with an episode from ``state`` (an :meth:`episode_state`, maybe another instance's) in the one-world ``view``
        of the world's state just loaded: set what :meth:`start_episode` and the steps since would have set (default: nothing)."""

    def commands(self, view: CrowdView) -> np.ndarray:
        """(n,) complex: a velocity command (m/s) for every human of the one-world ``view``; only those of the
        model's groups are used (standing and stopped humans are zeroed by the simulator)."""
        raise NotImplementedError(f"{type(self).__name__} must implement commands(view)")

    def commands_batch(self, view: CrowdView, worlds: Sequence[CrowdModel]) -> np.ndarray:
        """(K, n) complex: :meth:`commands` of every world of the K-world ``view``; ``worlds[k]`` is world k's own
        instance of this model. Default: world by world (each world's instance on its row)."""
        return np.stack([model.commands(view.world(k)) for k, model in enumerate(worlds)])

    def place(self, view: CrowdView) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For a model that :attr:`places`: (index, positions, velocities), its humans (indices among the humans) and where
        they are now, after the step's moves and pushes (one-world ``view``; its ``step_count`` already counts this step).
        Its humans are stopped humans for the simulator (no command, goal rule or stall check)."""
        raise NotImplementedError(f"{type(self).__name__} places its humans and must implement place(view)")
