"""The notebooks run; the README's set-up commands are Makefile targets. (The plugins'
parameter tables are the documentation site's, generated from the doc blocks: tests/cross/test_docs.py
and the `make docs` check of tests/cross/test_readme_commands.py. The notebooks are stored with the
outputs the site renders, made by scripts/store_notebook_outputs.py; that they are the outputs
of the code cells as they stand is checked by tests/cross/test_notebook_outputs.py.)

Every ``notebooks/*.ipynb`` is executed with nbclient in a kernel running this
interpreter (``sys.executable``), with ``THINFILM_NB_QUICK=1`` so that each one
uses tiny images, few samples and coarse grids. The notebooks check their own
results with ``assert`` (Fresnel closed forms, energy balance, colour white
point, recovered thickness), so a wrong number fails the test, not only an
exception.
"""
from __future__ import annotations

import json
import re
import sys

import pytest

from tests.support import ROOT

REPO = ROOT
NOTEBOOKS = sorted((REPO / "notebooks").glob("*.ipynb"))
IDS = [p.stem for p in NOTEBOOKS]


@pytest.fixture
def kernel_name(tmp_path, monkeypatch):
    """A kernel spec that starts ipykernel with this very interpreter."""
    pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    spec = tmp_path / "jupyter" / "kernels" / "thinfilm-test"
    spec.mkdir(parents=True)
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "thinfilm-mi tests", "language": "python"}))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path / "jupyter"))
    monkeypatch.setenv("THINFILM_NB_QUICK", "1")
    return "thinfilm-test"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=IDS)
def test_notebook_executes(path, kernel_name):
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(str(path), as_version=4)
    client = NotebookClient(nb, timeout=600, kernel_name=kernel_name,
                            resources={"metadata": {"path": str(path.parent)}})
    client.execute()  # raises CellExecutionError, with the cell and traceback, on failure
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(c.execution_count is not None for c in code)
    text = "".join(o.get("text", "") for c in code for o in c.outputs if o.output_type == "stream")
    assert "quick mode" in text, f"{path.name} did not report THINFILM_NB_QUICK"
    figures = sum("image/png" in o.get("data", {}) for c in code for o in c.outputs)
    assert figures > 0, f"{path.name} drew no figure"


def test_readme_setup_commands_are_makefile_targets():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    targets = set(re.findall(r"^([A-Za-z_][\w-]*):", (REPO / "Makefile").read_text(), re.M))
    for target in ("demo", "test"):
        assert f"make {target}" in readme
        assert target in targets
