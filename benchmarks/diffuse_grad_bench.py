"""``thinfilm_diffuse`` gradients through ``R_dh`` (issue 30): what they cost.

    python benchmarks/diffuse_grad_bench.py [--variants llvm_ad_spectral,llvm_ad_rgb]
                                            [--res 64] [--spp 16] [--repeats 7]
                                            [--films 3,10,30] [--edit-repeats 5]

In AD variants the "multiple" model's ``R_dh`` carries its derivatives: a table of
``∂R_dh/∂x`` (every film's thickness and index, ``thinfilm_mi/tabulate/hemispherical.py``)
is built when the BSDF loads and when its films are edited, and the kernel adds
``Σ ∂R_dh/∂x (x - detach(x))`` to ``R_dh`` where a parameter carries gradients.
One process, per variant:

1. Render time. A sphere with ``thinfilm_diffuse`` (``"2.3 90; 1.46 150; 2.3 60"``
   on reflectance 0.6, the issue's stack, "multiple") under a constant emitter,
   ``path`` integrator, max_depth 3, --res x --res, --spp spp. Three
   configurations of the same scene object: ``primal`` (no gradients) and ``grad``
   (``layers.0.thickness`` tracked: enabled and ``params.update()``, which builds
   ``R_dh``'s derivative table, render then ``dr.backward`` of the mean pixel, up to
   the parameter's gradient). Each renders once (warm-up: compiles), then --repeats
   round-robin rounds (order reversed every other round), different seeds; medians,
   and ``grad`` / ``primal``. The gradient of the last round is printed too.
2. Load and edit time for --films films (alternating 2.3 / 1.46, 50-200 nm from
   ``numpy.random.default_rng(6)``, as ``render_bench.py``): ``mi.load_dict`` of the
   BSDF, an edit of ``layers.0.thickness`` (``params.update()``), and the derivative
   table's share (``r_dh_partials`` on the BSDF's own factors, timed alone).
   Medians of --edit-repeats (after one warm-up, which takes the kernel compilation
   or Dr.Jit's disk cache).

Markdown tables on stdout, progress on stderr.

What a gradient costs over the primal render of the same scene object (both sides ours, the
same instances alive) is this bench's question: Mitsuba's ``diffuse`` has no films whose
derivatives it could carry, so there is no counterpart to time; the primal render against
``diffuse`` is ``plugin_bench.py``'s and ``render_bench.py``'s. The scene is freed
(``gc.collect``) before the next variant renders.
"""
from __future__ import annotations

import argparse
import gc
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

KEY = "sphere.bsdf.layers.0.thickness"
LAYERS = "2.3 90; 1.46 150; 2.3 60"


def scene_dict(res: int, spp: int) -> dict:
    import mitsuba as mi
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4.5],
                                                             target=[0, 0, 0], up=[0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": spp},
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}},
        "emitter": {"type": "constant"},
        "sphere": {"type": "sphere", "bsdf": {"type": "thinfilm_diffuse", "layers": LAYERS,
                                              "reflectance": 0.6}},
    }


def render(variant: str, res: int, spp: int, repeats: int) -> list[str]:
    import drjit as dr
    import mitsuba as mi

    scene = mi.load_dict(scene_dict(res, spp))
    params = mi.traverse(scene)

    def primal(seed):
        img = mi.render(scene, spp=spp, seed=seed)
        dr.eval(img)
        dr.sync_thread()
        return None

    def gradient(seed):
        # the derivative table of R_dh is built by the update that enables gradients
        dr.enable_grad(params[KEY])
        params.update()
        try:
            img = mi.render(scene, params, spp=spp, seed=seed)
            dr.backward(dr.mean(img, axis=None))
            g = dr.grad(params[KEY])
            dr.eval(g)
            dr.sync_thread()
            return float(g[0])
        finally:
            dr.disable_grad(params[KEY])
            params.update()

    configs = {"primal": primal, "grad": gradient}
    times = {c: [] for c in configs}
    last = {}
    for c, f in configs.items():
        f(0)                                   # warm-up: compiles
    for i in range(repeats):
        order = list(configs) if i % 2 == 0 else list(configs)[::-1]
        for c in order:
            t = time.perf_counter()
            last[c] = configs[c](i + 1)
            times[c].append(time.perf_counter() - t)
    med = {c: float(np.median(v)) for c, v in times.items()}
    for c in configs:
        print(f"  {variant} {c}: median {med[c]:.3f} s", file=sys.stderr, flush=True)
    ratio = med["grad"] / med["primal"]
    return [f"| `{variant}` | {med['primal']:.3f} | {med['grad']:.3f} | {ratio:.2f} | "
            f"{last['grad']:+.3e} |"]


def layers_of(n: int) -> str:
    d = np.random.default_rng(6).uniform(50.0, 200.0, n)
    return "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(n))


def load_and_edit(variant: str, films: int, repeats: int) -> str:
    import drjit as dr
    import mitsuba as mi

    from thinfilm_mi.materials.model import GRID
    from thinfilm_mi.render.layered.factors import DiffuseFactors

    spec = {"type": "thinfilm_diffuse", "layers": layers_of(films), "reflectance": 0.6}
    loads, edits, partials = [], [], []
    for i in range(repeats + 1):
        t = time.perf_counter()
        bsdf = mi.load_dict(spec)
        dr.sync_thread()
        t_load = time.perf_counter() - t
        params = mi.traverse(bsdf)
        d0 = float(params["layers.0.thickness"][0])
        t = time.perf_counter()
        params["layers.0.thickness"] = d0 + 0.5 + 0.01 * i
        params.update()
        dr.sync_thread()
        t_edit = time.perf_counter() - t
        factors = DiffuseFactors(bsdf.coating, bsdf.film_n, None)
        t = time.perf_counter()
        factors.r_dh_partials(GRID)
        t_part = time.perf_counter() - t
        if i:                                   # the first is the warm-up
            loads.append(t_load)
            edits.append(t_edit)
            partials.append(t_part)
    lo, ed, pa = (float(np.median(v)) for v in (loads, edits, partials))
    print(f"  {variant} {films} films: load {lo:.3f} s, edit {ed:.3f} s, table {pa:.3f} s",
          file=sys.stderr, flush=True)
    return f"| `{variant}` | {films} | {lo:.3f} | {ed:.3f} | {pa:.3f} |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", default="llvm_ad_spectral,llvm_ad_rgb")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--films", default="3,10,30")
    ap.add_argument("--edit-repeats", type=int, default=5)
    args = ap.parse_args()
    import mitsuba as mi

    rows_r, rows_l = [], []
    for variant in args.variants.split(","):
        mi.set_variant(variant)
        import thinfilm_mi  # noqa: F401  (registers the plugins in this variant)
        rows_r += render(variant, args.res, args.spp, args.repeats)
        gc.collect()   # the scene of render(): none of it alive in the next renders
        rows_l += [load_and_edit(variant, int(f), args.edit_repeats)
                   for f in args.films.split(",")]
    print(f"\n### Render with a tracked thickness ({args.res}x{args.res}, {args.spp} spp, "
          f"median of {args.repeats})\n")
    print("| variant | primal (s) | grad (s) | grad / primal | gradient |")
    print("|---|---|---|---|---|")
    print("\n".join(rows_r))
    print(f"\n### Load and edit (median of {args.edit_repeats}; the table is part of both)\n")
    print("| variant | films | load (s) | edit (s) | derivative table (s) |")
    print("|---|---|---|---|---|")
    print("\n".join(rows_l))


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("diffuse_grad_bench"):   # --write-docs: docs/_generated/diffuse_grad_bench.md
        main()
