"""The Ray executor on a real Ray head started on 127.0.0.1: same results as the local executor, worker deaths retried,
bugs reported, finished runs skipped; and a clear error when Ray is not installed."""

from __future__ import annotations

import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pytest
from crowdnav.evaluation.baselines import EXPERIMENT_BASELINES
from crowdnav.evaluation.benchmark import run_experiment
from crowdnav.evaluation.executors import ExecutorError, make_executor
from crowdnav.evaluation.experiment import experiment_from_mapping
from crowdnav.evaluation.storage import ResultsError
from crowdnav.evaluation.transfer import claim_storage, node_local_root, pack_folder, unpack_folder, work_folder

from crowdnav.cli import main
from crowdnav.scenario.library import library_dir
from tests.evaluation.evaluation_tiny import tiny_experiment_document, tiny_frozen_encoder_document, write_tiny_experiment
from tests.evaluation.test_evaluation_resume import check_complete

WALL_TIME_COLUMNS = ("seconds", "wall_time_s")


@dataclass
class Cluster:
    address: str
    session: int
    """Session id of every process of this cluster (ray start ran as a session leader), to find and stop exactly them."""


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _session_processes(session: int) -> list[int]:
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if os.getsid(int(entry.name)) == session:
                    pids.append(int(entry.name))
            except OSError:  # gone meanwhile
                pass
    return pids


def _stop_session(session: int) -> None:
    """Stop this cluster's processes only (``ray stop`` would stop every Ray on the machine)."""
    for sig, wait in ((signal.SIGTERM, 3.0), (signal.SIGKILL, 5.0)):  # the GCS server takes ~15 s to honour SIGTERM
        for pid in _session_processes(session):
            try:
                os.kill(pid, sig)
            except OSError:
                pass
        deadline = time.monotonic() + wait
        while _session_processes(session) and time.monotonic() < deadline:
            time.sleep(0.1)
        if not _session_processes(session):
            return


@pytest.fixture(scope="module")
def cluster():
    # Hermetic token authentication, as docs/cluster.md recommends: the head, its workers and this driver share a token
    # given in the environment, whatever ~/.ray/auth_token holds (Ray 2.5x turns authentication on when that file exists).
    with pytest.MonkeyPatch.context() as environment:
        environment.setenv("RAY_AUTH_MODE", "token")
        environment.setenv("RAY_AUTH_TOKEN", secrets.token_hex(32))
        environment.delenv("RAY_AUTH_TOKEN_PATH", raising=False)
        environment.delenv("RAY_ADDRESS", raising=False)
        pytest.importorskip("ray")
        if not Path("/proc").is_dir():
            pytest.skip("the Ray cluster tests find and stop the cluster's processes through /proc")
        ray_cli = Path(sys.executable).with_name("ray")
        ray_cli = str(ray_cli) if ray_cli.is_file() else shutil.which("ray")
        temp = tempfile.mkdtemp(prefix="cnray-")  # short: Ray's socket paths must stay under ~107 characters
        port = _free_port()
        head = subprocess.Popen([ray_cli, "start", "--head", "--node-ip-address", "127.0.0.1", "--port", str(port), "--num-cpus", "2",
                                 "--include-dashboard=false", "--disable-usage-stats", "--temp-dir", temp],
                                start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            output, _ = head.communicate(timeout=120)
            assert head.returncode == 0, output
            yield Cluster(f"127.0.0.1:{port}", head.pid)
        finally:
            head.kill()
            _stop_session(head.pid)
            shutil.rmtree(temp, ignore_errors=True)


def _tables(folder: Path) -> dict[str, pd.DataFrame]:
    """Every CSV below ``folder`` without its wall-time columns, by relative path."""
    tables = {}
    for path in sorted(folder.rglob("*.csv")):
        frame = pd.read_csv(path, keep_default_na=False)
        tables[str(path.relative_to(folder))] = frame.drop(columns=[c for c in WALL_TIME_COLUMNS if c in frame])
    return tables


def _meta(path: Path) -> dict:
    """meta.json without what depends on the clock or on the folder the run was done in."""
    meta = json.loads(path.read_text())
    del meta["wall_time_s"]
    meta.get("config", {}).pop("out", None)  # scripted baselines have no training config
    return meta


# First among the tests in this file: Ray reads its authentication mode once per process, so the cluster's token
# mode must reach Ray before a test below initialises it without a cluster (the unreachable-address case).
@pytest.mark.slow  # 20-28 s with the cluster's start and stop; the default suite checks the executor's errors without a cluster
def test_a_task_learns_within_seconds_that_its_driver_is_gone(cluster, tmp_path):
    """The board actor dies with the driver; the task's reporter notices it and stops the task (not Ray's ~90 s)."""
    import ray
    from crowdnav.evaluation.protocol import Protocol
    from crowdnav.evaluation.ray_executor import _Board, _ProgressReporter

    handler = signal.getsignal(signal.SIGTERM)
    ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False)
    try:
        board = _Board.options(num_cpus=0).remote()
        lost = threading.Event()
        protocol = Protocol(train_episodes=1, eval_every=1, test_episodes=1, seeds=1)
        reporter = _ProgressReporter(board, "run", tmp_path, protocol, on_driver_lost=lost.set)
        assert reporter.driver_alive() and not lost.wait(timeout=3)
        ray.kill(board)
        assert lost.wait(timeout=15)
        reporter.stop()
    finally:
        ray.shutdown()
        signal.signal(signal.SIGTERM, handler)  # ray.init installs its own and leaves it behind


