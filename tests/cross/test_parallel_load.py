"""Parallel scene loading with thin-film plugins (issue: a use-after-free of
Mitsuba's FileResolver).

Before the fix the plugin constructors built helper spectra with
``mi.load_dict``, which installs a copy of the global FileResolver and frees it
on return; C++ plugins resolving file names on other loader threads read the
freed copy. The child script (``tests/support/parallel_load_child.py``) widens that window;
with the old constructors about one fresh process in four failed
(``std::bad_alloc``, ``basic_string::_M_create`` or SIGSEGV; measured 13-25 % over
16-40 processes), so 12 processes all passing had a chance of ~3 % (0.75^12)
before the fix. After it, none may fail. The cause itself (a constructor that calls
``mi.load_*``) is checked without chance by
:func:`test_no_plugin_constructor_swaps_the_file_resolver`, so the stress test need not
be long enough to find it alone.
"""
from __future__ import annotations

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from tests.support import ROOT

HERE = ROOT / "tests" / "support"
PROCESSES = 12


def _load_once(_, variant="llvm_ad_spectral"):
    out = subprocess.run([sys.executable, str(HERE / "parallel_load_child.py"), str(ROOT),
                          variant], capture_output=True, text=True, timeout=300)
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


def test_parallel_loading_builds_colour_tables_safely():
    """llvm_ad_rgb: every constructor builds colour tables (float64 kernel launches,
    the shared table cache) on Mitsuba's loader threads at once. 8 fresh processes
    (~1.3 s each) must all load."""
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(lambda i: _load_once(i, "llvm_ad_rgb"), range(8)))
    failed = [r for r in results if r[0] != 0 or not r[1].startswith("ok")]
    assert not failed, f"{len(failed)} of 8 parallel loads failed: {failed[:3]}"


def test_library_and_plugins_never_call_load_dict():
    """The regression's root: no code that a plugin constructor can reach calls
    ``mi.load_dict`` (or ``load_string``/``load_file``, which swap the resolver the
    same way). Checked on the syntax tree, so docstrings and comments do not count."""
    import ast

    offenders = []
    for path in sorted((ROOT / "thinfilm_mi").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                    and node.func.attr in ("load_dict", "load_string", "load_file")):
                offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not offenders, offenders


def test_no_plugin_constructor_swaps_the_file_resolver(monkeypatch):
    """Deterministic companion of the stress test (whose failure rate before the fix
    depended on machine load: ~25 % of processes on an idle 2-core machine, ~0-6 %
    with both cores busy): every plugin type, with every kind of index, factor,
    roughness and thickness texture, is built through Mitsuba's parser while
    ``load_dict``/``load_string``/``load_file`` are spies; the constructors must not
    call them (each installs and frees a FileResolver copy)."""
    import mitsuba as mi

    mi.set_variant("llvm_ad_spectral")
    import thinfilm_mi  # noqa: F401

    calls = []
    for name in ("load_dict", "load_string", "load_file"):
        monkeypatch.setattr(mi, name, lambda *a, _n=name, **k: calls.append(_n))
    uni = '<spectrum name="{}" value="{}"/>'
    bsdfs = [
        '<bsdf type="thinfilm_conductor"><string name="material" value="Au"/>'
        '<string name="layers" value="SiO2 300; 1.5 20; 0.4+2.5j 5"/>'
        '<float name="specular_reflectance" value="0.9"/>'
        '<texture type="bitmap" name="thickness"><string name="filename" '
        f'value="{ROOT}/scenes/textures/soap_film.exr"/><boolean name="raw" value="true"/>'
        '</texture></bsdf>',
        '<bsdf type="thinfilm_conductor"><float name="eta" value="1.2"/>'
        '<float name="k" value="3"/><string name="layers" value="TiO2 80; SiO2 90"/></bsdf>',
        '<bsdf type="thinfilm_dielectric"><string name="int_ior" value="BK7"/>'
        '<string name="layers" value="MgF2 100; 2.3 50"/>'
        '<float name="specular_transmittance" value="0.9"/></bsdf>',
        '<bsdf type="thinfilm_diffuse"><string name="layers" value="SiO2 300; Au 20"/>'
        '<rgb name="reflectance" value="0.5, 0.3, 0.2"/></bsdf>',
        '<bsdf type="thinfilm_roughconductor"><string name="material" value="Cu"/>'
        '<float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/>'
        '<string name="layers" value="1.46 120"/></bsdf>',
        '<bsdf type="thinfilm_roughdielectric"><float name="alpha" value="0.2"/>'
        '<string name="thin_film_ior" value="TiO2"/><float name="thin_film_thickness" '
        'value="90"/>' + uni.format("specular_reflectance", "0.8") + '</bsdf>',
    ]
    xml = '<scene version="3.0.0">' + "".join(
        f'<shape type="sphere"><point name="center" value="{i}, 0, 0"/>{b}</shape>'
        for i, b in enumerate(bsdfs)) + "</scene>"
    config = mi.parser.ParserConfig("llvm_ad_spectral")
    state = mi.parser.parse_string(config, xml)
    mi.parser.transform_all(config, state)
    scene = mi.parser.instantiate(config, state)
    assert len(scene.shapes()) == len(bsdfs)
    # edits go through the same code (parameters_changed rebuilds spectra)
    params = mi.traverse(scene)
    for key in list(params.keys()):
        if key.endswith(".thickness") and "layers" in key:
            params[key] = float(np.ravel(np.array(params[key]))[0]) * 1.1
    params.update()
    assert calls == []


def test_loads_between_one_thread_renders_never_hang():
    # the scene-hash sequence (load on two threads, render on one): every run of it
    # hung while constructors updated resampled spectra through mi.traverse; a load takes
    # ~1 s, so 240 s is a hang, not a slow machine
    out = subprocess.run([sys.executable, str(HERE / "load_sequence_child.py"), str(ROOT)],
                         capture_output=True, text=True, timeout=240)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-800:]
