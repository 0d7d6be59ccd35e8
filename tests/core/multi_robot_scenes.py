"""Small multi-robot scenes the tests of several robots share (tests/core/test_multi_robot*.py)."""

from __future__ import annotations

import copy

HALL = {
    "description": "Two robots swap sides of an empty hall.",
    "world": {"min": [-5, -5], "max": [5, 5]},
    "robots": [
        {"name": "east", "start": {"type": "rectangle", "min": [-4.5, -1], "max": [-3.5, 1]},
         "goal": {"type": "rectangle", "min": [3.5, -1], "max": [4.5, 1]}},
        {"name": "west", "start": {"type": "rectangle", "min": [3.5, -1], "max": [4.5, 1]},
         "goal": {"type": "rectangle", "min": [-4.5, -1], "max": [-3.5, 1]}},
    ],
    "humans": {"count": 4, "spawn": [{"type": "rectangle", "min": [-2, -4], "max": [2, -3]}],
               "goal": [{"type": "rectangle", "min": [-2, 3], "max": [2, 4]}]},
}


def hall(**changes):
    document = copy.deepcopy(HALL)
    document.update(changes)
    return document


HEAD_ON = hall(
    robots=[
        {"name": "east", "start": {"type": "points", "points": [[-1.5, 0]]}, "goal": {"type": "points", "points": [[4, 0]]},
         "start_heading": "toward_goal"},
        {"name": "west", "start": {"type": "points", "points": [[1.5, 0]]}, "goal": {"type": "points", "points": [[-4, 0]]},
         "start_heading": "toward_goal"},
    ],
    humans={"count": 0},
)
LANES = hall(
    robots=[
        {"name": "east", "start": {"type": "points", "points": [[-1, 2]]}, "goal": {"type": "points", "points": [[0.5, 2]]},
         "start_heading": "toward_goal"},
        {"name": "west", "start": {"type": "points", "points": [[3, -2]]}, "goal": {"type": "points", "points": [[-3, -2]]},
         "start_heading": "toward_goal", "modalities": ["goal", "humans", "velocity"]},
    ],
    humans={"count": 0},
)
