"""``run_folder.writing``: a refusal (a CrowdNavError) leaves no run folder behind, and never removes one that holds anything."""

from __future__ import annotations

import pytest
from crowdnav.agents.runs.folder import EPISODE_LOG, writing
from crowdnav.agents.training.config import ConfigError


def test_a_refusal_removes_the_folder_it_created_with_its_setup_files_and_new_parents(tmp_path):
    out = tmp_path / "a" / "b" / "run"
    with pytest.raises(ConfigError, match="refused"), writing(out):
        (out / "config.yaml").write_text("algo: ppo\n", encoding="utf-8")
        (out / EPISODE_LOG).write_text("episode,seed\n", encoding="utf-8")  # the header only: nothing trained
        raise ConfigError("refused")
    assert not (tmp_path / "a").exists()


@pytest.mark.parametrize("made", ["logged", "checkpoint", "existing", "bug"])
def test_a_folder_with_anything_trained_a_folder_that_existed_or_a_bug_is_kept(tmp_path, made):
    out = tmp_path / "run"
    if made == "existing":
        out.mkdir()
    error = RuntimeError("bug") if made == "bug" else ConfigError("refused")
    with pytest.raises(type(error)), writing(out):
        if made == "logged":
            (out / EPISODE_LOG).write_text("episode,seed\n0,1000\n", encoding="utf-8")
        if made == "checkpoint":
            (out / "checkpoint").mkdir()
        raise error
    assert out.is_dir()
