"""crowdnav export: an ONNX policy run by onnxruntime acts as the torch policy, to 1e-5, on recorded observations."""

from __future__ import annotations

import json

import numpy as np
import pytest
from crowdnav.agents import load_policy, train

from crowdnav.cli import main
from tests.agents.agents_tiny import recorded_observations, tiny_config

ort = pytest.importorskip("onnxruntime", reason='the onnx extra (pip install -e ".[onnx]") runs the exported policies')


@pytest.mark.parametrize(("algo", "modalities", "frozen_leog"), [
    ("sac", ["lidar", "goal"], False),
    ("ppo", ["lidar", "goal", "velocity"], False),
    ("td3", ["humans", "closest_obstacle", "goal"], False),
    ("sac", ["leog", "goal"], False),   # the LEOG CNN inside the network
    ("sac", ["leog", "goal"], True),    # trained on a frozen encoder's latents: the encoder goes into the graph
])
def test_onnxruntime_matches_the_torch_policy_on_recorded_observations(tmp_path, algo, modalities, frozen_leog, request):
    extra = {"encoder": {"mode": "frozen", "weights": str(request.getfixturevalue("encoder_file"))}} if frozen_leog else {}
    config = tiny_config(tmp_path / "run", algo=algo, modalities=modalities, episodes=2, max_steps=40, **extra)
    train(config)
    out = tmp_path / "policy.onnx"
    assert main(["export", str(tmp_path / "run"), "--out", str(out)]) == 0
    policy = load_policy(tmp_path / "run")
    assert (policy.encoder is not None) == frozen_leog and policy.scales  # what the graph must apply itself
    observations = recorded_observations(policy, seed=3)
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    assert sorted(i.name for i in session.get_inputs()) == sorted(modalities)
    actions = session.run(["action"], observations)[0]  # the raw env observation, as it comes
    np.testing.assert_allclose(actions, policy(observations), rtol=0, atol=1e-5)
    one = session.run(["action"], {key: value[:1] for key, value in observations.items()})[0]
    np.testing.assert_allclose(one, policy({key: value[0] for key, value in observations.items()})[None], rtol=0, atol=1e-5)
    assert np.abs(actions).max() <= 1.0 and actions.dtype == np.float32
    assert (np.abs(actions) < 0.999).any() and np.ptp(actions, axis=0).min() > 1e-3  # not a saturated, constant action
    meta = session.get_modelmeta().custom_metadata_map
    assert json.loads(meta["crowdnav.env_options"]) == json.loads(json.dumps(policy.env_options)) and meta["crowdnav.algo"] == algo
    if "leog" in modalities:
        grid = next(i for i in session.get_inputs() if i.name == "leog")
        assert grid.type == "tensor(uint8)" and grid.shape[1:] == [1, 30, 30]


def test_export_refuses_to_overwrite_and_names_a_missing_policy_in_one_line(tmp_path, capsys):
    train(tiny_config(tmp_path / "run", episodes=1, max_steps=20))
    out = tmp_path / "policy.onnx"
    assert main(["export", str(tmp_path / "run"), "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["export", str(tmp_path / "run"), "--out", str(out)]) == 1
    assert "exists; pass --force" in capsys.readouterr().err
    assert main(["export", str(tmp_path / "run"), "--out", str(out), "--force"]) == 0
    for argv, message in ((["export", str(tmp_path / "nowhere")], "no such run folder or checkpoint"),
                          (["export", str(tmp_path), "--out", str(tmp_path / "p.onnx")], str(tmp_path)),
                          (["export", str(tmp_path / "run"), "--out", str(tmp_path / "p.txt")], "ending in .onnx")):
        capsys.readouterr()
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1


NO_TORCH = '''
import json, sys
sys.modules["torch"] = sys.modules["stable_baselines3"] = None  # importing either now fails
import numpy as np
import onnxruntime as ort
from crowdnav import CrowdNavEnv

session = ort.InferenceSession(sys.argv[1], providers=["CPUExecutionProvider"])
env = CrowdNavEnv(**json.loads(session.get_modelmeta().custom_metadata_map["crowdnav.env_options"]))
observation, _ = env.reset(seed=0)
for _ in range(30):
    inputs = {i.name: np.asarray(observation[i.name])[None] for i in session.get_inputs()}
    observation, _, terminated, truncated, info = env.step(session.run(["action"], inputs)[0][0])
    if terminated or truncated:
        break
print(info["outcome"], "torch" in sys.modules and sys.modules["torch"] is not None)
'''


def test_the_exported_policy_drives_the_env_with_onnxruntime_and_without_torch(tmp_path):
    import subprocess
    import sys

    train(tiny_config(tmp_path / "run", modalities=["lidar", "goal", "velocity"], episodes=1, max_steps=20))
    assert main(["export", str(tmp_path / "run"), "--out", str(tmp_path / "policy.onnx")]) == 0
    done = subprocess.run([sys.executable, "-c", NO_TORCH, str(tmp_path / "policy.onnx")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    outcome, torch_loaded = done.stdout.split()
    assert outcome in ("success", "collision", "out_of_bounds", "truncated") and torch_loaded == "False"
