"""Bounds of the SARL agent (issue 49, items 3 and 5): its sizes checked before anything is allocated, its checkpoint files
checked before they are used (npz headers against state.json, finite weights, state.json's fields), and a world whose
sensors differ from the trained ones refused in one line naming the setting and both values."""

from __future__ import annotations

import dataclasses
import json
import zipfile

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

torch = pytest.importorskip("torch")

from crowdnav.agents import load_policy, train  # noqa: E402
from crowdnav.agents.networks.size import MAX_PARAMETERS  # noqa: E402
from crowdnav.agents.sarl.agent import SarlAgent  # noqa: E402
from crowdnav.agents.sarl.files import SarlFileError  # noqa: E402
from crowdnav.agents.sarl.network import value_network  # noqa: E402
from crowdnav.agents.sarl.options import network_parameters  # noqa: E402
from crowdnav.agents.sarl.sensing import SensorMismatchError  # noqa: E402
from crowdnav.agents.training.config import ConfigError  # noqa: E402

from crowdnav import CrowdNavEnv  # noqa: E402
from tests.agents.test_bounded_totals import _refused  # noqa: E402
from tests.agents.test_sarl import config  # noqa: E402


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A two-episode SARL run with one teacher episode (every checkpoint file holds arrays)."""
    out = tmp_path_factory.mktemp("sarl") / "run"
    train(config(out, episodes=2, algo_kwargs={**config("x")["algo_kwargs"], "imitation_episodes": 1, "imitation_epochs": 1}))
    return out


def _copy(run, tmp_path):
    import shutil

    shutil.copytree(run, tmp_path / "run")
    return tmp_path / "run", tmp_path / "run" / "checkpoint" / "algorithm"


@pytest.mark.parametrize(("width", "members", "room", "robot_features"), [(16, 1, False, 3), (64, 3, True, 4), (7, 2, False, 4)])
def test_the_counted_parameters_are_those_the_built_network_holds(width, members, room, robot_features):
    built = sum(parameter.numel() for parameter in value_network(width, members, room, robot_features).parameters())
    assert network_parameters(width, members, room, robot_features) == built


def test_a_width_beyond_its_bound_is_refused_by_the_cli_in_one_line_under_1_gib(tmp_path):
    (tmp_path / "wide.yaml").write_text(json.dumps(config(tmp_path / "run", algo_kwargs={"width": 20000})), encoding="utf-8")
    error = _refused("train", "--config", str(tmp_path / "wide.yaml"))  # 4.95 GB and a traceback before
    assert "algo_kwargs.width: 'sarl' takes an integer from 1 to 4096, got 20000" in error


def test_networks_over_the_total_are_refused_before_building(tmp_path):
    with pytest.raises(ConfigError, match=rf"^algo_kwargs.width: its networks would hold [\d,]+ parameters \(sarl, width 2048, "
                                          rf"ensemble 8\), more than the {MAX_PARAMETERS:,}"):
        train(config(tmp_path / "a", algo_kwargs={"width": 2048, "ensemble": 8}))


def test_a_replay_memory_over_its_total_is_refused_in_one_line(tmp_path):
    with pytest.raises(ConfigError, match=r"^algo_kwargs.memory_size: 10,000,000 transitions of 312 bytes \(5 humans, 0 static "
                                          r"shapes\) take 2.91 GiB, more than the 1.00 GiB"):
        train(config(tmp_path / "a", algo_kwargs={"memory_size": 10_000_000}))


@pytest.mark.parametrize(("option", "value", "expected"), [
    ("batch_size", 0, "algo_kwargs.batch_size: 'sarl' takes an integer from 1 to 100000, got 0"),
    ("target_update_every", 0, "algo_kwargs.target_update_every: 'sarl' takes an integer from 1 to 1000000, got 0"),
    ("memory_size", "big", "algo_kwargs.memory_size: 'sarl' takes an integer from 1 to 10000000, got 'big'"),
    ("epsilon_start", float("nan"), "algo_kwargs.epsilon_start: 'sarl' takes a rate from 0 to 1, got nan"),
])
def test_each_option_out_of_its_bounds_is_refused_in_one_line(tmp_path, option, value, expected):
    with pytest.raises(ConfigError) as error:
        train(config(tmp_path / "a", algo_kwargs={option: value}))
    assert str(error.value) == expected


def test_a_tampered_state_json_width_is_refused_naming_the_file_under_1_gib(run, tmp_path):
    copy, folder = _copy(run, tmp_path)
    document = json.loads((folder / "state.json").read_text(encoding="utf-8"))
    document["options"]["width"] = 20000
    (folder / "state.json").write_text(json.dumps(document), encoding="utf-8")
    error = _refused("evaluate", str(copy), "--scenario", "open_space", "--episodes", "1", "--out", str(tmp_path / "out"))
    assert "state.json: options.width: 'sarl' takes an integer from 1 to 4096, got 20000" in error


@pytest.mark.parametrize(("field", "value", "expected"), [
    ("humans", "five", r"state.json: humans: expected an integer from 0 to 100,000, got 'five'$"),
    ("gamma", float("nan"), r"state.json: gamma: expected a number from 0.0 to 1.0, got nan$"),
    ("rng", {"bit_generator": "PCG64", "state": 3}, r"state.json: rng: not a PCG64 state"),
    ("physics", {"radius": 0.3}, r"state.json: physics: expected the fields"),
    ("adam_groups", [{"lr": 0.001}, {"lr": 0.001}], r"state.json: adam_groups: not the state of this agent's optimiser"),
])
def test_a_malformed_state_json_field_is_refused_in_one_line_naming_it(run, tmp_path, field, value, expected):
    _, folder = _copy(run, tmp_path)
    document = json.loads((folder / "state.json").read_text(encoding="utf-8"))
    document[field] = value
    (folder / "state.json").write_text(json.dumps(document), encoding="utf-8")
    with pytest.raises(SarlFileError, match=expected) as error:
        SarlAgent.load(folder)
    assert "\n" not in str(error.value)


def _with_member(path, name, header_shape, data=b"\0" * 64):
    """``path`` with member ``name`` replaced by a float32 array header declaring ``header_shape`` over ``data``."""
    with zipfile.ZipFile(path) as archive:
        members = {info.filename: archive.read(info) for info in archive.infolist()}
    import io

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": header_shape})
    members[f"{name}.npy"] = header.getvalue() + data
    with zipfile.ZipFile(path, "w") as archive:
        for member, content in members.items():
            archive.writestr(member, content)


@pytest.mark.parametrize(("file", "member", "shape", "expected"), [
    ("memory.npz", "humans", (1_000_000_000, 5, 7), r"memory.npz: humans.npy: declares 140,000,000,000 bytes"),
    ("weights.npz", "network.value.0.weight", (16, 99),
     r"weights.npz: network.value.0.weight: expected shape \(16, 11\) \(float\), holds \(16, 99\)"),
    ("demonstrations.npz", "returns", (3,), r"demonstrations.npz: returns: expected shape \(\d+,\) \(float\), holds \(3,\)"),
])
def test_an_npz_member_of_another_shape_is_refused_from_its_header(run, tmp_path, file, member, shape, expected):
    _, folder = _copy(run, tmp_path)
    size = int(np.prod(shape)) * 4
    _with_member(folder / file, member, shape, b"\0" * (64 if size > 1 << 20 else size))
    with pytest.raises(SarlFileError, match=expected) as error:  # a MemoryError or a 26-60 line traceback before
        SarlAgent.load(folder)
    assert "\n" not in str(error.value)


def test_nan_weights_are_refused_naming_the_file(run, tmp_path):
    copy, folder = _copy(run, tmp_path)
    with np.load(folder / "weights.npz") as arrays:
        weights = dict(arrays)
    weights["network.value.0.weight"][0, 0] = np.nan  # loaded silently before
    np.savez(folder / "weights.npz", **weights)
    with pytest.raises(ValueError, match=r"weights.npz: network.value.0.weight: holds NaN or infinite values$"):
        load_policy(copy)


def test_another_tracker_size_is_refused_naming_the_setting_and_both_values(run):
    policy = load_policy(run)
    env = CrowdNavEnv(**{**policy.env_options, "sensors": {"humans": {"count": 8}}})
    observation = {key: np.asarray(value) for key, value in env.reset(seed=0)[0].items()}
    message = "sensors.humans.count: this SARL agent was trained with 5 tracked humans, the world gives 8; evaluate it with sensors.humans.count=5"
    with pytest.raises(SensorMismatchError) as error:  # a raw broadcast error before
        policy.model.predict(observation)
    assert str(error.value) == message
    with pytest.raises(SensorMismatchError, match="^sensors.humans.count: .* trained with 5 .* gives 8"):
        policy.model.check_world(env.observation_space, env.scenario)
    own = policy.make_env()
    policy.model.check_world(own.observation_space, own.scenario)  # its own world passes
    assert policy(own.reset(seed=0)[0]).shape == (2,)


def test_another_geodesic_spacing_is_refused_naming_both_values(run):
    agent = load_policy(run).model
    agent.geodesic = True  # as an agent trained with the geodesic modality at the default spacing
    agent.physics = dataclasses.replace(agent.physics, geodesic_spacing=0.1)
    env = CrowdNavEnv("open_space", modalities=["humans", "goal", "velocity", "geodesic"], overrides={"humans.count": 3,
                      "sensors.geodesic.spacing": 0.2})
    with pytest.raises(SensorMismatchError, match=r"^sensors.geodesic.spacing: this SARL agent was trained with 0.1 m, the world "
                                                  r"gives 0.2 m; evaluate it with sensors.geodesic.spacing=0.1$"):
        agent.check_world(env.observation_space, env.scenario)
