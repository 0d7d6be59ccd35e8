"""Crowd models: how walking humans choose their velocity, one model per group, in one world or K.

:data:`CROWD_MODELS` is the one registry (a scenario's ``humans.model`` / group ``model`` value ->
its class, a :class:`crowdnav.crowd.base.CrowdModel`); the scenario schema's list of names
(:data:`crowdnav.scenario.crowd.CROWD_MODEL_NAMES`) must name the same models, in the same order,
which importing this package checks. :class:`Crowd` is what a simulator holds: the models its
scenario's walking groups use and their composition (docs/architecture.md, "How to add a crowd model").
"""

from __future__ import annotations

import copy
from collections.abc import Iterator, Mapping, Sequence
from typing import Any, overload

import numpy as np

from crowdnav.crowd.base import CrowdModel, CrowdView
from crowdnav.crowd.orca import OrcaModel
from crowdnav.crowd.replay import ReplayModel
from crowdnav.crowd.social_force import SocialForceModel
from crowdnav.errors import CrowdNavError
from crowdnav.scenario import crowd as crowd_schema
from crowdnav.scenario.errors import ScenarioError, ScenarioIssue
from crowdnav.worlds.compiled import CompiledWorld

__all__ = ["CROWD_MODELS", "Crowd", "CrowdModel", "CrowdView", "OrcaModel", "ReplayModel", "SocialForceModel"]

CROWD_MODELS: dict[str, type[CrowdModel]] = {model.name: model for model in (SocialForceModel, OrcaModel, ReplayModel)}
"""Model name -> class: every crowd model a scenario may name; the first is the default (``humans.model``'s)."""

if tuple(CROWD_MODELS) != crowd_schema.CROWD_MODEL_NAMES:
    raise ImportError(f"crowdnav.crowd.CROWD_MODELS names {tuple(CROWD_MODELS)} but the scenario schema's CROWD_MODEL_NAMES "
                      f"{crowd_schema.CROWD_MODEL_NAMES}: add a new model to both")


