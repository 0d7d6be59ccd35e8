"""Every SB3 internal crowdnav relies on (crowdnav.agents.sb3.internals) exists on the installed SB3, as crowdnav uses it."""

from __future__ import annotations

import importlib
import inspect
import re
from functools import cache
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import stable_baselines3
from crowdnav.agents.sb3.internals import SB3_INTERNALS, TESTED_SB3, Internal, fingerprint, source_fingerprint
from gymnasium import spaces

from tests.paths import REPO

ROOT = REPO


class _TinyDictEnv(gym.Env):
    """The smallest env with crowdnav's kind of spaces (a Dict observation, a 2-D continuous action)."""

    observation_space = spaces.Dict({"state": spaces.Box(-1.0, 1.0, (3,), np.float32)})
    action_space = spaces.Box(-1.0, 1.0, (2,), np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        super().reset(seed=seed)
        return {"state": np.zeros(3, np.float32)}, {}

    def step(self, action: np.ndarray) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        return {"state": np.zeros(3, np.float32)}, 0.0, False, False, {}


@cache
def _instances() -> tuple[Any, ...]:
    """Objects SB3 builds the way crowdnav has it build them: models, their buffers, networks and env."""
    from sb3_contrib import RecurrentPPO
    from stable_baselines3 import PPO, SAC, TD3

    def small() -> dict[str, Any]:  # a fresh dict each: SB3 writes into policy_kwargs
        return {"policy_kwargs": {"net_arch": [4]}, "device": "cpu", "seed": 0}

    # a fixed entropy coefficient: SB3 sets ent_coef_tensor only then (log_ent_coef and its optimizer are None then, but set)
    sac = SAC("MultiInputPolicy", _TinyDictEnv(), buffer_size=8, learning_starts=0, ent_coef=0.1, **small())
    td3 = TD3("MultiInputPolicy", _TinyDictEnv(), buffer_size=8, learning_starts=0, **small())
    ppo = PPO("MultiInputPolicy", _TinyDictEnv(), n_steps=8, batch_size=8, **small())
    recurrent = RecurrentPPO("MultiInputLstmPolicy", _TinyDictEnv(), n_steps=8, batch_size=8,
                             **{**small(), "policy_kwargs": {"net_arch": [4], "lstm_hidden_size": 4}})
    return (sac, td3, ppo, recurrent, sac.replay_buffer, ppo.rollout_buffer, recurrent.rollout_buffer, sac.policy, td3.policy,
            ppo.policy, sac.actor, sac.critic, sac.get_env())


def _resolve(path: str) -> Any:
    module, _, rest = path.partition(".")
    found: Any = importlib.import_module(module)
    for part in rest.split("."):
        try:
            found = getattr(found, part)
        except AttributeError:
            found = importlib.import_module(f"{found.__name__}.{part}")
    return found


def _problem(internal: Internal) -> str | None:
    """What is wrong with ``internal`` on the installed SB3, or None."""
    try:
        owner = _resolve(internal.owner)
    except (ImportError, AttributeError):
        return f"{internal.owner} is gone"
    if internal.kind == "attribute":
        instances = [instance for instance in _instances() if isinstance(instance, owner)]
        if not instances:
            return f"no {owner.__name__} among the objects the test builds"
        missing = [type(instance).__name__ for instance in instances if not hasattr(instance, internal.name)]
        return f"attribute missing on {', '.join(missing)}" if missing else None
    member = getattr(owner, internal.name, None)
    if not callable(member):
        return "is gone (or no longer a method)"
    if internal.kind == "method":
        parameters = inspect.signature(member).parameters
        missing = [name for name in internal.parameters if name not in parameters]
        return f"takes {list(parameters)}, crowdnav passes {list(internal.parameters)}" if missing else None
    if internal.kind == "local":
        names = inspect.unwrap(member).__code__.co_varnames
        missing = [name for name in internal.parameters if name not in names]
        return f"has no local {missing} (read through the callback's self.locals)" if missing else None
    found = fingerprint(member)
    if found not in internal.fingerprints:
        return (f"its code changed (fingerprint {found}, crowdnav's copy matches {list(internal.fingerprints)}): port the change "
                "to crowdnav's copy (or judge it irrelevant), then add the fingerprint in crowdnav/agents/sb3/internals.py")
    return None


@pytest.mark.parametrize("internal", SB3_INTERNALS, ids=lambda internal: f"{internal.label}-{internal.kind}")
def test_sb3_internal_is_there_as_crowdnav_uses_it(internal: Internal) -> None:
    problem = _problem(internal)
    assert problem is None, (f"stable-baselines3 {stable_baselines3.__version__}: {internal.label} ({internal.kind}) {problem}; "
                             f"crowdnav relies on it in {internal.used_in}")


def test_every_sb3_internal_is_listed_once() -> None:
    keys = [(internal.owner, internal.name, internal.kind) for internal in SB3_INTERNALS]
    assert len(keys) == len(set(keys)), sorted(key for key in keys if keys.count(key) > 1)


def test_pyproject_bounds_sb3_to_the_tested_versions() -> None:
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    for package in ("stable-baselines3", "sb3-contrib"):  # RecurrentPPO's internals are checked here too
        requirement = re.search(rf'"{package}([^"]*)"', text)
        assert requirement is not None and requirement.group(1) == TESTED_SB3, (package, requirement and requirement.group(0), TESTED_SB3)
    bounds = re.fullmatch(r">=(\d+)\.(\d+),<(\d+)\.(\d+)", TESTED_SB3)
    assert bounds is not None, TESTED_SB3
    low, high = (int(bounds[1]), int(bounds[2])), (int(bounds[3]), int(bounds[4]))
    import sb3_contrib

    for name, version in (("SB3", stable_baselines3.__version__), ("sb3-contrib", sb3_contrib.__version__)):
        installed = tuple(int(part) for part in version.split(".")[:2])
        assert low <= installed < high, f"{name} {version} outside {TESTED_SB3}"


_LOOP = '''
def loop(total):
    """A docstring."""
    count = 0  # a comment
    for step in range(total):
        count += step
    return count
'''


def test_fingerprint_ignores_docstrings_comments_and_layout_but_not_code() -> None:
    reworded = _LOOP.replace("A docstring.", "Another docstring.").replace("# a comment", "").replace("count += step", "count  +=  step")
    changed = _LOOP.replace("count += step", "count += 2 * step")
    assert source_fingerprint(reworded) == source_fingerprint(_LOOP)
    assert source_fingerprint(changed) != source_fingerprint(_LOOP)


def test_a_missing_or_changed_internal_is_reported_with_what_changed() -> None:
    algorithm = "stable_baselines3.common.base_class.BaseAlgorithm"
    assert _problem(Internal(algorithm, "_no_such_counter", "attribute", "nowhere")) == "attribute missing on SAC, TD3, PPO, RecurrentPPO"
    assert "takes" in (_problem(Internal(algorithm, "_update_learning_rate", "method", "nowhere", ("no_such",))) or "")
    assert "has no local" in (_problem(Internal(algorithm, "learn", "local", "nowhere", ("no_such",))) or "")
    assert "its code changed" in (_problem(Internal(algorithm, "learn", "copied", "nowhere", fingerprints=("0" * 16,))) or "")
    gone = "stable_baselines3.no_such_module.Thing"
    assert _problem(Internal(gone, "x", "attribute", "nowhere")) == f"{gone} is gone"
