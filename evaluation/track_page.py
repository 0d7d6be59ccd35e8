"""A track's leaderboard as one static, self-contained HTML page, viewable offline.

``crowdnav leaderboard --track NAME RESULTS --html PAGE.html`` writes the leaderboard's table and,
per entry, one frame: the last frame of the track's first test episode played by that entry (the
same episode for every entry), as an inline PNG (``data:`` URI). No script, style sheet, font or
image is fetched from anywhere: the page is one file.

A frame replays the entry's policy: the scripted baselines, and a user's result whose policy is a
file (a run folder, a checkpoint, an SB3 zip: only parameters are read). A ``module:function``
result is never imported from a results file (docs/security.md): its frame is the episode's start,
and the caption says so. A small inline script counts the frames that decoded and writes the
count into the page (``data-frames-loaded`` on ``<body>``), logging a console error for any
broken one, which is what the browser test checks.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Any

import numpy as np
from crowdnav.evaluation.track_leaderboard import Entry, Ranked, note, table_rows

MAX_STEPS_SHOWN = 10_000


def _act(entry: Entry, options: dict[str, Any]) -> tuple[Any, bool, str]:
    """(act, privileged, caption) of an entry's policy, or (None, False, why) when it is not replayed."""
    from crowdnav.evaluation.baselines import BASELINE_PREFIX, scripted_policy
    from crowdnav.evaluation.storage import META_FILE, read_json

    if entry.name.startswith(BASELINE_PREFIX):
        return scripted_policy(entry.name.removeprefix(BASELINE_PREFIX)), True, "last frame of the first test episode"
    if entry.reference:  # a shipped reference agent: its episodes are shipped, its policy is not
        return None, False, "the episode's start (a reference agent ships its episodes, not its policy)"
    meta = read_json(Path(entry.source) / META_FILE) if (Path(entry.source) / META_FILE).is_file() else {}
    source = str(meta.get("policy_source", ""))
    if not source or not Path(source).exists():
        return None, False, "the episode's start (a module:function is never imported from a results file)"
    from crowdnav.evaluation.evaluate import resolve_policy

    _, _, act, privileged, env_options = resolve_policy(source, options, allow_import=False)
    options.clear()
    options.update(env_options)
    return act, privileged, "last frame of the first test episode"


def entry_frame(board: Ranked, entry: Entry) -> tuple[np.ndarray, str]:
    """The entry's frame (RGB array) of the track's first test episode, and its caption."""
    from crowdnav.envs import CrowdNavEnv

    options: dict[str, Any] = board.track.env_options()
    act, privileged, caption = _act(entry, options)
    options["scenario"], options["overrides"] = board.track.scenario, board.track.env_options()["overrides"]
    env = CrowdNavEnv(render_mode="rgb_array", **options)
    try:
        observation, _ = env.reset(seed=board.track.seeds[0])
        for _ in range(MAX_STEPS_SHOWN if act is not None else 0):
            if privileged:
                action = act(env.simulator.robot_view(0))
            else:
                action = np.asarray(act({key: np.asarray(value)[None] for key, value in observation.items()})).reshape(-1)
            observation, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                caption += f" (seed {board.track.seeds[0]}: {info.get('outcome', 'ended')})"
                break
        frame = env.render()
    finally:
        env.close()
    assert frame is not None
    return frame, caption


def _png(frame: np.ndarray) -> str:
    import imageio.v3 as iio

    return base64.b64encode(iio.imwrite("<bytes>", np.ascontiguousarray(frame), extension=".png")).decode("ascii")


STYLE = """body{font-family:sans-serif;margin:1.5em;color:#222}table{border-collapse:collapse;font-size:0.85em}
th,td{border:1px solid #bbb;padding:0.3em 0.5em;text-align:left}th{background:#eee}.frames{display:flex;flex-wrap:wrap;gap:1em}
figure{margin:0;width:320px}figure img{width:320px;border:1px solid #bbb}figcaption{font-size:0.8em}"""
SCRIPT = """window.addEventListener("load", function () {
  var images = document.querySelectorAll("img"), loaded = 0;
  images.forEach(function (image) {
    if (image.complete && image.naturalWidth > 0) { loaded += 1; } else { console.error("frame did not load: " + image.alt); }
  });
  document.body.setAttribute("data-frames-loaded", String(loaded));
});"""


def render_page(board: Ranked) -> str:
    """The page's HTML text."""
    rows = table_rows(board)
    header = list(rows[0])
    track = board.track
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             f"<title>crowdnav track {html.escape(track.label)}</title><style>{STYLE}</style></head>",
             f'<body data-track="{html.escape(track.name)}" data-version="{track.version}">',
             f"<h1>Track {html.escape(track.label)}</h1><p>{html.escape(track.description)}. Test set: {track.test_episodes} episodes, "
             f"seeds {track.seeds[0]}-{track.seeds[-1]}; time limit {track.time_limit_steps} steps; "
             f"fingerprint {html.escape(track.fingerprint)}.</p>",
             '<table id="leaderboard"><thead><tr>' + "".join(f"<th>{html.escape(column)}</th>" for column in header) + "</tr></thead><tbody>"]
    parts += ["<tr>" + "".join(f"<td>{html.escape(row[column])}</td>" for column in header) + "</tr>" for row in rows]
    parts.append(f"</tbody></table><p>* not a reference result. {html.escape(note(board))}</p>")
    parts.append('<h2>One frame per entry</h2><div class="frames">')
    for entry in board.rows:
        frame, caption = entry_frame(board, entry)
        label = html.escape(entry.label)
        parts.append(f'<figure><img alt="{label}" src="data:image/png;base64,{_png(frame)}"><figcaption><b>{label}</b>: '
                     f"{html.escape(caption)}</figcaption></figure>")
    parts.append(f"</div><script>{SCRIPT}</script></body></html>")
    return "\n".join(parts) + "\n"


def write_page(board: Ranked, path: Path) -> Path:
    """Write the page to ``path`` (atomically); returns it."""
    from crowdnav.evaluation.storage import atomic_write_text

    return atomic_write_text(path, render_page(board))
