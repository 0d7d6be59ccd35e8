"""Every exception class crowdnav defines derives from crowdnav.CrowdNavError and keeps its builtin base."""

from __future__ import annotations

import importlib
import inspect
import json
import pickle
import pkgutil
import subprocess
import sys

import crowdnav
from crowdnav import CrowdNavError
from tests.paths import REPO

PACKAGES = ("crowdnav", "crowdnav.agents", "crowdnav.evaluation")


def _exception_classes() -> dict[str, type[BaseException]]:
    """``module.Name`` -> class, for every exception class defined in a crowdnav module (each module imported)."""
    names = set(PACKAGES)
    for package in PACKAGES:
        path = importlib.import_module(package).__path__
        names.update(info.name for info in pkgutil.walk_packages(path, f"{package}.") if not info.name.endswith("__main__"))
    found = {}
    for name in sorted(names):
        for value in vars(importlib.import_module(name)).values():
            if inspect.isclass(value) and issubclass(value, BaseException) and value.__module__ == name:
                found[f"{name}.{value.__qualname__}"] = value
    return found


def test_every_crowdnav_exception_derives_from_crowdnav_error() -> None:
    # The walk imports every module, Ray's executor too: in a child process, so that Ray's import-time state
    # (its authentication settings) cannot leak into the Ray cluster tests of this session.
    script = ("import json\nfrom crowdnav import CrowdNavError\nfrom tests.project.test_errors import _exception_classes\n"
              "print(json.dumps({n: c is CrowdNavError or issubclass(c, CrowdNavError) for n, c in _exception_classes().items()}))")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=REPO, check=True)
    classes = json.loads(done.stdout.strip().splitlines()[-1])
    assert len(classes) >= 24, sorted(classes)  # the walk reaches every layer (24 classes when the base was introduced)
    assert {"crowdnav.scenario.errors.ScenarioError", "crowdnav.agents.training.config.ConfigError",
            "crowdnav.evaluation.storage.ResultsError"} <= classes.keys()
    outside = sorted(name for name, derives in classes.items() if not derives)
    assert not outside, f"exception classes not deriving from crowdnav.CrowdNavError: {outside}"


def test_crowdnav_errors_keep_their_builtin_base_so_callers_catching_it_still_do() -> None:
    from crowdnav.agents.runs.folder import RunBusyError
    from crowdnav.evaluation.evaluate import ResultsExistError

    assert issubclass(crowdnav.ScenarioError, ValueError) and issubclass(crowdnav.SimulationError, RuntimeError)
    assert issubclass(RunBusyError, RuntimeError) and issubclass(ResultsExistError, FileExistsError)
    error = pickle.loads(pickle.dumps(ResultsExistError(17, "results exist")))  # crosses process boundaries (workers, Ray)
    assert isinstance(error, CrowdNavError) and error.errno == 17


def test_crowdnav_error_is_exported_from_the_package() -> None:
    assert "CrowdNavError" in crowdnav.__all__ and crowdnav.CrowdNavError is CrowdNavError
