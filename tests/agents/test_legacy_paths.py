"""Files written before agents/ became subpackages still load: the old module paths they name import as the new modules."""

from __future__ import annotations

import importlib
import pickle
import subprocess
import sys
import zipfile

import pytest
from crowdnav.agents.legacy import MOVED
from crowdnav.agents.training.config import config_from_mapping

from tests.agents.agents_tiny import tiny_config


@pytest.mark.parametrize("old", sorted(MOVED))
def test_every_old_module_path_is_the_new_module(old):
    new = importlib.import_module(MOVED[old])
    assert importlib.import_module(old) is new and sys.modules[old] is new and new.__name__ == MOVED[old]


def test_an_old_path_that_never_existed_is_still_not_found():
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module("crowdnav.agents.no_such_module")


@pytest.mark.parametrize(("old", "name"), [("crowdnav.agents.extractor", "MultiModalExtractor"),
                                           ("crowdnav.agents.algorithms", "CrowdNavSACPolicy"),
                                           ("crowdnav.agents.replay_buffer", "PackedGridReplayBuffer"),
                                           ("crowdnav.agents.marl_networks", "KindActorCriticPolicy"),
                                           ("crowdnav.agents.factory", "LinearDecay")])
def test_a_pickle_naming_a_class_by_its_old_module_loads_the_class(old, name):
    """The bytes an older crowdnav's pickle holds for a class: its module path (the old one) and its name."""
    old_pickle = f"c{old}\n{name}\n.".encode()
    assert pickle.loads(old_pickle) is getattr(importlib.import_module(MOVED[old]), name)


def test_an_sb3_zip_saved_under_the_old_module_paths_loads_in_a_fresh_interpreter(tmp_path, monkeypatch):
    """A SAC model.zip as crowdnav wrote it before the move (its pickles name crowdnav.agents.extractor and the like),
    loaded by SB3's own ``SAC.load`` in a new process, where nothing but the legacy finder knows the old paths."""
    from crowdnav.agents.sb3.factory import make_env, make_model

    config = config_from_mapping(tiny_config(tmp_path / "run", modalities=("lidar", "goal")))
    model = make_model(config, make_env(config))
    classes = {type(model.policy): "crowdnav.agents.algorithms", model.replay_buffer_class: "crowdnav.agents.replay_buffer",
               model.policy_kwargs["features_extractor_class"]: "crowdnav.agents.extractor"}
    for cls, old in classes.items():
        importlib.import_module(old)  # pickled by reference only where the old path finds the class
        monkeypatch.setattr(cls, "__module__", old)
    model.save(tmp_path / "model.zip")
    monkeypatch.undo()
    with zipfile.ZipFile(tmp_path / "model.zip") as archive:
        data = archive.read("data").decode()
    assert "crowdnav.agents.extractor.MultiModalExtractor" in data and "crowdnav.agents.networks" not in data

    code = ("import sys\nfrom stable_baselines3 import SAC\n"
            f"model = SAC.load({str(tmp_path / 'model.zip')!r}, device='cpu')\n"
            "print(type(model.policy).__module__, model.replay_buffer_class.__module__,"
            " model.policy_kwargs['features_extractor_class'].__module__)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["crowdnav.agents.sb3.algorithms", "crowdnav.agents.sb3.replay_buffer",
                                     "crowdnav.agents.networks.extractor"]