@pytest.mark.slow  # 20-26 s (two benchmarks of a tiny experiment, one through the cluster); the cluster cases all run with -m slow
def test_ray_on_a_running_cluster_gives_row_for_row_the_local_executors_results(cluster, tmp_path, capsys):
    experiment = write_tiny_experiment(tmp_path / "tiny.yaml")
    common = [str(experiment), "--no-video", "--no-progress"]
    assert main(["benchmark", *common, "--executor", "local", "--workers", "2", "--out", str(tmp_path / "local")]) == 0
    storage = tmp_path / "storage"  # not the results folder: every run comes back to the driver as bytes
    assert main(["benchmark", *common, "--executor", "ray", "--address", cluster.address, "--storage", str(storage),
                 "--out", str(tmp_path / "ray")]) == 0
    out = capsys.readouterr().out
    assert "4 runs finished (0 already done), 0 retried, 0 failed" in out
    assert "finished: closest/seed_0, closest/seed_1, lidar/seed_0, lidar/seed_1" in out

    local, ray = tmp_path / "local" / "tiny", tmp_path / "ray" / "tiny"
    files = sorted(str(path.relative_to(local)) for path in local.rglob("*") if path.is_file() and not path.name.startswith("replay_buffer."))
    assert files == sorted(str(path.relative_to(ray)) for path in ray.rglob("*") if path.is_file())  # the same layout, less the
    # replay buffers (resume state, not transferred)
    local_tables, ray_tables = _tables(local), _tables(ray)
    # per run: 2 evaluations, test and training episodes, agents' log; each baseline's test episodes; leaderboard, evaluation rates
    assert len(local_tables) == 4 * 5 + len(EXPERIMENT_BASELINES) + 2
    for name, frame in local_tables.items():
        pd.testing.assert_frame_equal(ray_tables[name], frame, obj=name)
    for meta in local.rglob("meta.json"):
        assert _meta(ray / meta.relative_to(local)) == _meta(meta)
    assert [path.name for path in storage.iterdir()] == [".crowdnav-storage"]  # working copies removed once in the results

    stamps = {path: path.stat().st_mtime_ns for path in ray.rglob("*") if path.is_file() and "seed_" in str(path)}
    assert main(["benchmark", *common, "--executor", "ray", "--address", cluster.address, "--storage", str(storage),
                 "--out", str(tmp_path / "ray")]) == 0
    assert "4 runs finished (4 already done), 0 retried, 0 failed" in capsys.readouterr().out
    assert {path: path.stat().st_mtime_ns for path in stamps} == stamps  # finished runs skipped, never rewritten


@pytest.mark.slow  # 6-19 s on a cluster
def test_pretrained_encoder_reaches_runs_that_work_outside_the_results_folder(cluster, tmp_path):
    document = tiny_frozen_encoder_document()
    experiment = experiment_from_mapping(document)
    storage = tmp_path / "storage"
    report = run_experiment(experiment, tmp_path / "results", progress=False, video=False, log=lambda line: None,
                            executor=make_executor("ray", address=cluster.address, storage=storage))
    assert not report.failures and [s["status"] for s in report.summaries] == ["done"]
    meta = json.loads((tmp_path / "results" / "tiny" / "frozen" / "seed_0" / "meta.json").read_text())
    assert meta["config"]["encoder"]["weights"] == str(storage / "tiny" / "encoder" / "encoder.pt")  # the copy the task was given
    assert (tmp_path / "results" / "tiny" / "frozen" / "seed_0" / "train" / "checkpoint" / "encoder.pt").is_file()


