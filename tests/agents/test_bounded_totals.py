"""Bounds on totals: a model's parameters and a model zip's uncompressed bytes are counted before anything is allocated.

Each bound is within the per-layer and per-member limits but over the total one; every refusal
runs in a fresh process whose peak memory (``ru_maxrss``) must stay under 1 GiB and whose error
is one line (no wall-time asserts: a loaded machine would make them flaky, and memory is what a
late refusal costs).
"""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile

import pytest
from crowdnav.agents.networks.size import MAX_PARAMETERS, NetworkSizeError, model_parameters
from crowdnav.agents.runs.checkpoint import POLICY_FORMAT
from crowdnav.agents.sb3.factory import env_options, hyperparameters, make_env, make_model
from crowdnav.agents.sb3.model_zip import MAX_TOTAL_BYTES, zip_parameters
from crowdnav.agents.training.config import config_from_mapping, config_to_dict

from tests.agents.agents_tiny import tiny_config
from tests.paths import REPO

GIB_KIB = 1 << 20
"""1 GiB in the KiB that ru_maxrss counts on Linux."""

WIDE = [4096] * 16
"""16 layers of 4,096 units: within the per-layer bounds, 268 M parameters per head."""

_CHILD = """
import resource, sys
argv = sys.argv[1:]
try:
    if argv[0] == "load_robots_policy":
        from crowdnav.agents.marl.robots import load_robots_policy
        load_robots_policy(argv[1])
        code = 0
    else:
        from crowdnav.cli import main
        code = main(argv)
except Exception as error:
    print(f"{type(error).__name__}: {error}", file=sys.stderr)
    code = 1
print(f"maxrss_kib={resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}", file=sys.stderr)
sys.exit(code)
"""


def _refused(*argv: str) -> str:
    """Run ``argv`` (crowdnav's CLI, or ``load_robots_policy FOLDER``) in a fresh process: its one-line error, after the memory check."""
    result = subprocess.run([sys.executable, "-c", _CHILD, *argv], capture_output=True, text=True, timeout=300, cwd=REPO)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 1, result.stderr[-2000:]
    assert "Traceback" not in result.stderr and len(lines) == 2, result.stderr[-2000:]
    peak = int(lines[1].removeprefix("maxrss_kib="))
    assert peak < GIB_KIB, f"refusing cost {peak / 1024:.0f} MiB"
    return lines[0]


def _policy_json(folder, **fields) -> None:
    """A checkpoint folder whose policy.json describes the tiny config with ``fields`` (no model.zip: the refusal comes first)."""
    config = config_from_mapping(tiny_config(folder, modalities=["goal"], **fields))
    folder.mkdir(parents=True, exist_ok=True)
    info = {"format": POLICY_FORMAT, "algo": config.algo, "env": env_options(config), "observation_normalization": None,
            "episodes": 1, "timesteps": 60, "config": config_to_dict(config), "leog_encoder": None}
    (folder / "policy.json").write_text(json.dumps(info), encoding="utf-8")


@pytest.mark.parametrize("algo", ["sac", "td3", "ddpg", "ppo", "a2c"])
@pytest.mark.parametrize("fields", [
    {"modalities": ["lidar", "goal"]},
    {"modalities": ["leog", "goal", "velocity", "humans"], "policy_kwargs": {"share_features_extractor": True}},
    {"modalities": ["goal", "closest_obstacle"], "policy_kwargs": {"share_features_extractor": False},
     "extractor": {"lidar_conv_channels": [4], "rbf_trainable": True, "rbf_centres": 3, "lowdim_hidden": [8],
                   "leog_channels": [4, 8], "leog_kernels": [4, 3], "leog_strides": [4, 2], "leog_latent": 8}},
], ids=["lidar", "leog-shared", "lowdim-separate"])
def test_the_counted_parameters_are_those_the_built_model_holds(tmp_path, algo, fields):
    config = config_from_mapping(tiny_config(tmp_path, algo=algo, **fields))
    env = make_env(config)
    built = sum(parameter.numel() for parameter in make_model(config, env).policy.parameters())
    assert model_parameters(config, hyperparameters(config)["net_arch"], env.observation_space, env.action_space) == built


@pytest.mark.parametrize(("algo", "fields"), [("sac", {"policy_kwargs": {"n_critics": 3}}), ("td3", {"policy_kwargs": {"n_critics": 4}}),
                                              ("sac", {"algo_kwargs": {"use_sde": True}}),
                                              ("ppo", {"algo_kwargs": {"use_sde": True, "n_steps": 32}, "policy_kwargs": {"full_std": False}})])
def test_critics_and_state_dependent_noise_are_counted(tmp_path, algo, fields):
    config = config_from_mapping(tiny_config(tmp_path, algo=algo, modalities=["lidar"], **fields))
    env = make_env(config)
    built = sum(parameter.numel() for parameter in make_model(config, env).policy.parameters())
    assert model_parameters(config, hyperparameters(config)["net_arch"], env.observation_space, env.action_space) == built


@pytest.mark.parametrize("algo", ["ppo", "sac", "td3", "ddpg"])
def test_an_sb3_zip_policy_is_counted_as_sb3_builds_it(algo):
    import stable_baselines3 as sb3
    from stable_baselines3.common.preprocessing import is_image_space

    from crowdnav import CrowdNavEnv

    env = CrowdNavEnv("open_space", modalities=["goal", "leog"], sensors={"leog": {"size": 6.4, "resolution": 0.1}})
    assert is_image_space(env.observation_space["leog"])  # SB3 puts its NatureCNN on the grid
    options = {"n_steps": 32, "policy_kwargs": {"net_arch": {"pi": [32], "vf": [16, 8]}}} if algo == "ppo" else \
        {"buffer_size": 10, "policy_kwargs": {"net_arch": [32, 16]}}
    model = getattr(sb3, algo.upper())("MultiInputPolicy", env, device="cpu", **options)
    kwargs = {"net_arch": model.policy_kwargs["net_arch"], **({"n_critics": 1} if algo == "ddpg" else {})}
    built = sum(parameter.numel() for parameter in model.policy.parameters())
    assert zip_parameters(type(model.policy), kwargs, env.observation_space, env.action_space)[0] == built


