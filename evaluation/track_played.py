"""Reference agents played again: each training seed's final policy on a track whose sensing is not its training's.

``crowdnav track reference NAME --agents RESULTS_DIR/CONFIGURATION --played`` does not copy the
experiment's recorded final evaluation (:mod:`crowdnav.evaluation.track_agents`): it loads each
training seed's final policy, the snapshot its final evaluation played (the row's
``training_episodes``, or ``training_steps`` for a protocol in env steps, names it among
``seed_K/train/snapshots/`` and the checkpoint, as the evaluation runner chose it), and plays it on
the track's test episodes with the track's setting. Its observations then come through the track's
sensing: a network trained with the perfect people tracker reads the ``lidar_tracker`` profile's
tracks on ``figure4_lidar_tracker``, as do its shield and whatever else reads the tracker.

What may differ between the run's training and the track is the sensing only: the keys under
``sensors.`` of the scenario as the run trained it (its overrides and its ``sensors`` options).
:func:`crowdnav.evaluation.track_agents.check_setting` refuses any other difference in one line and
returns these; the entry records them (``trained_setting``, the trained values) and its label says
them (:func:`played_label`). The world played is the track's exactly: the run's sensor options are
not carried over, its observation keys, reward weights and shield are; a network that cannot take
the track's observation sizes, or a model that refuses its world (the SARL agent's geodesic
spacing), is refused in one line before anything is written.

The play is deterministic: the policy is deterministic, the episodes are the track's seeds, and
torch runs on one thread while it plays (the evaluation workers' setting), so playing again writes
the same bytes. Played on a track whose setting is its training's, the rows are the recorded final
evaluation's (tested).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from crowdnav.evaluation.track import Track, TrackError

TRACKER_KEY = "sensors.tracker.profile"
"""The flat key of the people tracker's profile in a scenario's settings."""


def played_label(differences: Mapping[str, tuple[Any, Any]]) -> str:
    """What a played entry's label adds: ``trained with perfect sensing, played through lidar_tracker`` (empty without differences)."""
    parts = []
    for key, (trained, now) in sorted(differences.items()):
        if key == TRACKER_KEY:
            parts.append(f"trained with {trained} sensing, played through {now}")
        else:
            parts.append(f"trained with {key} {json.dumps(trained)}, played with {json.dumps(now)}")
    return "; ".join(parts)


def final_policy(run: Path, meta: Mapping[str, Any], final_row: Mapping[str, str], where: str) -> Path:
    """The folder of the policy the run's final evaluation played (``final_row``: one of its rows)."""
    from crowdnav.agents.runs.folder import policy_snapshots
    from crowdnav.evaluation.protocol import AXIS_LABELS, Protocol
    from crowdnav.evaluation.storage import TRAIN_DIR

    try:
        protocol = Protocol(**dict(meta.get("protocol") or {}))
    except ValueError as error:
        raise TrackError(f"{where}: its protocol does not load ({str(error).splitlines()[0]})") from None
    point = str(final_row.get(protocol.point_column, ""))
    if not point.isdigit():
        raise TrackError(f"{where}: its final evaluation's rows name no {protocol.point_column}: which policy it played is unknown")
    folder = policy_snapshots(run / TRAIN_DIR, protocol.unit).get(int(point))
    if folder is None:
        raise TrackError(f"{where}: no policy saved after {int(point)} {AXIS_LABELS[protocol.unit]} in {run / TRAIN_DIR} (the one its "
                         "final evaluation played): --played needs the run's snapshots")
    return folder


def play_final(track: Track, run: Path, meta: Mapping[str, Any], final_row: Mapping[str, str], where: str) -> tuple[list[dict[str, Any]], str]:
    """(rows for :func:`crowdnav.evaluation.track_reference.reference_csv`, the policy's folder relative to the experiment's)
    of the run's final policy played on every test episode of ``track``, with the track's setting."""
    from crowdnav.agents import load_policy
    from crowdnav.agents.training.run_loop import torch_threads
    from crowdnav.evaluation.played_options import OptionRefusedError, check_played_world
    from crowdnav.evaluation.rollout import HeldOutEpisodes

    folder = final_policy(run, meta, final_row, where)
    try:
        policy = load_policy(folder)
    except (FileNotFoundError, ValueError) as error:  # a shared robot policy, an algorithm not registered, a damaged file
        raise TrackError(f"{where}: {str(error).splitlines()[0]}") from None
    track.check_observations(list(policy.env_options.get("modalities") or []))
    # the track's world: its scenario and overrides (its sensing among them), none of the run's sensor options
    played = {**policy.env_options, "scenario": track.scenario, "overrides": track.env_options()["overrides"], "sensors": {}}
    try:
        check_played_world(str(folder), policy, played)
    except OptionRefusedError as error:
        raise TrackError(f"{where}: {error}") from None
    episodes = HeldOutEpisodes(played, track.seeds)
    try:
        with torch_threads(1):  # the same sums in the same order, run after run
            rows = episodes.run(policy)
    finally:
        episodes.close()
    return rows, folder.relative_to(run.parent).as_posix()
