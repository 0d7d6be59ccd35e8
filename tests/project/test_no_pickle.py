"""No code runs from a file crowdnav loads: every POLICY form and every resume works with pickle broken,
and a pickle payload planted in a model zip never runs."""

from __future__ import annotations

import base64
import json
import pickle
import random
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from crowdnav.agents import ConfigError, load_policy, train
from crowdnav.agents.runs.checkpoint import UntrustedCheckpointError
from crowdnav.agents.runs.resume_state import ROLLOUT_ARRAYS, STATE_FILE
from crowdnav.evaluation.evaluate import PolicyError, evaluate_policy

from crowdnav.cli import main
from tests.agents.agents_tiny import tiny_config


class Stopped(Exception):
    """Stands for a kill right after a checkpoint."""


def _break_pickle(patch):
    """Every way of unpickling raises (pickle, its Unpickler, cloudpickle); torch's weights_only reader and JSON still work."""
    import cloudpickle

    def refuse(*args, **kwargs):
        raise AssertionError("something was unpickled")

    class Refused(pickle.Unpickler):  # a class: modules imported meanwhile may subclass pickle.Unpickler
        def __init__(self, *args, **kwargs):
            refuse()

    for name in ("loads", "load"):
        patch.setattr(pickle, name, refuse)
        patch.setattr(cloudpickle, name, refuse)
    patch.setattr(pickle, "Unpickler", Refused)


@pytest.fixture
def no_pickle(monkeypatch):
    _break_pickle(monkeypatch)


def _records(result) -> list[tuple]:
    return [(r.seed, r.outcome, r.reward, r.length, r.timesteps) for r in result.records]


def _weights(result) -> list[bytes]:
    return [p.detach().numpy().tobytes() for p in result.model.policy.parameters()]


def _stop_at_first_checkpoint(config, when=lambda folder: True):
    def stop(episodes):
        if when(Path(config["out"])):
            raise Stopped

    with pytest.raises(Stopped):
        train(config, on_checkpoint=stop)


def _sb3_zip(path, **policy_kwargs):
    from stable_baselines3 import PPO

    from crowdnav import CrowdNavEnv

    PPO("MultiInputPolicy", CrowdNavEnv("open_space", modalities=["goal"]), n_steps=32, batch_size=16, seed=0,
        policy_kwargs=policy_kwargs or None).save(path)
    return path


def test_every_policy_form_is_evaluated_with_pickle_broken(tmp_path, no_pickle):
    run = tmp_path / "runs" / "sac"
    train(tiny_config(run, modalities=["goal", "closest_obstacle"], episodes=2))
    sb3 = _sb3_zip(tmp_path / "their_ppo.zip")
    finals = []
    for policy in (run, run / "checkpoint", run / "checkpoint" / "model.zip", run / "checkpoint" / "policy.json"):
        folder = evaluate_policy(str(policy), "open_space", tmp_path / "results", episodes=2, force=True)  # one policy: one folder
        finals.append(json.loads((folder / "meta.json").read_text())["final"])
    assert finals[1:] == finals[:-1]  # one policy, whichever way it is named
    assert evaluate_policy(str(sb3), "open_space", tmp_path / "results", modalities=["goal"], episodes=2).is_dir()
    assert evaluate_policy("baseline:straight", "open_space", tmp_path / "results", episodes=2).is_dir()
    code = main(["render", "open_space", "--policy", str(run / "checkpoint" / "model.zip"), "--episodes", "1", "--format", "gif",
                 "--out", str(tmp_path / "videos"), "--no-progress"])
    assert code == 0 and len(list((tmp_path / "videos").glob("*.gif"))) == 1


