"""How the render-time benchmarks time a thin-film plugin against its Mitsuba counterpart:
the sphere scene, the counterparts, and the alone-scene method, written once.

A live Python BSDF is traced into every render of its variant: a symbolic call records
every registered instance of its domain, so while one of our scenes is alive, every other
render of the process, that of a scene holding only Mitsuba's plugins included, pays for
tracing our code. With several scenes of ours alive at once each render paid for all of
them, and the ratios were pulled towards 1 (measured: Mitsuba's twins of
``plugin_bench.py`` rendered in 0.09-0.17 s alone against 0.14-0.22 s beside seven live
plugins). Hence the method every bench here uses (:func:`pair_rounds`):

- a scene holding our plugins is loaded for its render, rendered once untimed (what a load
  leaves for the first render is not steady cost), timed, and freed (:func:`alone`); the
  process has its own table store (:func:`own_table_store`), so a reload reads its tables
  instead of building them, and its kernels are cached;
- Mitsuba's scenes stay loaded (their instances are C++: nothing of them is traced into
  another render);
- an untimed first round compiles every kernel with the same instances alive as in the
  timed rounds; then each pair renders back to back, the order alternating per round; the
  ratio is the median over the rounds of the round's ratio of the process's CPU time (all of
  Dr.Jit's threads; a slow spell of a shared machine hits both renders of a pair alike);
- each variant runs in a process of its own (:func:`child`); a first image is a fresh
  process too (:func:`first_images`).
"""
from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

#: This checkout's root: its package is the one timed (first on ``sys.path`` here and in the
#: children), not an installed one
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, REPO)

__all__ = ["COUNTERPARTS", "MODES", "Counterpart", "alone", "child", "first_images", "mode_of",
           "own_table_store", "pair_rounds", "render_sync", "sphere_scene", "timed_render"]


# -- the scene ------------------------------------------------------------------------------

