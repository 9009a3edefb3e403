"""Execute notebooks and store their outputs in place, small, for the documentation site.

    python scripts/store_notebook_outputs.py notebooks/01_optics.ipynb [...] [--quick]

The site renders ``notebooks/*.ipynb`` from their stored outputs (myst-nb with
``nb_execution_mode = "off"``: ``make docs`` never runs them), so the outputs are made
here, once, and committed. Each notebook runs top to bottom in a fresh kernel of this
interpreter (in full mode, or with ``THINFILM_NB_QUICK=1`` when ``--quick`` is given),
from the ``notebooks/`` folder. Then:

* every PNG output is shrunk to at most :data:`MAX_WIDTH` pixels wide and stored with an
  adaptive palette of 256 colours (the figures are plots and small renders; a palette
  keeps a figure to tens of kB, so the repository does not grow by megabytes a run);
* the notebook's metadata records, under ``thinfilm``, the SHA-256 of its code cells'
  sources (:func:`sources_digest`) and the mode it ran in: ``tests/cross/test_notebook_outputs.py``
  fails when a code cell was edited after its outputs were stored, so the site never shows
  outputs of code that is no longer there.
"""
from __future__ import annotations

import argparse
import base64
import hashlib
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["MAX_WIDTH", "execute", "shrink_png", "sources_digest"]

#: the widest stored figure, in pixels (the site's content column is ~750 px wide)
MAX_WIDTH = 720


def sources_digest(nb: dict) -> str:
    """SHA-256 of the notebook's code cells' sources, in order (the outputs' provenance)."""
    sources = ["".join(c["source"]) if isinstance(c["source"], list) else c["source"]
               for c in nb["cells"] if c["cell_type"] == "code"]
    return hashlib.sha256(json.dumps(sources).encode("utf-8")).hexdigest()


def shrink_png(data: str) -> str:
    """A base64 PNG at most :data:`MAX_WIDTH` wide, with a 256-colour adaptive palette."""
    from PIL import Image

    image = Image.open(io.BytesIO(base64.b64decode(data)))
    if image.width > MAX_WIDTH:
        image = image.resize((MAX_WIDTH, round(image.height * MAX_WIDTH / image.width)), Image.LANCZOS)
    image = image.convert("RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    out = io.BytesIO()
    image.save(out, format="PNG", optimize=True)
    return base64.b64encode(out.getvalue()).decode("ascii")


def execute(path: Path, quick: bool, timeout: int = 3600) -> float:
    """Run ``path`` in a fresh kernel of this interpreter and store its outputs; seconds taken."""
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(str(path), as_version=4)
    with tempfile.TemporaryDirectory() as tmp:
        spec = Path(tmp) / "kernels" / "thinfilm-store"
        spec.mkdir(parents=True)
        (spec / "kernel.json").write_text(json.dumps({
            "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
            "display_name": "thinfilm-mi", "language": "python"}))
        os.environ["JUPYTER_PATH"] = tmp
        if quick:
            os.environ["THINFILM_NB_QUICK"] = "1"
        else:
            os.environ.pop("THINFILM_NB_QUICK", None)
        start = time.perf_counter()
        NotebookClient(nb, timeout=timeout, kernel_name="thinfilm-store",
                       resources={"metadata": {"path": str(path.parent)}}).execute()
        seconds = time.perf_counter() - start
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for output in cell.outputs:
            if "image/png" in output.get("data", {}):
                output["data"]["image/png"] = shrink_png(output["data"]["image/png"])
    nb.metadata["kernelspec"] = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
    nb.metadata["thinfilm"] = {"sources_sha256": sources_digest(nb), "mode": "quick" if quick else "full"}
    nbformat.write(nb, str(path))
    return seconds


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("notebooks", nargs="+", type=Path)
    parser.add_argument("--quick", action="store_true", help="run with THINFILM_NB_QUICK=1")
    args = parser.parse_args(argv)
    for path in args.notebooks:
        seconds = execute(path.resolve(), args.quick)
        print(f"{path}: executed in {seconds:.0f} s, {path.stat().st_size / 1024:.0f} kB stored", flush=True)


if __name__ == "__main__":
    main()
