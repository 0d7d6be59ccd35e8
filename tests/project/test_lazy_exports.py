"""agents and evaluation import their heavy modules only when one of their names is used."""

from __future__ import annotations

import subprocess
import sys

import crowdnav.agents as agents
import crowdnav.evaluation as evaluation
import pytest

from tests.paths import REPO


def test_importing_the_packages_and_the_command_line_loads_no_torch_pandas_or_matplotlib():
    code = ("import sys, crowdnav.cli\nfrom crowdnav import agents, evaluation\n"
            "heavy = [name for name in ('torch', 'pandas', 'matplotlib', 'stable_baselines3') if name in sys.modules]\n"
            "assert not heavy, heavy\n"
            "agents.train_seed, evaluation.Protocol\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)


@pytest.mark.parametrize("package", [agents, evaluation])
def test_every_export_resolves_and_an_unknown_name_is_an_attribute_error(package):
    for name in package.__all__:
        assert getattr(package, name) is not None and name in dir(package)
    with pytest.raises(AttributeError, match=f"module '{package.__name__}' has no attribute 'no_such_name'"):
        package.no_such_name  # noqa: B018
