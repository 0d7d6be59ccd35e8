"""What a training run plays when ``crowdnav evaluate`` or ``render`` names options: the user's, or a one-line refusal.

A run's env options carry its own sensor settings and reward weights as options, and
:class:`crowdnav.envs.CrowdNavEnv` lets options win over ``overrides``: left alone, ``--set
sensors.lidar.max_range=2`` or ``--set reward.collision=-3`` would be recorded in the results and
never played. Here ``--set`` wins over the run's own setting of the same field, a ``--modalities``
other than the run's is refused, and so is any setting that changes the observation sizes its
network was trained on (it could not take them), each in one line naming the option.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from crowdnav.errors import CrowdNavError


class OptionRefusedError(CrowdNavError, ValueError):
    """An option that cannot reach the episodes of this policy; one line naming the option."""


def run_env_options(spec: str, trained: Mapping[str, Any], requested: Mapping[str, Any]) -> dict[str, Any]:
    """The env options a run plays: its own (``trained``) with the user's ``requested`` scenario and overrides on top.

    Another scenario than the run's takes only the user's overrides; its own scenario keeps the
    run's overrides, changed where ``--set`` says. Raises :class:`OptionRefusedError` for
    ``--modalities`` or ``--set sensors.modalities`` other than the run's own keys.
    """
    played = dict(trained)
    own = list(trained.get("modalities") or [])
    overrides = dict(requested.get("overrides") or {})
    asked = requested.get("modalities")
    if asked and list(asked) != own:
        raise OptionRefusedError(f"--modalities {','.join(asked)}: {spec} reads the observation keys it was trained on "
                                 f"({','.join(own)}); leave --modalities out")
    for path, value in overrides.items():
        modalities = value.get("modalities") if path == "sensors" and isinstance(value, Mapping) else value if path == "sensors.modalities" else None
        if modalities is not None and own and list(modalities) != own:
            raise OptionRefusedError(f"--set {path}: {spec} reads the observation keys it was trained on ({','.join(own)}); leave it out")
    if requested.get("scenario") not in (None, trained["scenario"]):
        played["scenario"] = requested["scenario"]  # the same observations, in another scenario
        played["overrides"] = overrides
    elif overrides:
        played["overrides"] = {**trained.get("overrides", {}), **overrides}
    # the run's sensor settings and reward weights are options, which win over overrides: --set must win over them
    played["sensors"] = _without(trained.get("sensors") or {}, [path.split(".")[1:] for path in overrides if path.split(".")[0] == "sensors"])
    played["reward_weights"] = _without(trained.get("reward_weights") or {},
                                        [path.split(".")[1:] for path in overrides if path.split(".")[0] == "reward"])
    return {key: value for key, value in played.items() if key in trained or value}


def _without(settings: Mapping[str, Any], paths: Sequence[Sequence[str]]) -> dict[str, Any]:
    """``settings`` (nested) without the fields at ``paths`` (an empty path: all of them)."""
    kept = {key: dict(value) if isinstance(value, Mapping) else value for key, value in settings.items()}
    for path in paths:
        if not path:
            return {}
        if len(path) == 1:
            kept.pop(path[0], None)
        elif isinstance(kept.get(path[0]), Mapping):
            kept[path[0]] = _without(kept[path[0]], [path[1:]])
    return kept


def check_played_world(spec: str, policy: Any, played: Mapping[str, Any]) -> None:
    """Refuse, naming the options, a world the run cannot play: observations of other sizes than its own (its
    network takes only those), or one its model says it senses otherwise than it was trained to (an agent's
    ``check_world``, e.g. the SARL agent's geodesic spacing, a constant of its lookahead that changes no size)."""
    from crowdnav.envs import CrowdNavEnv

    trained = policy.env_options
    env = CrowdNavEnv(**played)
    try:
        own, now = _shapes(CrowdNavEnv(**trained)), _shapes(env, close=False)
        if own != now:
            from crowdnav.agents.sb3.model_zip import describe_shapes

            changed = [path for path in played.get("overrides", {}) if path.split(".")[0] == "sensors"]
            named = (f"--set {', '.join(changed)}" if changed else f"--scenario {played['scenario']}"
                     if played["scenario"] != trained["scenario"] else "--set")
            raise OptionRefusedError(f"{named}: {spec} was trained on observations {describe_shapes(own)}, these settings give "
                                     f"{describe_shapes(now)}; its network takes only the sizes it was trained on")
        check = getattr(getattr(policy, "model", None), "check_world", None)
        if check is not None:
            try:
                check(env.observation_space, env.scenario)
            except ValueError as error:  # the agent's one-line mismatch (a CrowdNavError and ValueError)
                raise OptionRefusedError(f"--set: {spec}: {error}") from None
    finally:
        env.close()


def _shapes(env: Any, close: bool = True) -> dict[str, tuple[int, ...]]:
    """Each observation key's shape in ``env`` (closed after unless ``close`` is false)."""
    try:
        return {key: tuple(space.shape or ()) for key, space in env.observation_space.items()}
    finally:
        if close:
            env.close()


def refuse_modalities(spec: str, requested: Mapping[str, Any], reads: str) -> None:
    """``--modalities`` given for a policy that reads no observation dict (``reads``: what it reads instead)."""
    if requested.get("modalities"):
        raise OptionRefusedError(f"--modalities: {spec} reads {reads}, not the observation keys; leave --modalities out")
