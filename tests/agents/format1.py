"""Format-1 checkpoints, as crowdnav wrote them before it stored world states: a run whose env records its worlds' actions.

:class:`RecordingSession` is the training session with the collecting env behind an
:class:`~crowdnav.agents.runs.resume_state.ActionLog`, as every run had it: its checkpoints store each world as the
actions since its reset (``rollout_state.npz`` of format ``crowdnav-resume/1``, kind "vector"), which a resume replays.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.agents.runs.resume_state import ActionLog
from crowdnav.agents.sb3.session import TrainingSession


class RecordingSession(TrainingSession):
    """A training session whose checkpoints store their worlds as recorded actions (format 1)."""

    def _build_env(self, leog: Any) -> None:
        super()._build_env(leog)
        self.collecting = ActionLog(self.env)  # type: ignore[assignment]


def rollout_file(path: Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """A ``rollout_state.npz``'s arrays and its ``meta.json``, as stored."""
    with np.load(path, allow_pickle=False) as archive:
        arrays = {name: archive[name] for name in archive.files}
    return arrays, json.loads(str(arrays.pop("meta.json")))


def write_rollout_file(path: Path, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    np.savez(path, **arrays, **{"meta.json": np.array(json.dumps(meta))})


def mid_episode(path: Path) -> bool:
    """Whether a checkpoint's ``rollout_state.npz`` holds a world mid-episode (either format)."""
    with np.load(path, allow_pickle=False) as saved:
        return bool((saved["worlds/episode_lengths"] > 0).any())