def _task_pid(cluster: Cluster, run: str) -> int | None:
    """The worker process of this cluster running the Ray task of ``run`` (its process title is ``ray::crowdnav RUN``)."""
    for pid in _session_processes(cluster.session):
        try:
            title = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if title.startswith(f"ray::crowdnav {run}"):
            return pid
    return None


def _kill_in_the_middle_of_training(cluster: Cluster, run_dir: Path, killed: list[int]) -> threading.Thread:
    """A thread that SIGKILLs the worker of the run in ``run_dir`` once it has logged 3 training episodes (of 12)."""
    log = run_dir / "train" / "episodes.csv"
    run = f"{run_dir.parent.name}/{run_dir.name}"

    def kill() -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            # episode 2 is logged: the checkpoint holds 2 episodes, the next one is due after episode 4
            if log.is_file() and len(log.read_text().splitlines()) >= 4 and (pid := _task_pid(cluster, run)):
                os.kill(pid, signal.SIGKILL)
                killed.append(len(log.read_text().splitlines()) - 1)
                return
            time.sleep(0.01)

    thread = threading.Thread(target=kill, daemon=True)
    thread.start()
    return thread


@pytest.mark.slow  # 6-19 s on a cluster
def test_killed_worker_is_retried_and_its_run_resumes_from_its_checkpoint(cluster, tmp_path):
    experiment = experiment_from_mapping(tiny_experiment_document(seeds=1, train_episodes=12, eval_every=2))
    killed = []  # default storage: the results folder itself, where the killer watches the run
    killer = _kill_in_the_middle_of_training(cluster, tmp_path / "tiny" / "lidar" / "seed_0", killed)
    report = run_experiment(experiment, tmp_path, executor=make_executor("ray", address=cluster.address, retries=2),
                            progress=False, video=False, log=lambda line: None)
    killer.join()
    assert killed and killed[0] < 12, "the worker was not killed in the middle of the run"
    assert not report.failures
    assert sorted((s["configuration"], s["status"], s["attempts"]) for s in report.summaries) == [("closest", "done", 1),
                                                                                                  ("lidar", "done", 2)]
    assert "retried: lidar/seed_0 (2 attempts)" in report.summary_lines()
    for unit, out_dir in experiment.units(tmp_path / "tiny"):
        tests, training = check_complete(out_dir, unit.to_dict())  # every row exactly once
    meta = json.loads((tmp_path / "tiny" / "lidar" / "seed_0" / "meta.json").read_text())
    assert meta["resumed"]  # the retry went on from the checkpoint instead of starting over


@pytest.mark.slow  # 6-19 s on a cluster
def test_worker_killed_more_often_than_the_retries_allow_is_a_failed_run(cluster, tmp_path):
    document = tiny_experiment_document(seeds=1, train_episodes=12, eval_every=2)
    document["configurations"] = document["configurations"][:1]
    experiment = experiment_from_mapping(document)
    killed = []
    killer = _kill_in_the_middle_of_training(cluster, tmp_path / "tiny" / "lidar" / "seed_0", killed)
    report = run_experiment(experiment, tmp_path, executor=make_executor("ray", address=cluster.address, retries=0),
                            progress=False, video=False, log=lambda line: None)
    killer.join()
    assert killed and not report.summaries
    [failure] = report.failures
    assert failure["attempts"] == 1 and failure["error"].startswith("worker died (1 attempt(s)): ")
    assert Path(failure["log"]).read_text().strip()
    assert not (tmp_path / "tiny" / "lidar" / "seed_0" / "meta.json").exists()


@pytest.mark.slow  # 6-19 s on a cluster
def test_run_that_raises_is_reported_with_its_traceback_and_the_others_finish(cluster, tmp_path):
    scenario = tmp_path / "doomed.yaml"
    shutil.copy(library_dir() / "open_space.yaml", scenario)
    document = tiny_experiment_document(seeds=1)
    document["configurations"][1]["train"]["scenario"] = str(scenario)
    experiment = experiment_from_mapping(document)  # checked while the scenario file exists
    scenario.unlink()  # ... so the run fails inside its Ray task
    report = run_experiment(experiment, tmp_path / "results", progress=False, video=False, log=lambda line: None,
                            executor=make_executor("ray", address=cluster.address, storage=tmp_path / "storage"))
    assert [(s["configuration"], s["status"]) for s in report.summaries] == [("lidar", "done")]
    [failure] = report.failures
    assert (failure["configuration"], failure["attempts"]) == ("closest", 1)  # a bug is not retried
    log = tmp_path / "results" / "tiny" / "closest" / "seed_0" / "error.log"  # the traceback comes back to the results
    assert failure["log"] == str(log) and "doomed.yaml" in failure["error"]
    assert log.read_text().startswith("Traceback (most recent call last)") and "doomed.yaml" in log.read_text()
    assert report.summary_lines()[0].startswith("1 runs finished (0 already done), 0 retried, 1 failed, in ")
    assert any(line.startswith("failed: closest/seed_0 (") for line in report.summary_lines())


