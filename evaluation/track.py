"""Named, versioned tracks: fixed test sets to rank policies on, like D4RL's or Procgen's task sets.

A track (``evaluation/tracks/<name>.yaml``, shipped in the package) fixes everything that decides
what a policy is ranked on:

* the scenario (a library name) and its overrides;
* the time limit (``time_limit_steps``, the scenario's ``max_steps`` for the track);
* the test episodes: ``test_episodes`` seeds from ``test_seed_base``;
* the observation keys a policy may read (``observations``: a list, or ``any``: any keys, which
  the results then declare in their ``meta.json``);
* a ``version``, and a ``fingerprint`` of its episodes: a hash of the straight-to-goal baseline's
  outcome, length and first positions on the first :data:`FINGERPRINT_SEEDS` test seeds
  (:func:`fingerprint`). A change of the simulator or of the track that changes its episodes
  changes the fingerprint; ``tests/evaluation/test_tracks.py`` recomputes every track's and fails
  until the developer bumps the version and stores the new fingerprint (``crowdnav track check``
  prints it). A track file given by path is played again on load and refused when its episodes
  are not its fingerprint's: a modified copy of a track cannot pass for it. Results carry the
  track's name, version and fingerprint, and ``crowdnav leaderboard --track`` refuses to rank
  results of another version or fingerprint (or another recorded setting) together.

Every problem in a track file is one :class:`TrackError` line naming the file and the field.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from crowdnav.config_errors import ConfigIssue, YamlProblem, format_issues, read_yaml, validation_issues, yaml_line
from crowdnav.errors import CrowdNavError
from crowdnav.suggest import did_you_mean
from crowdnav.yaml_input import YamlLimitError, read_text_file

FINGERPRINT_SEEDS = 10
"""Seeds (from the track's ``test_seed_base``) the fingerprint plays."""
FINGERPRINT_STEPS = 5
"""Steps whose positions (every agent's) the fingerprint hashes, after the reset's."""
ANY = "any"
"""``observations: any``: any observation keys, declared in the results."""
FIRST_ROBOT_NOTE = "several robots: the first robot is evaluated, the others are driven by the social-force robot"


class TrackError(CrowdNavError, ValueError):
    """An unknown track, a bad track file, or a request the track does not allow; one line."""


class _TrackFile(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)

    name: str = Field(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$", description="The track's name (folder-safe).")
    version: int = Field(ge=1, description="Bumped whenever the track's episodes change.")
    description: str = Field(max_length=300)
    scenario: str = Field(description="A library scenario name.")
    overrides: dict[str, Any] = Field(default_factory=dict, description="Scenario overrides, as --set takes them.")
    time_limit_steps: int = Field(ge=1, le=100_000, description="The scenario's max_steps for this track.")
    test_episodes: int = Field(ge=1, le=10_000)
    test_seed_base: int = Field(ge=0)
    observations: Literal["any"] | list[str] = Field(description="Allowed observation keys, or any (declared in the results).")
    fingerprint: str = Field(pattern=r"^[0-9a-f]{16}$", description="Hash of the track's first episodes (crowdnav track check).")


@dataclass(frozen=True)
class Track:
    """One track, as loaded and checked (see the module's docstring for the fields)."""

    name: str
    version: int
    description: str
    scenario: str
    overrides: Mapping[str, Any]
    time_limit_steps: int
    test_episodes: int
    test_seed_base: int
    observations: tuple[str, ...] | None
    """The allowed observation keys; None: any (declared)."""
    fingerprint: str
    source: str

    @property
    def seeds(self) -> list[int]:
        return list(range(self.test_seed_base, self.test_seed_base + self.test_episodes))

    @property
    def label(self) -> str:
        """``figure4 v1``: the track as tables name it."""
        return f"{self.name} v{self.version}"

    def env_options(self, modalities: Sequence[str] | None = None) -> dict[str, Any]:
        """Keyword arguments of :class:`crowdnav.envs.CrowdNavEnv` for this track (``modalities`` checked first)."""
        if modalities:
            self.check_observations(modalities)
        options: dict[str, Any] = {"scenario": self.scenario, "overrides": {**self.overrides, "max_steps": self.time_limit_steps}}
        if modalities:
            options["modalities"] = list(modalities)
        return options

    def check_observations(self, keys: Sequence[str]) -> None:
        """Refuse, in one line, observation keys the track does not allow."""
        if self.observations is None:
            return
        refused = [key for key in keys if key not in self.observations]
        if refused:
            raise TrackError(f"track {self.name} allows the observation keys {', '.join(self.observations)}; "
                             f"{', '.join(refused)} {'is' if len(refused) == 1 else 'are'} not allowed")

    def describe(self) -> list[str]:
        """The lines of ``crowdnav track show``."""
        overrides = ", ".join(f"{key}={json.dumps(value)}" for key, value in self.overrides.items()) or "none"
        lines = [f"track {self.label}: {self.description}",
                 f"  scenario:     {self.scenario} (overrides: {overrides})",
                 f"  time limit:   {self.time_limit_steps} steps",
                 f"  test set:     {self.test_episodes} episodes, seeds {self.seeds[0]}-{self.seeds[-1]}",
                 f"  observations: {', '.join(self.observations) if self.observations else 'any (declared in the results)'}",
                 f"  fingerprint:  {self.fingerprint} (straight-to-goal on the first {FINGERPRINT_SEEDS} seeds from {self.test_seed_base})"]
        from crowdnav.scenario import load_scenario

        if load_scenario(self.scenario, dict(self.overrides)).robots is not None:
            lines.append(f"  note:         {FIRST_ROBOT_NOTE}")
        lines.append(f"  evaluate:     crowdnav evaluate POLICY --track {self.name}; rank: crowdnav leaderboard --track {self.name} RESULTS")
        return lines

    def identity(self) -> dict[str, Any]:
        """What results record of the track (``meta.json``'s ``track``)."""
        return {"name": self.name, "version": self.version, "fingerprint": self.fingerprint}


def _tracks_folder() -> Any:
    return files("crowdnav.evaluation").joinpath("tracks")


def shipped_tracks() -> list[str]:
    """The names of the shipped tracks, sorted."""
    return sorted(entry.name[: -len(".yaml")] for entry in _tracks_folder().iterdir() if entry.name.endswith(".yaml"))


def load_track(name_or_path: str | Path, *, check_fingerprint: bool = True) -> Track:
    """A shipped track by name, or a track file by path; :class:`TrackError` (one line) for anything wrong.

    A track file's fingerprint is played again (~0.1 s) and a mismatch refused: a copy of a track
    with other episodes cannot pass for it (``check_fingerprint=False``: ``crowdnav track check``).
    Shipped tracks are checked by the test suite instead.
    """
    spec = str(name_or_path)
    if spec in shipped_tracks():
        entry = _tracks_folder().joinpath(f"{spec}.yaml")
        text, label = entry.read_text(encoding="utf-8"), str(entry)
    elif spec.endswith((".yaml", ".yml")) or "/" in spec:
        try:
            text, label = read_text_file(spec), spec
        except (OSError, YamlLimitError, UnicodeDecodeError) as error:
            raise TrackError(f"{spec}: cannot read the track file ({error})") from None
    else:
        raise TrackError(f"unknown track {spec!r}; expected one of: {', '.join(shipped_tracks())} (crowdnav track list), or a track "
                         f"file{did_you_mean(spec, shipped_tracks())}")
    try:
        document, root = read_yaml(text)
    except YamlProblem as problem:
        raise TrackError(format_issues(label, [problem.issue])) from None
    try:
        parsed = _TrackFile.model_validate(document)
    except ValidationError as error:
        raise TrackError(format_issues(label, validation_issues(error, document, _TrackFile), separator=" / ")) from None
    from crowdnav.scenario import ScenarioError, load_scenario
    from crowdnav.scenario.library import library_names

    issues = []
    if parsed.scenario not in library_names():
        issues.append(ConfigIssue("scenario", f"a library scenario name{did_you_mean(parsed.scenario, library_names())}",
                                  yaml_line(root, "scenario")))
    else:
        try:
            load_scenario(parsed.scenario, {**parsed.overrides, "max_steps": parsed.time_limit_steps})
        except ScenarioError as error:
            issues.append(ConfigIssue("overrides", str(error).splitlines()[0], yaml_line(root, "overrides")))
    from crowdnav.agents.training.seeding import check_test_seeds

    try:  # a track's test seeds are held out: below every run's training, grid and demonstration seeds
        check_test_seeds(parsed.test_seed_base, parsed.test_episodes)
    except ValueError as error:
        issues.append(ConfigIssue("test_seed_base", str(error), yaml_line(root, "test_seed_base")))
    if parsed.observations != ANY:
        from crowdnav.registry import modality_names

        unknown = [key for key in parsed.observations if key not in modality_names()]
        if unknown or not parsed.observations:
            issues.append(ConfigIssue("observations", f"any, or a list of observation keys ({', '.join(modality_names())}); got {unknown or '[]'}",
                                      yaml_line(root, "observations")))
    if issues:
        raise TrackError(format_issues(label, issues, separator=" / "))
    track = Track(parsed.name, parsed.version, parsed.description, parsed.scenario, dict(parsed.overrides), parsed.time_limit_steps,
                  parsed.test_episodes, parsed.test_seed_base, None if parsed.observations == ANY else tuple(parsed.observations),
                  parsed.fingerprint, label)
    if check_fingerprint and spec not in shipped_tracks():
        played = fingerprint(track)
        if played != track.fingerprint:
            raise TrackError(format_issues(label, [ConfigIssue(
                "fingerprint", f"{track.fingerprint} is not this file's episodes' ({played}): a track whose episodes differ cannot pass "
                f"for track {track.label}; give it its own name or version and the fingerprint `crowdnav track check FILE` prints",
                yaml_line(root, "fingerprint"))]))
    return track


def fingerprint(track: Track, seeds: int = FINGERPRINT_SEEDS) -> str:
    """16 hex digits of sha256 over the straight-to-goal baseline's first test episodes of ``track``.

    It plays the ``seeds`` seeds from ``test_seed_base`` whatever ``test_episodes`` says (a shorter
    copy of a track has its episodes, so its fingerprint). Per episode: the seed, outcome, what was
    hit, its length in steps, and every agent's position (rounded to 1e-6 m) at the reset and after each of the first :data:`FINGERPRINT_STEPS` steps.
    Straight-to-goal ignores everyone, so these move only when the track's episodes move.
    """
    from crowdnav.evaluation.baselines import scripted_policy
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    played = HeldOutEpisodes({**track.env_options(), "modalities": ["goal"]}, list(range(track.test_seed_base, track.test_seed_base + seeds)))
    try:
        rows = played.run(scripted_policy("straight"), privileged=True, record=True)
    finally:
        played.close()
    summary = []
    for row in rows:
        positions = np.asarray(row["frames"]["positions"])[: FINGERPRINT_STEPS + 1]
        rounded = np.round(np.stack([positions.real, positions.imag], axis=-1), 6) + 0.0  # + 0.0: no -0.0
        summary.append([row["test_seed"], row["outcome"], row["collision_kind"], int(row["steps"]),
                        [f"{value:.6f}" for value in rounded.ravel().tolist()]])
    return hashlib.sha256(json.dumps(summary).encode()).hexdigest()[:16]


def check_version(track: Track, recorded: Mapping[str, Any] | None, where: str) -> None:
    """Refuse, in one line, a result (``where``) measured on another version of ``track`` (``recorded``: its meta's ``track``)."""
    if not recorded or recorded.get("name") != track.name:
        raise TrackError(f"{where} was not measured on track {track.name}")
    if recorded.get("version") != track.version:
        raise TrackError(f"{where} was measured on track {track.name} v{recorded.get('version')}, and the track is v{track.version} "
                         f"now: results of different versions are never ranked together; evaluate it again with --track {track.name}")
    if recorded.get("fingerprint") != track.fingerprint:
        raise TrackError(f"{where} was measured on episodes of fingerprint {str(recorded.get('fingerprint'))[:16]!r}, and track "
                         f"{track.label}'s are {track.fingerprint}: a modified copy of the track; evaluate it again with --track {track.name}")


def track_key(track: Track) -> str:
    """The folder-safe key of the track's environment in results folders: ``track-figure4-v1``."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", f"track-{track.name}-v{track.version}")
