"""Parallel scene loading with thin-film plugins (issue: a use-after-free of
Mitsuba's FileResolver).

Before the fix the plugin constructors built helper spectra with
``mi.load_dict``, which installs a copy of the global FileResolver and frees it
on return; C++ plugins resolving file names on other loader threads read the
freed copy. The child script (``_parallel_load_child.py``) widens that window;
with the old constructors about one fresh process in four failed
(``std::bad_alloc``, ``basic_string::_M_create`` or SIGSEGV; measured 13-25 % over
16-40 processes), so 24 processes all passing had a chance of ~0.1 % (0.75^24)
before the fix. After it, none may fail.
"""
from __future__ import annotations

import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
PROCESSES = 24


def _load_once(_):
    out = subprocess.run([sys.executable, str(HERE / "_parallel_load_child.py"), str(ROOT)],
                         capture_output=True, text=True, timeout=300)
    return out.returncode, out.stdout.strip()[-400:], out.stderr.strip()[-400:]


def test_parallel_scene_loading_with_every_plugin_and_bitmaps_never_fails():
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(_load_once, range(PROCESSES)))
    failed = [r for r in results if r[0] != 0 or not r[1].startswith("ok")]
    assert not failed, f"{len(failed)} of {PROCESSES} parallel loads failed: {failed[:3]}"
    # every plugin type was built in the parallel load
    kinds = set(results[0][1].split()[1:])
    assert {"ThinFilmConductor", "ThinFilmDielectric", "ThinFilmDiffuse",
            "ThinFilmRoughConductor", "ThinFilmRoughDielectric"} <= kinds


def test_library_and_plugins_never_call_load_dict():
    """The regression's root: no code that a plugin constructor can reach calls
    ``mi.load_dict`` (or ``load_string``/``load_file``, which swap the resolver the
    same way). Checked on the syntax tree, so docstrings and comments do not count."""
    import ast

    offenders = []
    for folder in ("thinfilm_mi", "plugins"):
        for path in sorted((ROOT / folder).glob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                        and node.func.attr in ("load_dict", "load_string", "load_file")):
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not offenders, offenders
