"""Every multi-agent loop of docs/environments.md runs, as written, in every library scenario (several robots included),
and an unknown agent name is a one-line error that lists the agents."""

from __future__ import annotations

import re

import numpy as np
import pytest

import crowdnav
import crowdnav.planning.scripted  # noqa: F401  (the several-robots loop reads crowdnav.planning.scripted)
from crowdnav.envs.multi_agent import UnknownAgentError, agent_list
from crowdnav.errors import CrowdNavError
from crowdnav.scenario.library import library_names
from tests.paths import REPO

_BLOCK = re.compile(r"```python\n(.*?)```", re.S)
_SCENARIO = re.compile(r'(crowdnav\.(?:parallel_env|env)\()"[a-z_]+"')


def docs_loops() -> list[str]:
    """The python blocks of docs/environments.md that step a multi-agent env in a loop."""
    text = (REPO / "docs" / "environments.md").read_text(encoding="utf-8")
    return [code for code in _BLOCK.findall(text) if ("while env.agents" in code or "agent_iter(" in code) and _SCENARIO.search(code)]


def test_the_docs_have_the_loops_this_file_runs():
    loops = docs_loops()
    assert len(loops) >= 3  # the AEC loop, the stubborn humans, several robots
    assert any("stubborn" in code for code in loops) and any("robot_view" in code for code in loops)


@pytest.mark.parametrize("name", library_names())
@pytest.mark.parametrize("loop", range(len(docs_loops())))
def test_docs_loop_runs_in_every_library_scenario(loop, name):
    code = _SCENARIO.sub(lambda m: f'{m[1]}"{name}"', docs_loops()[loop])
    namespace: dict = {"np": np, "crowdnav": crowdnav}
    exec(compile(code, f"docs/environments.md loop {loop} in {name}", "exec"), namespace)  # noqa: S102 - our own documentation
    env = namespace["env"]
    if "while env.agents" in code:
        assert env.agents == []  # the episode ran to its end


def test_unknown_agent_names_are_one_line_errors_listing_the_agents():
    env = crowdnav.parallel_env("robots_crossing_hall", modalities=["goal"])
    observations, _ = env.reset(seed=0)
    for method in (env.action_space, env.observation_space):
        with pytest.raises(UnknownAgentError) as error:
            method("robot")
        message = str(error.value)
        assert message.startswith("unknown agent 'robot'") and "\n" not in message
        assert "east_bound, west_bound, north_bound, human_0 .. human_" in message
        assert isinstance(error.value, KeyError) and isinstance(error.value, CrowdNavError)
    actions = {name: np.zeros(2, dtype=np.float32) for name in env.agents if name != "east_bound"}
    actions["robot"] = np.zeros(2, dtype=np.float32)
    with pytest.raises(ValueError, match=r"missing: \['east_bound'\], not in env.agents: \['robot'\]; env.agents: east_bound, ") as error:
        env.step(actions)
    assert "\n" not in str(error.value)
    single = crowdnav.parallel_env("open_space", modalities=["goal"])
    with pytest.raises(KeyError, match=r"unknown agent 'human_9'; did you mean 'human_4'\? the agents are: robot, human_0 \.\. human_4$"):
        single.action_space("human_9")


def test_agent_lists_name_robots_and_shorten_runs_of_humans():
    assert agent_list(["robot", "human_0", "human_1", "human_2", "human_5", "human_7", "human_8"]) == \
        "robot, human_0 .. human_2, human_5, human_7, human_8"
    assert agent_list(["a", "b"]) == "a, b" and agent_list([]) == "none"