class Crowd:
    """The crowd models of one simulator's scenario and how their commands combine.

    Each walking group follows its model (a group's ``model``, filled in from ``humans.model``);
    one instance of each model the groups use is built here, in :data:`CROWD_MODELS`' order.
    With several models every human takes its own group's model's command (``np.where``, exact);
    standing members never move, so they count as members of every model.
    """

    def __init__(self, world: CompiledWorld):
        humans = world.scenario.humans
        groups = [group for _, group in humans.crowd]
        asked = {group.model for group in groups if not group.standing and group.model is not None}
        names = [name for name in CROWD_MODELS if name in asked] or [next(iter(CROWD_MODELS))]
        unknown = sorted(asked - set(CROWD_MODELS))
        if unknown:  # a schema name without a class: a model added to the schema only
            raise ScenarioError("scenario", [ScenarioIssue("humans.model", f"crowd model {unknown[0]!r} has no class in "
                                                                            "crowdnav.crowd.CROWD_MODELS")])
        self.models: dict[str, CrowdModel] = {}
        """Model name -> this simulator's instance, for the models its walking groups use (the default alone if none walks)."""
        for name in names:
            try:
                self.models[name] = CROWD_MODELS[name](world)
            except CrowdNavError as error:  # "FILE:LINE: humans.model: orca needs the optional package pyrvo ..."
                issue = ScenarioIssue(getattr(error, "field", None) or _field_asking(world, name), str(error))
                raise (world.source.error([issue]) if world.source is not None else ScenarioError("scenario", [issue])) from None
        self._only = next(iter(self.models.values())) if len(self.models) == 1 else None
        self._placing = [model for model in self.models.values() if model.places]
        self.places = bool(self._placing)
        """Whether a model puts its humans where they are (after the step's pushes; :meth:`place`)."""
        self._covers = {name: np.array([group.standing or group.model == name for group in groups]) for name in self.models}
        """Model name -> (groups,) whether each group's humans take that model's command (standing ones: every model)."""

    def copy(self) -> Crowd:
        """This crowd for a clone of its simulator: each model's :meth:`CrowdModel.copy` (its own episode state)."""
        twin = copy.copy(self)
        twin.models = {name: model.copy() for name, model in self.models.items()}
        twin._only = next(iter(twin.models.values())) if len(twin.models) == 1 else None
        twin._placing = [model for model in twin.models.values() if model.places]
        return twin

    def model(self, name: str) -> CrowdModel | None:
        """This simulator's instance of model ``name``, or None when no walking group uses it."""
        return self.models.get(name)

    def moved_by(self, name: str, human_group: np.ndarray) -> np.ndarray:
        """Bool mask (the shape of ``human_group``): the humans whose commands come from model ``name``."""
        covers: np.ndarray = self._covers[name][human_group]
        return covers

    def start_episode(self, view: CrowdView, rng: np.random.Generator) -> None:
        """Every model's :meth:`CrowdModel.start_episode` for the episode just drawn (``rng``: the episode's generator)."""
        for model in self.models.values():
            model.start_episode(view, rng)

    def episode_state(self) -> dict[str, dict[str, Any]]:
        """Model name -> its :meth:`CrowdModel.episode_state` (what the models' commands depend on besides the view and the generator)."""
        return {name: model.episode_state() for name, model in self.models.items()}

    def resume(self, view: CrowdView, states: Mapping[str, Mapping[str, Any]]) -> None:
        """Every model's :meth:`CrowdModel.resume` from ``states`` (an :meth:`episode_state` of a crowd of the same scenario)."""
        for name, model in self.models.items():
            model.resume(view, states[name])

    def place(self, view: CrowdView) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(index, positions, velocities) of every model that :attr:`CrowdModel.places` its humans (one world)."""
        return [model.place(view) for model in self._placing]

    def commands(self, view: CrowdView) -> np.ndarray:
        """(n,) complex: every human's command in one world, from its group's model."""
        if self._only is not None:
            return self._only.commands(view)
        first, *others = self.models.values()
        commands = first.commands(view)
        for model in others:
            commands = np.where(self.moved_by(model.name, view.human_group), model.commands(view), commands)
        return commands

    def commands_batch(self, view: CrowdView, worlds: Sequence[Crowd]) -> np.ndarray:
        """(K, n) complex: :meth:`commands` of K worlds; ``worlds[k]`` is world k's own :class:`Crowd` (its models' instances)."""
        if self._only is not None:
            return self._only.commands_batch(view, _instances(worlds, self._only.name))
        first, *others = self.models.values()
        commands = first.commands_batch(view, _instances(worlds, first.name))
        for model in others:
            chosen = model.commands_batch(view, _instances(worlds, model.name))
            commands = np.where(self.moved_by(model.name, view.human_group), chosen, commands)
        return commands


class _Instances(Sequence[CrowdModel]):
    """Model ``name``'s instance in each of ``worlds``, looked up when read (the social force reads none)."""

    def __init__(self, worlds: Sequence[Crowd], name: str):
        self._worlds, self._name = worlds, name

    def __len__(self) -> int:
        return len(self._worlds)

    def __iter__(self) -> Iterator[CrowdModel]:
        name = self._name
        return (crowd.models[name] for crowd in self._worlds)

    @overload
    def __getitem__(self, k: int) -> CrowdModel: ...
    @overload
    def __getitem__(self, k: slice) -> Sequence[CrowdModel]: ...
    def __getitem__(self, k: int | slice) -> CrowdModel | Sequence[CrowdModel]:
        if isinstance(k, slice):
            return [crowd.models[self._name] for crowd in self._worlds[k]]
        return self._worlds[k].models[self._name]


def _instances(worlds: Sequence[Crowd], name: str) -> Sequence[CrowdModel]:
    return _Instances(worlds, name)


def _field_asking(world: CompiledWorld, name: str) -> str:
    """The first scenario field that asks for model ``name``: a group's own ``model``, or ``humans.model``."""
    humans = world.scenario.humans
    for i, group in enumerate(humans.groups):
        if not group.standing and (group.model or humans.model) == name:
            return f"humans.groups.{i}.model" if group.model else "humans.model"
    return "humans.model"