@pytest.mark.slow
@pytest.mark.parametrize(("algo", "fields"), [
    ("sac", {"algo_kwargs": {"train_freq": 4}}),  # rewound to an episode end; replay buffer as arrays
    ("ppo", {"num_envs": 4, "n_steps": 16, "algo_kwargs": {"n_epochs": 1}}),  # batched: 4 worlds stored mid-episode
], ids=["sac", "ppo-batched"])
def test_a_run_resumes_exactly_with_pickle_broken(tmp_path, monkeypatch, algo, fields):
    whole = train(tiny_config(tmp_path / "whole", algo=algo, episodes=8, **fields))
    config = tiny_config(tmp_path / "stopped", algo=algo, episodes=8, **fields)

    def mid_episode(out):
        rollout = out / "checkpoint" / ROLLOUT_ARRAYS
        if not rollout.is_file():
            return True
        with np.load(rollout, allow_pickle=False) as saved:
            return bool((saved["worlds/episode_lengths"] > 0).any())

    _stop_at_first_checkpoint(config, mid_episode)
    checkpoint = tmp_path / "stopped" / "checkpoint"
    assert not list(checkpoint.glob("*.pkl")) and (checkpoint / STATE_FILE).is_file()
    if algo == "ppo":  # the worlds as their states: arrays and JSON
        with np.load(checkpoint / ROLLOUT_ARRAYS, allow_pickle=False) as saved:
            assert json.loads(str(saved["meta.json"]))["worlds"]["kind"] == "states"
    with monkeypatch.context() as patch:
        _break_pickle(patch)
        resumed = train(config, resume=True)
    assert resumed.records and _records(resumed) == _records(whole)[-len(resumed.records):]
    assert _weights(resumed) == _weights(whole)


class _Payload:
    """Unpickling this creates a file: the proof that a pickle ran."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _plant(zip_path, marker) -> None:
    """Every pickled value of the zip's data becomes the payload (the JSON beside it is kept)."""
    with zipfile.ZipFile(zip_path) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(entries["data"])
    payload = base64.b64encode(pickle.dumps(_Payload(marker))).decode()
    planted = 0
    for value in data.values():
        if isinstance(value, dict) and ":serialized:" in value:
            value[":serialized:"] = payload
            planted += 1
    assert planted >= 3
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(zip_path, "w") as archive:
        for name, content in entries.items():
            archive.writestr(name, content)


def test_a_pickle_payload_in_a_model_zip_never_runs(tmp_path):
    marker = tmp_path / "marker"
    _plant(_sb3_zip(tmp_path / "probe.zip"), marker)
    from stable_baselines3 import PPO

    with pytest.raises(ValueError):  # the payload is live: SB3's own load runs it (then fails on what it returned) ...
        PPO.load(tmp_path / "probe.zip")
    assert marker.exists()
    marker.unlink()
    run = tmp_path / "run"
    train(tiny_config(run, modalities=["goal"], episodes=2, checkpoint_every=1))
    _plant(run / "checkpoint" / "model.zip", marker)
    _plant(_sb3_zip(tmp_path / "their_ppo.zip"), marker)
    for policy in (run, run / "checkpoint", run / "checkpoint" / "model.zip"):  # ... crowdnav never decodes it
        evaluate_policy(str(policy), "open_space", tmp_path / "results", episodes=1, force=True)
    evaluate_policy(str(tmp_path / "their_ppo.zip"), "open_space", tmp_path / "results", modalities=["goal"], episodes=1)
    train(tiny_config(run, modalities=["goal"], episodes=3, checkpoint_every=1), resume=True)
    assert not marker.exists()


