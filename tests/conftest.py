"""Fixtures shared by several test files; helpers that are plain functions live in tests/agents/agents_tiny.py
and tests/evaluation/evaluation_tiny.py (imported as ``tests.agents.agents_tiny``, ``tests.evaluation.evaluation_tiny``).

Heavy imports (torch) happen inside the fixtures, so the core tests run without the training extras.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import settings

from tests.agents.agents_tiny import SMALL_LEOG, TINY_EXTRACTOR

# CI (.ci/run sets CI=true) replays the same fuzzing examples every run, so a red build names a change, not a draw;
# elsewhere every run draws new examples (and `-m slow` draws thousands), which is where the fuzzing finds bugs.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "default")


@pytest.fixture(scope="session")
def encoder_file(tmp_path_factory) -> Path:
    """A LEOG encoder pre-trained for one epoch with the tiny architecture on 30x30 grids, made once per session (read only)."""
    from crowdnav.agents import collect_grids, pretrain_encoder

    grids = collect_grids("room_furniture", 64, seed=0, sensors=SMALL_LEOG)
    result = pretrain_encoder(grids, tmp_path_factory.mktemp("encoder"), channels=TINY_EXTRACTOR["leog_channels"],
                              kernels=TINY_EXTRACTOR["leog_kernels"], strides=TINY_EXTRACTOR["leog_strides"],
                              latent=TINY_EXTRACTOR["leog_latent"], epochs=1)
    return result.encoder_path


@pytest.fixture
def one_torch_thread() -> Iterator[None]:
    """torch on one thread for the test: networks this small gain nothing from threads, and on a busy
    2-core machine torch's spinning worker threads made such runs 10-25x slower (5 s -> 140 s)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def importable_module(tmp_path, monkeypatch) -> Iterator[Callable[[str, str], str]]:
    """``write(name, source) -> name``: a Python module in ``tmp_path``, importable by ``name`` for this test only."""
    written: list[str] = []
    monkeypatch.syspath_prepend(str(tmp_path))

    def write(name: str, source: str) -> str:
        (tmp_path / f"{name}.py").write_text(source)
        written.append(name)
        return name

    yield write
    for name in written:
        sys.modules.pop(name, None)
