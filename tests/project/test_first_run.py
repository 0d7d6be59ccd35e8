"""The first training a reader runs shows RL working: it beats straight-to-goal on the same held-out episodes.

The README's "From the command line" block and docs/agents.md's opening block train with
``crowdnav train`` and state, next to each ``crowdnav evaluate`` line, the held-out success it gives
(``# ...: 95% success``) and straight-to-goal's on the same episodes. The fast tests hold the docs to
that form; the slow ones run the blocks' commands as written (parsed from the files, so the test
follows the docs) and check the learned policy beats straight-to-goal and scores what the docs say.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests.paths import REPO

FILES = ["README.md", "docs/agents.md"]
BASH = re.compile(r"```bash\n(.*?)```", re.S)
RUN = ("train", "collect-dataset", "pretrain-encoder", "evaluate")  # what a training example needs; render, benchmark ... not
STRAIGHT = "baseline:straight"
LEARNED_TOLERANCE = 10  # percentage points: torch's arithmetic may differ across machines; the scripted baseline may not


def training_blocks(file: str) -> list[list[tuple[list[str], str]]]:
    """The bash blocks of ``file`` that hold a ``crowdnav train`` line: each line as (arguments, comment)."""
    found = []
    for code in BASH.findall((REPO / file).read_text(encoding="utf-8")):
        if not re.search(r"^crowdnav train ", code, re.M):
            continue
        lines = []
        for raw in code.replace("\\\n", " ").splitlines():
            command, _, comment = raw.partition("#")
            if command.strip():
                lines.append((shlex.split(command), comment))
        found.append(lines)
    return found


def option(words: list[str], name: str, default: str | None = None) -> str | None:
    return words[words.index(name) + 1] if name in words else default


def stated_percent(comment: str) -> int | None:
    match = re.search(r"(\d+)%", comment)
    return int(match[1]) if match else None


def evaluations(block: list[tuple[list[str], str]]) -> list[tuple[list[str], int | None, list[str] | None]]:
    """Each learned policy's evaluate line with its stated percent and straight-to-goal's line on the same episodes."""
    lines = [(words, stated_percent(comment)) for words, comment in block if words[:2] == ["crowdnav", "evaluate"]]
    straight = {(option(words, "--scenario"), option(words, "--episodes", "20")): words for words, _ in lines if words[2] == STRAIGHT}
    return [(words, percent, straight.get((option(words, "--scenario"), option(words, "--episodes", "20"))))
            for words, percent in lines if words[2] != STRAIGHT]


@pytest.mark.parametrize("file", FILES)
def test_every_training_example_states_its_held_out_result_next_to_straight_to_goal(file):
    blocks = training_blocks(file)
    assert blocks, f"{file}: no bash block trains (the first-run examples moved?)"
    for block in blocks:
        evaluated = {words[2] for words, _, _ in evaluations(block)}
        for words, _ in block:
            if words[:2] == ["crowdnav", "train"]:
                out = option(words, "--out")
                assert out in evaluated, f"{file}: `{shlex.join(words)}` is not evaluated (`crowdnav evaluate {out} ...`)"
        for words, percent, straight in evaluations(block):
            assert percent is not None, f"{file}: `{shlex.join(words)}` states no held-out success (# ...: N%)"
            assert straight is not None, f"{file}: `{shlex.join(words)}` has no straight-to-goal line on the same episodes"
            straight_percent = next(stated_percent(comment) for line, comment in block if line == straight)
            assert straight_percent is not None, f"{file}: `{shlex.join(straight)}` states no success"
            assert percent > straight_percent, f"{file}: `{shlex.join(words)}` states {percent}%, not above straight's {straight_percent}%"


def run(words: list[str], folder: Path) -> str:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    done = subprocess.run(words, cwd=folder, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, f"`{shlex.join(words)}` exited {done.returncode}:\n{done.stderr[-2000:]}"
    return done.stdout


def success_percent(stdout: str, folder: Path) -> float:
    """Held-out success (%) of an evaluate run, from the meta.json of the folder it says it wrote."""
    written = re.search(r"^wrote (.+?); rank with", stdout, re.M)[1]
    return round(100 * json.loads((folder / written / "meta.json").read_text(encoding="utf-8"))["final"]["success"], 1)


@pytest.mark.slow
@pytest.mark.parametrize("file", FILES)
def test_the_training_examples_beat_straight_to_goal_on_the_same_held_out_episodes(file, tmp_path):
    for block in training_blocks(file):
        scores = {}
        for words, _ in block:
            if words[0] == "crowdnav" and words[1] in RUN:
                stdout = run(words, tmp_path)
                if words[1] == "evaluate":
                    scores[shlex.join(words)] = success_percent(stdout, tmp_path)
        for words, percent, straight in evaluations(block):
            learned, baseline = scores[shlex.join(words)], scores[shlex.join(straight)]
            assert learned > baseline, f"{file}: `{shlex.join(words)}`: {learned:.0f}% held-out, straight-to-goal {baseline:.0f}%"
            assert abs(learned - percent) <= LEARNED_TOLERANCE, f"{file}: `{shlex.join(words)}` states {percent}%, scored {learned:.0f}%"
            stated_straight = next(stated_percent(comment) for line, comment in block if line == straight)
            assert baseline == stated_straight, f"{file}: straight-to-goal states {stated_straight}%, scored {baseline:.0f}%"