def test_unreachable_cluster_address_is_a_one_line_error(tmp_path, capsys):
    pytest.importorskip("ray")
    address = f"127.0.0.1:{_free_port()}"  # nothing listens there
    code = main(["benchmark", str(write_tiny_experiment(tmp_path / "tiny.yaml")), "--executor", "ray", "--address", address,
                 "--out", str(tmp_path), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1 and err.startswith(f"crowdnav: error: cannot reach the Ray head at {address} (") and err.count("\n") == 1


def test_without_ray_installed_the_ray_executor_is_a_one_line_error(monkeypatch, tmp_path, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray now fails as if it were not installed
    monkeypatch.delitem(sys.modules, "crowdnav.evaluation.ray_executor", raising=False)
    with pytest.raises(ExecutorError, match=r'pip install -e "\.\[ray\]" in crowdnav\'s clone$'):
        make_executor("ray")
    code = main(["benchmark", str(write_tiny_experiment(tmp_path / "tiny.yaml")), "--executor", "ray", "--out", str(tmp_path)])
    out, err = capsys.readouterr()
    assert code == 1 and out == ""
    assert err == "crowdnav: error: the ray executor needs Ray, which is not installed: pip install -e \".[ray]\" in crowdnav's clone\n"


def test_core_benchmark_modules_never_import_ray():
    code = ("import sys, crowdnav.evaluation.benchmark, crowdnav.evaluation.executors, crowdnav.cli\n"
            "from crowdnav.evaluation.executors import make_executor\n"
            "make_executor('local', workers=2)\n"
            "assert 'ray' not in sys.modules, 'ray was imported'\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("option", [["--address", "127.0.0.1:6379"], ["--storage", "x"], ["--gpus-per-run", "1"], ["--retries", "1"]])
def test_ray_options_without_the_ray_executor_are_refused(option, capsys):
    code = main(["benchmark", *option])
    assert code == 1
    assert capsys.readouterr().err == f"crowdnav: error: {option[0]}: option(s) of --executor ray, not of --executor local\n"


def test_task_works_in_the_storage_only_when_it_reads_the_drivers_storage_id_there(tmp_path):
    storage_id = claim_storage(tmp_path / "storage")
    assert claim_storage(tmp_path / "storage") == storage_id  # kept across sweeps
    relative = Path("tiny", "lidar", "seed_0")
    assert work_folder(tmp_path / "storage", storage_id, relative) == (tmp_path / "storage" / relative, True)
    # a node without the shared file system: no id file there, or another storage's id at that path
    assert work_folder(tmp_path / "elsewhere", storage_id, relative) == (node_local_root(storage_id) / relative, False)
    other = claim_storage(tmp_path / "other")
    assert work_folder(tmp_path / "other", storage_id, relative) == (node_local_root(storage_id) / relative, False)
    assert other != storage_id


def _run_folder(folder: Path, **files: str) -> Path:
    for name, text in files.items():
        (folder / name.replace("__", "/")).parent.mkdir(parents=True, exist_ok=True)
        (folder / name.replace("__", "/")).write_text(text)
    return folder


def test_unpacked_run_replaces_a_partial_one_but_never_a_finished_one(tmp_path):
    work = _run_folder(tmp_path / "work", **{"meta.json": "{}", "train__checkpoint__model.zip": "model", "train__.log.csv.1.tmp": "x",
                                             "train__checkpoint.partial__model.zip": "half"})
    data = pack_folder(work)
    target = _run_folder(tmp_path / "results" / "seed_0", **{"spec.json": "partial", "error.log": "old failure"})
    assert unpack_folder(data, target, "meta.json")
    assert sorted(str(p.relative_to(target)) for p in target.rglob("*") if p.is_file()) == ["meta.json", "train/checkpoint/model.zip"]
    (target / "meta.json").write_text("finished")
    assert not unpack_folder(pack_folder(_run_folder(tmp_path / "again", **{"meta.json": "other"})), target, "meta.json")
    assert (target / "meta.json").read_text() == "finished"
    with pytest.raises(ResultsError, match="no meta.json"):
        unpack_folder(pack_folder(_run_folder(tmp_path / "broken", **{"spec.json": "x"})), tmp_path / "results" / "seed_1", "meta.json")
    assert sorted(path.name for path in (tmp_path / "results").iterdir()) == ["seed_0"]  # no staging folder left behind