def test_a_train_config_over_the_total_is_refused_before_building(tmp_path):
    config = config_from_mapping(tiny_config(tmp_path, modalities=["goal"], net_arch=WIDE))
    with pytest.raises(NetworkSizeError, match=rf"would hold 1,\d{{3}},\d{{3}},\d{{3}} parameters .*more than the {MAX_PARAMETERS:,}"):
        make_model(config, make_env(config))


def test_wide_heads_in_a_policy_json_are_refused_in_one_line_under_1_gib(tmp_path):
    _policy_json(tmp_path / "ckpt", net_arch=WIDE)  # 5.3 GB in 28 s before this bound
    error = _refused("evaluate", str(tmp_path / "ckpt"), "--scenario", "open_space", "--out", str(tmp_path / "out"))
    assert "parameters" in error and f"{MAX_PARAMETERS:,}" in error and "[4096 x 16]" in error


def test_many_critics_in_a_policy_json_are_refused_in_one_line_under_1_gib(tmp_path):
    _policy_json(tmp_path / "ckpt", net_arch=[4096] * 4, policy_kwargs={"n_critics": 16})  # 7.6 GB and a traceback before
    error = _refused("evaluate", str(tmp_path / "ckpt"), "--scenario", "open_space", "--out", str(tmp_path / "out"))
    assert "parameters" in error and "16 critics" in error


def test_a_train_config_with_wide_heads_is_refused_by_the_cli_under_1_gib(tmp_path):
    (tmp_path / "wide.yaml").write_text(json.dumps(tiny_config(tmp_path / "run", modalities=["goal"], net_arch=WIDE)), encoding="utf-8")
    error = _refused("train", "--config", str(tmp_path / "wide.yaml"))
    assert "parameters" in error and f"{MAX_PARAMETERS:,}" in error


def test_wide_heads_in_a_robots_policy_json_are_refused_under_1_gib(tmp_path):
    config = config_from_mapping({**tiny_config(tmp_path, algo="ppo", modalities=["goal"], net_arch=WIDE), "agents": "robots",
                                  "scenario": "robots_crossing_hall", "overrides": {}})
    info = {"format": POLICY_FORMAT, "algo": "ppo", "agents": "robots", "env": env_options(config), "config": config_to_dict(config),
            "robots": {"robots": ["robot_0", "robot_1"], "identity": True, "offset": [0.0, 0.0], "scale": [1.0, 1.0]},
            "episodes": 1, "timesteps": 1, "next_episode": 1, "successes": 0}
    (tmp_path / "policy.json").write_text(json.dumps(info), encoding="utf-8")
    error = _refused("load_robots_policy", str(tmp_path))
    assert "parameters" in error and "[4096 x 16]" in error and f"{MAX_PARAMETERS:,}" in error


def _sb3_zip(path, data_update):
    from stable_baselines3 import PPO

    from crowdnav import CrowdNavEnv

    PPO("MultiInputPolicy", CrowdNavEnv("open_space", modalities=["goal"]), n_steps=32, batch_size=16, seed=0).save(path)
    with zipfile.ZipFile(path) as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(entries["data"])
    data_update(data)
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as archive:
        for name, content in entries.items():
            archive.writestr(name, content)
    return path


def test_wide_heads_in_an_sb3_zip_are_refused_in_one_line_under_1_gib(tmp_path):
    def widen(data):
        data["policy_kwargs"] = {"net_arch": {"pi": WIDE, "vf": WIDE}}

    path = _sb3_zip(tmp_path / "wide.zip", widen)
    error = _refused("evaluate", str(path), "--scenario", "open_space", "--modalities", "goal", "--out", str(tmp_path / "out"))
    assert "parameters" in error and "wide.zip" in error


def test_a_zip_whose_members_sum_over_the_total_is_refused_before_reading_any(tmp_path):
    path = tmp_path / "bomb.zip"  # two 600 MiB members of zeros, each under the 1 GiB per-member limit: 5 MB on disk
    chunk = bytes(1 << 20)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as archive:
        archive.writestr("data", "{}")
        for name in ("policy.pth", "policy.optimizer.pth"):
            with archive.open(name, "w", force_zip64=True) as member:
                for _ in range(600):
                    member.write(chunk)
    assert path.stat().st_size < 10 << 20
    error = _refused("evaluate", str(path), "--scenario", "open_space", "--modalities", "goal", "--out", str(tmp_path / "out"))
    assert f"hold {2 * 600 * (1 << 20) + 2:,} bytes uncompressed" in error and f"{MAX_TOTAL_BYTES:,}" in error


def test_a_zip_with_more_members_than_allowed_is_refused(tmp_path):
    from crowdnav.agents.sb3.model_zip import MAX_MEMBERS, ModelZipError, read_model_zip

    path = tmp_path / "many.zip"
    with zipfile.ZipFile(path, "w") as archive:
        for index in range(MAX_MEMBERS + 1):
            archive.writestr(f"m{index}.pth", b"")
    with pytest.raises(ModelZipError, match=rf"{MAX_MEMBERS + 1} entries, more than an SB3 model zip holds \({MAX_MEMBERS}\)"):
        read_model_zip(path)
