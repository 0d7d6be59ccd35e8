"""A resumed run is the run it continues: same episodes and same final weights as if it had never
stopped, whenever it stopped; one writer per run folder; pool workers die with their sweep."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from crowdnav.agents import train
from crowdnav.agents.runs.folder import RunBusyError, writing

from tests.agents.agents_tiny import tiny_config


class Stopped(Exception):
    """Stands for a kill right after a checkpoint (the state a SIGKILL there leaves on disk)."""


def _episodes(result) -> list[tuple]:
    return [(r.seed, r.outcome, r.reward, r.length, r.timesteps) for r in result.records]


def _weights(result) -> list[bytes]:
    return [p.detach().numpy().tobytes() for p in result.model.policy.parameters()]


@pytest.mark.parametrize(("algo", "algo_kwargs"), [
    ("sac", {"train_freq": 4, "gradient_steps": -1}),  # the checkpoint falls 0-3 steps into the next episode
    ("td3", {"train_freq": 3}),
    ("a2c", {"n_steps": 16}),  # the checkpoint keeps the collected rollout and the env mid-episode
    ("ppo", {"n_steps": 32, "n_epochs": 1}),
])
def test_a_run_stopped_after_a_checkpoint_and_resumed_trains_bit_for_bit_like_the_uninterrupted_run(tmp_path, algo, algo_kwargs):
    whole = train(tiny_config(tmp_path / "whole", algo=algo, episodes=6, algo_kwargs=algo_kwargs))
    config = tiny_config(tmp_path / "stopped", algo=algo, episodes=6, algo_kwargs=algo_kwargs)

    def stop(episodes):
        if episodes == 2:
            raise Stopped

    with pytest.raises(Stopped):
        train(config, on_checkpoint=stop)
    resumed = train(config, resume=True)
    assert _episodes(resumed) == _episodes(whole)[2:]
    assert _weights(resumed) == _weights(whole)


def test_pretraining_the_encoder_again_with_its_seed_gives_the_same_weights(tmp_path):
    # a kill during pre-training restarts it; the restart must give the encoder the runs were promised
    import torch
    from crowdnav.agents import pretrain_encoder

    grids = (np.random.default_rng(0).random((64, 1, 30, 30)) < 0.1).astype(np.uint8)
    runs = [pretrain_encoder(grids, tmp_path / name, channels=[4], kernels=[5], strides=[5], latent=4, epochs=2, seed=3)
            for name in ("first", "again")]
    assert runs[0].train_loss == runs[1].train_loss and runs[0].val_loss == runs[1].val_loss
    saved = [torch.load(run.encoder_path, weights_only=True)["encoder"] for run in runs]
    assert all(torch.equal(saved[0][key], saved[1][key]) for key in saved[0])


def test_a_second_writer_of_a_run_folder_is_refused_with_the_holders_pid_and_the_lock_is_released_after(tmp_path):
    with writing(tmp_path):
        with pytest.raises(RunBusyError, match=rf"is being written by another process \(PID {os.getpid()}\)"):
            with writing(tmp_path):
                pass
    with writing(tmp_path):  # free again
        pass


def test_training_a_run_folder_another_process_is_writing_fails_at_once(tmp_path):
    with writing(tmp_path / "run"), pytest.raises(RunBusyError):
        train(tiny_config(tmp_path / "run", episodes=2))


def _pdeathsig() -> int:
    import ctypes

    value = ctypes.c_int()
    ctypes.CDLL(None).prctl(2, ctypes.byref(value))  # PR_GET_PDEATHSIG
    return value.value


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_local_pool_workers_are_killed_by_the_kernel_when_the_sweep_process_dies():
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from crowdnav.evaluation.executors import _init_worker

    with ProcessPoolExecutor(1, mp_context=get_context("spawn"), initializer=_init_worker, initargs=(os.getpid(),)) as pool:
        assert pool.submit(_pdeathsig).result() == signal.SIGKILL


EXPERIMENT = """\
name: killed
description: resume check
protocol: {train_episodes: 30, eval_every: 6, test_episodes: 3, seeds: 1, window: 3, final_evaluations: 1}
defaults:
  scenario: open_space
  algo: sac
  overrides: {max_steps: 40, humans.count: 3}
  sensors: {lidar: {beams: 16}}
  net_arch: [16]
  batch_size: 16
  buffer_size: 2000
  learning_starts: 30
  algo_kwargs: {train_freq: 4}
  extractor: {lidar_hidden: [16], rbf_centres: 4, lowdim_hidden: [8]}
configurations:
  - {name: lidar, label: LIDAR, train: {modalities: [lidar, goal]}}
"""
_TIME_COLUMNS = {"seconds", "wall_time_s", "train_seconds", "eval_seconds"}


def _benchmark(folder: Path, out: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "crowdnav", "benchmark", "experiment.yaml", "--workers", "1", "--no-progress",
                             "--no-video", "--out", out], cwd=folder, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _table(path: Path) -> pd.DataFrame:
    table = pd.read_csv(path)
    return table.drop(columns=[c for c in table.columns if c in _TIME_COLUMNS or c.endswith("_seconds")])


@pytest.mark.slow
def test_a_sweep_sigkilled_at_ten_moments_ends_with_the_results_of_one_never_killed(tmp_path):
    (tmp_path / "experiment.yaml").write_text(EXPERIMENT, encoding="utf-8")
    assert _benchmark(tmp_path, "whole").wait(timeout=300) == 0
    log = tmp_path / "killed" / "killed" / "lidar" / "seed_0" / "train" / "episodes.csv"
    rng = np.random.default_rng(21)
    moments = sorted(rng.choice(np.arange(1, 30), size=10, replace=False))
    for episodes, delay in zip(moments, rng.uniform(0.0, 0.05, size=10), strict=True):
        child = _benchmark(tmp_path, "killed")
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and (not log.exists() or len(log.read_text().splitlines()) <= episodes):
            time.sleep(0.005)
        time.sleep(delay)  # a few milliseconds on: some kills land in a checkpoint or results write
        os.kill(child.pid, signal.SIGKILL)  # the sweep's process only: its worker must not live on
        child.wait()
    assert _benchmark(tmp_path, "killed").wait(timeout=300) == 0
    whole, killed = tmp_path / "whole" / "killed", tmp_path / "killed" / "killed"
    files = sorted(path.relative_to(whole) for path in whole.rglob("*.csv"))
    assert len(files) >= 8
    for name in files:
        pd.testing.assert_frame_equal(_table(whole / name), _table(killed / name), obj=str(name))
    assert np.array_equal(pd.read_csv(log)["episode"], np.arange(30))
    assert (log.parent / "episodes.csv.discarded").is_file()  # the kills did interrupt training
