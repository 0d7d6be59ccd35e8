"""notebooks/plot_results.ipynb executes on a results folder made by the tests."""

from __future__ import annotations

import shutil

import nbformat
from crowdnav.evaluation.baselines import EXPERIMENT_BASELINES
from nbclient import NotebookClient

from tests.evaluation.evaluation_tiny import tiny_results
from tests.paths import REPO

NOTEBOOK = REPO / "notebooks" / "plot_results.ipynb"


def test_plot_results_notebook_draws_the_curves_and_the_leaderboard(tmp_path_factory, monkeypatch):
    results = tiny_results(tmp_path_factory)
    monkeypatch.setenv("CROWDNAV_RESULTS", str(results))  # the kernel inherits the environment
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(notebook, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOK.parent.parent)}}).execute()
    outputs = [output for cell in notebook.cells if cell.cell_type == "code" for output in cell.outputs]
    assert not [output for output in outputs if output.output_type == "error"]
    assert any("image/png" in output.get("data", {}) for output in outputs)
    tables = [output["data"]["text/markdown"] for output in outputs if "text/markdown" in output.get("data", {})]
    assert tables and "| LIDAR | 2 |" in tables[0] and "| closest obstacle | 2 |" in tables[0]


def test_the_notebook_started_in_notebooks_finds_results_beside_it_without_configuration(tmp_path_factory, monkeypatch, tmp_path):
    """Jupyter's working folder is notebooks/: the default results/default is read from the repository root."""
    shutil.copytree(tiny_results(tmp_path_factory), tmp_path / "results" / "default")
    (tmp_path / "notebooks").mkdir()
    monkeypatch.delenv("CROWDNAV_RESULTS", raising=False)
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    notebook.cells = notebook.cells[:2]  # the loading cell is what this checks
    NotebookClient(notebook, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(tmp_path / "notebooks")}}).execute()
    printed = "".join(output.get("text", "") for output in notebook.cells[1].outputs)
    assert printed.startswith(f"{4 + len(EXPERIMENT_BASELINES)} runs") and printed.rstrip().endswith(str(tmp_path / "results" / "default"))