def sphere_scene(bsdf: dict, res: int = 256, spp: int = 16, max_depth: int = 8,
                 radiance: dict | None = None) -> dict:
    """A sphere (radius 1) of ``bsdf`` on a diffuse floor under a constant emitter of
    ``radiance`` (default: a pale blue sky), ``path`` with ``max_depth``, ``res``², ``spp``,
    box filter. In a mono variant the film is ``luminance`` (what ``hdrfilm`` would switch
    to, with a warning)."""
    import mitsuba as mi
    film = {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}}
    if mi.is_monochromatic:
        film["pixel_format"] = "luminance"
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at(
                       origin=[0, 1.5, 5], target=[0, 0.2, 0], up=[0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": spp},
                   "film": film},
        "emitter": {"type": "constant",
                    "radiance": radiance or {"type": "rgb", "value": [0.8, 0.85, 1.0]}},
        "sphere": {"type": "sphere", "center": [0, 0.2, 0], "radius": 1.0, "bsdf": bsdf},
        "floor": {"type": "rectangle",
                  "to_world": mi.ScalarTransform4f().translate([0, -0.8, 0])
                  .rotate([1, 0, 0], -90).scale(6),
                  "bsdf": {"type": "diffuse",
                           "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.45]}}},
    }


# -- the counterparts -----------------------------------------------------------------------

@dataclass(frozen=True)
class Counterpart:
    """One of our BSDFs and the Mitsuba plugin it is timed against: ``native`` (a dict for
    ``mi.load_dict``) and ``ours`` (the same settings, plus ``layers``)."""

    plugin: str
    native: dict
    settings: dict = field(default_factory=dict)

    def ours(self, layers: str, **extra) -> dict:
        return {"type": self.plugin, **self.settings, "layers": layers, **extra}


_ROUGH_AL = {"type": "roughconductor", "material": "Al", "alpha": 0.2}

#: plugin -> its counterpart, for a stack of any depth. ``thinfilm_coating`` over a rough
#: base is timed against the base alone (Mitsuba has no coating of films); with no films
#: over ``diffuse`` its counterpart is ``plastic`` (``plugin_bench.PAIRS``).
COUNTERPARTS = {c.plugin: c for c in (
    Counterpart("thinfilm_conductor", {"type": "conductor", "material": "Al"}, {"material": "Al"}),
    Counterpart("thinfilm_roughconductor", _ROUGH_AL, {"material": "Al", "alpha": 0.2}),
    Counterpart("thinfilm_dielectric", {"type": "dielectric", "int_ior": 1.6}, {"int_ior": 1.6}),
    Counterpart("thinfilm_roughdielectric", {"type": "roughdielectric", "int_ior": 1.6, "alpha": 0.2},
                {"int_ior": 1.6, "alpha": 0.2}),
    Counterpart("thinfilm_diffuse", {"type": "diffuse", "reflectance": 0.5}, {"reflectance": 0.5}),
    Counterpart("thinfilm_coating", _ROUGH_AL, {"int_ior": 1.5, "bsdf": _ROUGH_AL}),
)}

#: the ``tabulate`` settings a stack is timed at: name -> the BSDF's extra properties
MODES = {"default": {}, "exact": {"tabulate": False}, "table": {"tabulate": True}}


# -- the method -----------------------------------------------------------------------------

def render_sync(scene, **kw):
    """``mi.render``, evaluated and waited for."""
    import drjit as dr
    import mitsuba as mi
    img = mi.render(scene, **kw)
    dr.eval(img)
    dr.sync_thread()
    return img


def mode_of(scene) -> str:
    """How the stack of the scene's first thin-film BSDF is evaluated (``stack.mode()``; the
    coating's stack is its walk's; ``thinfilm_diffuse`` reads its model's factor table where
    it has one, else its coating's stack)."""
    for shape in scene.shapes():
        b = shape.bsdf()
        coated = getattr(b, "coated", None)
        if coated is not None and coated.table is not None:
            return "factor table"
        # explicit None tests: a stack without films has length 0
        candidates = (getattr(b, "stack", None),
                      getattr(getattr(b, "coating", None), "stack", None),
                      getattr(coated, "coating", None))
        stack = next((s for s in candidates if s is not None), None)
        if stack is not None:
            return stack.mode()
    return "–"


def timed_render(scene, seed: int) -> tuple[float, float]:
    """``(wall, cpu)`` seconds of one render of ``scene`` (the process's CPU time: all of
    Dr.Jit's threads)."""
    t, c = time.perf_counter(), time.process_time()
    render_sync(scene, seed=seed)
    return time.perf_counter() - t, time.process_time() - c


def alone(load, seed: int) -> tuple[float, float, str]:
    """Load a scene holding our (Python) BSDFs, render it and free it: ``(wall, cpu, mode)``
    of the render alone (see the module's docstring). Loads after the first find their
    tables in the process's own store and their kernels cached."""
    scene = load()
    mode = mode_of(scene)
    render_sync(scene, seed=seed + 1000)   # untimed: what a load leaves for the first render
    wall, cpu = timed_render(scene, seed)
    del scene
    gc.collect()
    return wall, cpu, mode


def own_table_store() -> None:
    """A fresh table store for this process, so that a scene loaded again (:func:`alone`)
    reads its tables instead of building them (the builds are not what is timed)."""
    os.environ["THINFILM_MI_TABLE_CACHE"] = tempfile.mkdtemp(prefix="bench_tables_")


def pair_rounds(natives: list, loaders: list, repeats: int, progress: str = "") -> list[dict]:
    """Each of Mitsuba's scenes ``natives[i]`` (loaded, they stay so) against ``loaders[i]()``
    (a scene of ours, :func:`alone`): an untimed round, then ``repeats`` rounds of back-to-back
    pairs, the order alternating. Per pair: ``mode`` (obtained), ``native`` and ``ours`` (median
    wall seconds), ``wall_ratio`` and ``ratio`` (median of the rounds' wall-clock and CPU-time
    ratios)."""
    modes = []
    for i, (native, load) in enumerate(zip(natives, loaders)):
        render_sync(native, seed=0)
        modes.append(alone(load, 0)[2])
        if progress:
            print(f"  {progress}: pair {i + 1}/{len(natives)} compiled, mode {modes[-1]}",
                  file=sys.stderr, flush=True)
    wall = [([], []) for _ in natives]
    cpu = [([], []) for _ in natives]
    for r in range(repeats):
        for i, (native, load) in enumerate(zip(natives, loaders)):
            for ours in ((False, True) if r % 2 == 0 else (True, False)):
                w, c = alone(load, r + 1)[:2] if ours else timed_render(native, r + 1)
                wall[i][ours].append(w)
                cpu[i][ours].append(c)
    out = []
    for i, mode in enumerate(modes):
        native_w, ours_w = (np.array(x) for x in wall[i])
        native_c, ours_c = (np.array(x) for x in cpu[i])
        out.append({"mode": mode, "native": float(np.median(native_w)),
                    "ours": float(np.median(ours_w)),
                    "wall_ratio": float(np.median(ours_w / native_w)),
                    "ratio": float(np.median(ours_c / native_c))})
    return out


def child(script: str, *args: str, **env: str) -> dict | list:
    """``script`` run with ``args`` in a fresh process, the table store off unless ``env``
    says otherwise (``env``: more environment variables): the JSON of its last line of output
    (its stderr passed on)."""
    env = {"THINFILM_MI_TABLE_CACHE": "off",
           "PYTHONPATH": os.pathsep.join([REPO] + [p for p in os.environ.get("PYTHONPATH", "")
                                                   .split(os.pathsep) if p]), **env}
    res = subprocess.run([sys.executable, os.path.abspath(script), *args],
                         env=dict(os.environ, **env), capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(res.stderr[-3000:])
    sys.stderr.write(res.stderr)
    return json.loads(res.stdout.strip().splitlines()[-1])


def first_images(script: str, configs, repeats: int, store: str = "off",
                 child_args: tuple = ()) -> dict:
    """Per configuration, the run (``{"load", "render", "mode"}``) with the median total of
    ``repeats``: each a new process running ``script --first-image-child CONFIG *child_args``
    with a fresh ``DRJIT_CACHE_DIR`` (an empty kernel cache), the configurations
    round-robin. ``store``: the table store on disk is ``"off"`` (every process builds its
    tables), or ``"warm"``: a store filled by one untimed run per configuration."""
    runs = {c: [] for c in configs}
    with tempfile.TemporaryDirectory(prefix="tables_") as tables:
        setting = tables if store == "warm" else "off"

        def run(c: str) -> dict:
            with tempfile.TemporaryDirectory(prefix="drjit_cache_") as cache:
                return child(script, "--first-image-child", c, *child_args,
                             DRJIT_CACHE_DIR=cache, THINFILM_MI_TABLE_CACHE=setting)

        if store == "warm":
            for c in configs:
                run(c)
        for _ in range(repeats):
            for c in configs:
                runs[c].append(run(c))
                print(f"  first image {c} {' '.join(child_args)} (table store {store}): "
                      f"{runs[c][-1]}", file=sys.stderr, flush=True)
    return {c: sorted(runs[c], key=lambda r: r["load"] + r["render"])[len(runs[c]) // 2]
            for c in configs}
