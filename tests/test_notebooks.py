"""Every notebook in notebooks/ runs top to bottom on the shipped data, in time.

`make test` checks that each one is stored without outputs, that its code parses and
that every name it imports from piecs_bayes exists (what a change of the API breaks);
the slow tier (`make test-all`) executes each end to end. Executed with nbclient in the `python3` kernel of this environment (checked:
the kernel's interpreter is the one running the tests), headless
(`MPLBACKEND=Agg`, `JAX_PLATFORMS=cpu`). Notebooks are stored without outputs.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import os
import sys
import time
from pathlib import Path

import pytest


def _nbformat():
    """nbformat, imported by the tests that read a notebook: not at collection, where
    every worker paid its 1.5 s (jsonschema's format checkers build a grammar)."""
    return pytest.importorskip("nbformat")


NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
ALL = sorted(NOTEBOOKS.glob("*.ipynb"))
LIMIT_S = 120.0  # each notebook, on the 2-core machine


def _execute(nb, cwd: Path, timeout: float):
    nbclient = pytest.importorskip("nbclient")
    os.environ["MPLBACKEND"] = "Agg"
    os.environ["JAX_PLATFORMS"] = "cpu"
    client = nbclient.NotebookClient(
        nb,
        timeout=int(timeout),
        kernel_name="python3",
        resources={"metadata": {"path": str(cwd)}},
    )
    return client.execute()


def test_the_six_notebooks_are_there():
    names = [p.name for p in ALL]
    assert len(names) == 6, names
    keys = (
        "quick_start", "robust_bayes_linearised", "capability", "nose_compensation", "feedback",
        "program_to_plan",
    )  # fmt: skip
    for key in keys:
        assert any(key in n for n in names), key


@pytest.mark.parametrize("path", ALL, ids=[p.stem for p in ALL])
def test_stored_without_outputs(path):
    nbformat = _nbformat()
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, path.name
    assert nb.metadata["kernelspec"]["name"] == "python3"


@pytest.mark.slow
def test_kernel_is_this_environment(tmp_path):
    nbformat = _nbformat()
    nb = nbformat.v4.new_notebook()
    nb.cells.append(nbformat.v4.new_code_cell("import sys; print(sys.prefix)"))
    _execute(nb, tmp_path, 60)
    out = nb.cells[0].outputs[0]["text"].strip()
    assert Path(out).resolve() == Path(sys.prefix).resolve()


@pytest.mark.parametrize("path", ALL, ids=[p.stem for p in ALL])
def test_code_parses_and_its_imports_exist(path):
    nbformat = _nbformat()
    nb = nbformat.read(path, as_version=4)
    imported = 0
    for i, cell in enumerate(c for c in nb.cells if c.cell_type == "code"):
        lines = [ln for ln in cell.source.splitlines() if not ln.lstrip().startswith(("%", "!"))]
        tree = ast.parse("\n".join(lines), f"{path.name}, code cell {i + 1}")
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("piecs_bayes"):
                module = importlib.import_module(node.module)
                for alias in node.names:
                    assert hasattr(module, alias.name) or importlib.util.find_spec(
                        f"{node.module}.{alias.name}"
                    ), f"{path.name}, code cell {i + 1}: {node.module} has no {alias.name}"
                    imported += 1
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.startswith("piecs_bayes"):
                        importlib.import_module(alias.name)
                        imported += 1
    assert imported >= 1, f"{path.name} imports nothing from piecs_bayes"


@pytest.mark.slow
@pytest.mark.parametrize("path", ALL, ids=[p.stem for p in ALL])
def test_notebook_runs_in_time(path):
    nbformat = _nbformat()
    nb = nbformat.read(path, as_version=4)
    t0 = time.perf_counter()
    _execute(nb, NOTEBOOKS, LIMIT_S + 60)  # nbclient's limit is per cell; ours is below
    wall = time.perf_counter() - t0
    errors = [
        o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"
    ]
    assert not errors
    figures = sum(
        "image/png" in o.get("data", {})
        for c in nb.cells
        if c.cell_type == "code"
        for o in c.outputs
    )
    assert figures >= 1, f"{path.name}: no figure was drawn"
    assert wall < LIMIT_S, f"{path.name} took {wall:.0f} s (limit {LIMIT_S:.0f} s)"
