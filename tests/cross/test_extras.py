"""The optional dependencies (issue 31): a plain ``pip install thinfilm-mi`` renders.

Dask ``distributed`` is the ``[sweep]`` extra, matplotlib the ``[plot]`` extra
(and part of ``[sweep]``, for the contact sheet). Each check runs in a fresh
Python process where an import hook stands for the missing packages: it refuses
``dask``, ``distributed`` and/or ``matplotlib`` and records every attempt to
import them. Rendering scenes/demo.xml must not even try; the commands that do
need them must say, in one line and with exit status 2, which extra to install.
"""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.support import ROOT

REPO = ROOT
DEMO = REPO / "scenes" / "demo.xml"

#: installs the import hook; ``BLOCKED`` and ``ATTEMPTS`` are then defined in the child
BLOCKER = textwrap.dedent("""
    import importlib.abc, json, sys

    BLOCKED = set(sys.argv[1].split(","))
    ATTEMPTS = []

    class Missing(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in BLOCKED:
                ATTEMPTS.append(name)
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
            return None

    assert not BLOCKED & {m.partition(".")[0] for m in sys.modules}
    sys.meta_path.insert(0, Missing())
""")


def _child(blocked: str, body: str, tmp_path: Path) -> dict:
    """Run ``body`` after the import hook in a new interpreter; it prints one JSON line last."""
    code = BLOCKER + textwrap.dedent(body)
    proc = subprocess.run([sys.executable, "-c", code, blocked, str(DEMO), str(tmp_path)],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_rendering_needs_neither_dask_nor_matplotlib(tmp_path):
    result = _child("dask,distributed,matplotlib", """
        import contextlib, io
        from pathlib import Path

        import thinfilm_mi
        from thinfilm_mi.batch.scene import render_file
        from thinfilm_mi.cli import render, tools

        demo, tmp = Path(sys.argv[2]), Path(sys.argv[3])
        res = render_file(demo, tmp / "demo.exr", spp=1, size=(8, 6))
        out = {"attempts_while_rendering": list(ATTEMPTS), "size": list(res.size),
               "png": res.png_path.is_file()}
        for name, main, argv in (
                ("sweep", render.render_main, ["sweep", str(demo), "-D", "sio2=200,400"]),
                ("plot", tools.main, ["spectrum", "--layers", "1.46 100", "--wl", "400:500:50",
                                      "--plot", str(tmp / "rt.png")])):
            err = io.StringIO()
            with contextlib.redirect_stderr(err):
                out[name] = [main(argv), err.getvalue()]
        try:
            from thinfilm_mi import sweep  # noqa: F401
        except ImportError as e:
            out["import_sweep"] = str(e)
        print(json.dumps(out))
    """, tmp_path)
    assert result["attempts_while_rendering"] == []  # not even tried
    assert result["size"] == [8, 6] and result["png"]  # the PNG preview needs no matplotlib
    for extra in ("sweep", "plot"):
        rc, err = result[extra]
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1, err
        assert "error:" in lines[0] and f"pip install 'thinfilm-mi[{extra}]'" in lines[0], err
    assert not (tmp_path / "rt.png").exists()
    assert "thinfilm-mi[sweep]" in result["import_sweep"]


def test_a_sweep_without_matplotlib_says_so_before_rendering(tmp_path):
    pytest.importorskip("distributed")
    result = _child("matplotlib", """
        from pathlib import Path

        from thinfilm_mi.errors import MissingExtra
        from thinfilm_mi.batch.sweeps import sweep

        demo, tmp = Path(sys.argv[2]), Path(sys.argv[3])
        try:
            sweep(demo, {"sio2": "200,400"}, out_dir=tmp / "sweep", workers=1)
        except MissingExtra as e:
            print(json.dumps({"error": str(e), "out": (tmp / "sweep").exists()}))
    """, tmp_path)
    assert "thinfilm-mi[plot]" in result["error"] and "--no-contact-sheet" in result["error"]
    assert not result["out"]  # nothing started