def test_a_pickle_inside_a_tensor_file_is_one_line_and_never_runs(tmp_path, capsys):
    marker = tmp_path / "marker"
    path = _sb3_zip(tmp_path / "their_ppo.zip")
    with zipfile.ZipFile(path) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    entries["policy.pth"] = pickle.dumps(_Payload(marker))
    with zipfile.ZipFile(path, "w") as archive:
        for name, content in entries.items():
            archive.writestr(name, content)
    assert main(["evaluate", str(path), "--scenario", "open_space", "--modalities", "goal", "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip()
    assert "policy.pth holds more than tensors" in err and err.count("\n") == 0
    assert not marker.exists()


def test_network_sizes_are_refused_before_anything_is_built(tmp_path):
    run = tmp_path / "run"
    train(tiny_config(run, modalities=["goal"], episodes=1))
    info_path = run / "checkpoint" / "policy.json"
    info = json.loads(info_path.read_text())
    info["config"]["net_arch"] = [20000, 20000]  # 4.95 GB once built
    info_path.write_text(json.dumps(info))
    with pytest.raises((UntrustedCheckpointError, ValueError), match=r"net_arch\.0: expected an integer <= 4096, got 20000"):
        load_policy(run)
    info["config"]["net_arch"], info["config"]["extractor"]["lidar_hidden"] = [16], [10**6]
    info_path.write_text(json.dumps(info))
    with pytest.raises(UntrustedCheckpointError, match="extractor.lidar_hidden"):
        load_policy(run)
    with pytest.raises(PolicyError, match=r"net_arch: expected at most 16 layers"):
        evaluate_policy(str(_sb3_zip(tmp_path / "wide.zip", net_arch=[8] * 17)), "open_space", tmp_path, modalities=["goal"], episodes=1)


def _legacy(checkpoint) -> None:
    """The checkpoint as an older crowdnav wrote it: random streams and replay buffer pickled, no training_state.json."""
    from crowdnav.agents.runs.checkpoint import load_model
    from crowdnav.agents.runs.resume_state import REPLAY_ARRAYS, load_replay_buffer

    model = load_model(checkpoint)
    load_replay_buffer(model.replay_buffer, checkpoint / REPLAY_ARRAYS)
    model.save_replay_buffer(checkpoint / "replay_buffer.pkl")
    (checkpoint / REPLAY_ARRAYS).unlink()
    state = json.loads((checkpoint / STATE_FILE).read_text())
    (checkpoint / STATE_FILE).unlink()
    (checkpoint / ROLLOUT_ARRAYS).unlink(missing_ok=True)
    streams = {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "random": random.getstate(), "action_space": None,
               "steps_after_episode_end": state["rng"].get("steps_after_episode_end", 0)}
    (checkpoint / "rng_state.pkl").write_bytes(pickle.dumps(streams))


def test_an_older_pickled_checkpoint_is_refused_unless_pickle_is_trusted(tmp_path, capsys):
    config = tiny_config(tmp_path, episodes=4, max_steps=20)
    _stop_at_first_checkpoint(config)
    _legacy(tmp_path / "checkpoint")
    refused = r"written by an older crowdnav, whose resume state is pickled \(rng_state\.pkl, replay_buffer\.pkl, .*--trust-pickle"
    with pytest.raises(ConfigError, match=refused):
        train(config, resume=True)
    assert train(config, resume=True, trust_pickle=True).episodes == 4


def test_a_damaged_resume_state_is_refused_with_one_line(tmp_path):
    config = tiny_config(tmp_path, algo="ppo", episodes=4, max_steps=40, algo_kwargs={"n_steps": 32, "n_epochs": 1})
    _stop_at_first_checkpoint(config)
    rollout = tmp_path / "checkpoint" / ROLLOUT_ARRAYS
    with np.load(rollout, allow_pickle=False) as saved:
        arrays = dict(saved)
    assert arrays["worlds/episode_lengths"][0] > 0  # 32 steps into a 40-step episode, stored as the world's state
    arrays["worlds/0/world/env/observation/goal"] += 0.5  # the one world's env (a single env) loads its last observation
    np.savez(rollout, **arrays)
    with pytest.raises(ConfigError, match="loading its worlds' states does not give the observation it holds"):
        train(config, resume=True)
    (tmp_path / "checkpoint" / STATE_FILE).write_text("{")
    rollout.unlink()
    with pytest.raises(ConfigError, match=f"cannot resume: .*{STATE_FILE}: cannot resume from it"):
        train(config, resume=True)
