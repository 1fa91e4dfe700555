"""docs/tutorial.ipynb: stored without outputs and well formed (fast), and executed from the first
cell to the last on tiny budgets with the native engine (slow), so that it cannot rot."""

import ast
import os
import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[1] / "docs" / "tutorial.ipynb"
TINY = "DPC_TUTORIAL_TINY"  # the notebook's switch to smoke-test budgets
# XLA's backend optimisation off in the kernel (as tests/helpers.FAST_COMPILE): a tiny run is
# compile-bound. dpc_mjx leaves a set XLA_FLAGS as it is.
FAST_XLA = "--xla_backend_optimization_level=0 --xla_llvm_disable_expensive_passes=true"
CELL_TIMEOUT_S = 1800  # one cell compiles up to three env programs on a loaded 2-core CPU


def _read():
    return nbformat.read(NOTEBOOK, as_version=nbformat.NO_CONVERT)


def test_the_tutorial_is_stored_without_outputs_and_parses():
    nb = _read()
    nbformat.validate(nb)
    assert nb.nbformat == 4 and nb.metadata.kernelspec.name == "python3"
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert len(code) >= 6, "the tutorial lost its sections"
    for i, cell in enumerate(code):
        assert cell.outputs == [] and cell.execution_count is None, (
            f"code cell {i} of {NOTEBOOK.name} is stored with outputs: clear them "
            "(jupyter nbconvert --clear-output --inplace docs/tutorial.ipynb)"
        )
        ast.parse(cell.source, filename=f"{NOTEBOOK.name}, code cell {i}")  # no magics, valid
    assert any(TINY in c.source for c in code), f"the notebook no longer reads {TINY}"


def _text(nb) -> str:
    """Every stream and text/plain output of the executed notebook, joined."""
    parts = []
    for cell in nb.cells:
        for out in cell.get("outputs", []):
            parts.append(out.get("text", "") or out.get("data", {}).get("text/plain", ""))
    return "\n".join(parts)


@pytest.mark.slow
def test_the_tutorial_runs_from_top_to_bottom_on_tiny_budgets(monkeypatch, tmp_path):
    monkeypatch.setenv(TINY, "1")  # the kernel inherits this process's environment
    monkeypatch.setenv("XLA_FLAGS", f"{os.environ.get('XLA_FLAGS', '')} {FAST_XLA}".strip())
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = _read()
    client = NotebookClient(
        nb,
        timeout=CELL_TIMEOUT_S,
        kernel_name="python3",
        resources={"metadata": {"path": tmp_path}},
    )
    client.execute()  # raises CellExecutionError, with the cell and its traceback, on any error
    text = _text(nb)
    assert "TINY=True" in text
    for arm, controller in (("regular", "mbc"), ("regular", "observer"), ("regular", "dpc")):
        assert f"| {arm} | {controller} |" in text
    assert "| my_arm | dpc |" in text and "'my_arm'" in text  # transferred, exported, evaluated
    (diff,) = re.findall(r"numpy vs JAX action: max \|difference\| (\S+)", text)
    assert float(diff) < 1e-4
    assert "nan" not in text.split("R^2 per component")[1].split("\n")[0]
