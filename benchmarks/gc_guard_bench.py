"""The GC guard (thinfilm_mi.render.gc_guard): the loop that crashed renders, on any thread, and its cost.

    python benchmarks/gc_guard_bench.py [--iterations 15] [--skip-matrix] [--skip-cost]
                                        [--repeats 9]

1. The matrix: ``tests/support/gc_guard_child.py`` in a fresh process per (variant, collector
   setting, kind, thread): every thin-film plugin, bare, in ``blendbsdf`` and (those that do
   not transmit) in ``twosided``, one configuration per iteration in turn, in
   ``llvm_ad_rgb``, ``llvm_ad_spectral`` and ``llvm_ad_spectral_polarized``, with the
   default collector and with ``gc.set_threshold(1, 1, 1)``, on the main thread and on a
   worker thread while the main thread runs Python, and on two worker threads at once; each
   iteration loads, renders, makes a refused edit whose exception it keeps in a local,
   renders and returns. Prints the exit status (a crash is -11, Dr.Jit's abort -6), the
   dropped BSDFs alive at most at an iteration's start and after a final collection, and the
   seconds (mostly kernel compilations: each iteration traces another set of instances).
   The plain-BSDF reproducer without the package (main thread and worker) and our plugins
   with the guard taken out (all must crash), and the plain BSDF with the guard (must not)
   run first.
2. The cost: one process, ``llvm_ad_spectral``, the demo's glass sphere
   (``thinfilm_dielectric`` "SiO2 500; Au 20; Al 10" on 1.5) on a diffuse floor, 128x128,
   4 spp: ``mi.render`` + ``dr.eval`` with the guard (the hook in ``gc.callbacks``, the
   wrapped ``mi.render``) and without (the hook taken out, Mitsuba's own ``render``), in
   alternating pairs (the median of --repeats pairs), and the passes it deferred and
   full collections it ran per render. Also the hook's own cost per collection pass
   outside a trace (a young pass with and without it), and what the owed full collection
   costs with this process's heap (plus 2e5 lists, as a notebook holds).

Not a comparison with Mitsuba's plugins: part 1 is a crash test, and part 2 times the same
loaded scene with the guard's hook and without it (the same instances alive in both renders),
so the ratio is the hook's own cost. The plugins against their counterparts:
``plugin_bench.py`` and ``render_bench.py``.
"""
from __future__ import annotations

import argparse
import gc
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CHILD = ROOT / "tests" / "support" / "gc_guard_child.py"
VARIANTS = ["llvm_ad_rgb", "llvm_ad_spectral", "llvm_ad_spectral_polarized"]


def _child(variant, iterations, threshold, kind, where):
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, str(CHILD), variant, str(iterations), threshold, kind, where],
                         capture_output=True, text=True, cwd=ROOT)
    last = (out.stdout.strip().splitlines() or ["(no output)"])[-1]
    return out.returncode, last, time.perf_counter() - t0


def matrix(iterations):
    print(f"{'variant':28s} {'gc':8s} {'kind':18s} {'thread':8s} {'status':>6s}  result{'':26s} seconds")
    runs = [("llvm_ad_rgb", "default", "plain", "main", 30), ("llvm_ad_rgb", "default", "plain", "worker", 30),
            ("llvm_ad_rgb", "1", "plain", "worker", 30),
            ("llvm_ad_rgb", "default", "thinfilm-unguarded", "main", 26),
            ("llvm_ad_rgb", "default", "plain+guard", "main", iterations),
            ("llvm_ad_rgb", "1", "plain+guard", "worker", iterations)]
    runs += [(v, g, "thinfilm", where, iterations) for v in VARIANTS for g in ("default", "1")
             for where in ("main", "worker")]
    runs += [("llvm_ad_rgb", g, "thinfilm", "workers", max(iterations // 3, 2)) for g in ("default", "1")]
    for variant, threshold, kind, where, n in runs:
        rc, last, seconds = _child(variant, n, threshold, kind, where)
        print(f"{variant:28s} {threshold:8s} {kind:18s} {where:8s} {rc:6d}  "
              f"{last if rc == 0 else 'crashed':50s} {seconds:7.1f}", flush=True)


def cost(repeats):
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_spectral")
    import thinfilm_mi  # noqa: F401  (installs the guard)
    from thinfilm_mi.render import gc_guard

    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 8},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at([0, 1.5, 5], [0, 0, 0], [0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": 4},
                   "film": {"type": "hdrfilm", "width": 128, "height": 128}},
        "emitter": {"type": "constant"},
        "ball": {"type": "sphere", "bsdf": {"type": "thinfilm_dielectric", "layers": "SiO2 500; Au 20; Al 10",
                                            "int_ior": 1.5}},
        "floor": {"type": "rectangle", "bsdf": {"type": "diffuse"},
                  "to_world": mi.ScalarTransform4f().translate([0, -1, 0]).rotate([1, 0, 0], -90).scale(5)},
    })
    hook = gc_guard._guard
    covered, plain = mi.render, mi.render.__wrapped__   # the guard's wrapper, Mitsuba's own

    def render(seed, render_fn=covered):
        t0 = time.perf_counter()
        dr.eval(render_fn(scene, seed=seed))
        dr.sync_thread()
        return time.perf_counter() - t0

    render(0)   # compile
    with_hook, without, deferred, collections = [], [], [], []
    for i in range(repeats):
        d0, c0 = gc_guard.deferred_collections()
        with_hook.append(render(2 * i + 1))
        d1, c1 = gc_guard.deferred_collections()
        deferred.append(d1 - d0)
        collections.append(c1 - c0)
        gc.callbacks.remove(hook)
        try:
            without.append(render(2 * i + 2, plain))
        finally:
            gc.callbacks.append(hook)
    a, b = statistics.median(with_hook), statistics.median(without)
    print(f"render 128x128 4 spp, thinfilm_dielectric 'SiO2 500; Au 20; Al 10', median of {repeats} pairs:")
    print(f"  with the guard {a * 1e3:.1f} ms, without {b * 1e3:.1f} ms, ratio {a / b:.3f}; "
          f"per render {statistics.median(deferred):.0f} passes deferred, "
          f"{statistics.median(collections):.0f} full collections")
    junk = [[i] for i in range(200_000)]   # a heap of the size a notebook has

    def young_passes(n=2000):
        t0 = time.perf_counter()
        for _ in range(n):
            gc.collect(0)
        return (time.perf_counter() - t0) / n

    on, off = [], []
    for _ in range(repeats):
        on.append(young_passes())
        gc.callbacks.remove(hook)
        try:
            off.append(young_passes())
        finally:
            gc.callbacks.append(hook)
    print(f"  a young pass outside a trace: {statistics.median(on) * 1e6:.2f} us with the hook, "
          f"{statistics.median(off) * 1e6:.2f} us without")
    full = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        gc.collect()
        full.append(time.perf_counter() - t0)
    tracked = len(gc.get_objects())
    del junk
    print(f"  the owed full collection after a trace with a deferred pass: {statistics.median(full) * 1e3:.1f} ms "
          f"({tracked} objects tracked)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--iterations", type=int, default=15)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--skip-matrix", action="store_true")
    ap.add_argument("--skip-cost", action="store_true")
    args = ap.parse_args()
    if not args.skip_cost:
        cost(args.repeats)
    if not args.skip_matrix:
        matrix(args.iterations)


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("gc_guard_bench"):   # --write-docs: docs/_generated/gc_guard_bench.md
        main()
