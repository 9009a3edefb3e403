"""Band-limited tables (``spectral_resolution``, issue 21): builds, steady render time
at every depth with default settings, first image, image error against exact
evaluation, and noise at equal spp.

    python benchmarks/band_bench.py [--repeats 5] [--first-repeats 3] [--de-spp 1024]
                                    [--skip-first] [--skip-fig8]
                                    [--only build|steady|first|de|fig8|noise]

Variant llvm_ad_spectral; the sphere scene and the Al stacks of render_bench.py
(2.3/1.46 films, 50-200 nm from ``default_rng(6)``). Configurations:
``conductor`` (Mitsuba's, Al), ``L:default`` (``thinfilm_conductor`` with L films
and default settings: ``tabulate="auto"``, ``spectral_resolution`` 1 nm) and
``L:exact`` (``tabulate=false``).

1. Builds: ``mi.load_dict`` of the 10- and 30-film BSDFs with default settings,
   empty table cache (the build kernels compiled by a first load of another
   stack): load time and what the build obtained (the side's ``build_report``).
2. Steady render, 256x256, 16 spp, each configuration against ``conductor``
   (``timing.pair_rounds``: each scene of ours loaded alone for its render and freed,
   as a live Python BSDF is traced into every render; an untimed round, then
   --repeats rounds of back-to-back pairs), medians of the CPU-time ratios.
3. First image with an empty kernel cache (subprocess, fresh DRJIT_CACHE_DIR):
   ``mi.load_dict`` + first ``mi.render``, --first-repeats round-robin rounds,
   the run with the median total; with the table store off (every process
   builds), and for the default configurations again with a warm store (a
   script run a second time: the tables come from disk).
4. Image error of default mode against ``tabulate=false``, 10 and 30 films,
   128x128 at --de-spp, the same seed: CIEDE2000 of 4x4-pixel block means
   (linear sRGB clipped to [0, 1]); noise floor: exact seed 0 against seed 1.
   The paper's Fig. 8 scenes: render_bench.image_error (tabulate true against
   false, per pixel).
5. Noise at equal spp: 16 renders (seeds 0..15) at 4 spp per mode, 10 and 30
   films, of the scene above and of the sphere alone with direct reflection only
   (the noise of the spectral estimate); the mean over pixels of the per-pixel
   variance of the luminance, exact / default.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import render_bench as rb  # noqa: E402

DEPTHS = (1, 3, 10, 30)


def bsdf(L: int, mode: str) -> dict:
    """``thinfilm_conductor`` on Al with the benchmark stack of ``L`` films at ``mode``."""
    return rb.bsdf_dict(f"{L}:{mode}")


def scene(config: str, res=256, spp=16) -> dict:
    return rb.scene_dict(config, res, spp)


def build() -> None:
    import mitsuba as mi

    from thinfilm_mi.render import stack_build
    print("\n### Band-limited builds (default settings)\n")
    print("| films | load (s) | result | table | rounds (nu x nv: err_u, err_v) "
          "| exact evaluations | colour check ΔE2000 (D65 / A / F11) |")
    print("|---:|---:|---|---|---|---:|---|")
    d = bsdf(10, "default")
    d["layers"] = d["layers"].replace("2.3 ", "2.31 ")
    mi.load_dict(d)                      # compiles the build kernels
    for L in (10, 30):
        stack_build.TABLE_CACHE.clear()
        t = time.perf_counter()
        b = mi.load_dict(bsdf(L, "default"))
        dt = time.perf_counter() - t
        s = b.stack.plan[False].build_report
        tab = b.stack.plan[False].table
        rounds = "; ".join(f"{nu}x{nv}: {eu:.1e}, {ev:.1e}" for nu, nv, eu, ev in s["errors"])
        ce = s.get("colour_errors") or {}
        print(f"| {L} | {dt:.2f} | {s['result']} | "
              f"{f'{tab.nu}x{tab.nv} ({tab.error:.1e})' if tab is not None else '–'} | "
              f"{rounds} | {s['points']:,} | "
              f"{' / '.join(f'{v:.3f}' for v in ce.values())} |", flush=True)


def steady(repeats: int) -> None:
    import mitsuba as mi
    from timing import own_table_store, pair_rounds
    configs = [f"{L}:default" for L in DEPTHS] + [f"{L}:exact" for L in (10, 30)]
    store = os.environ["THINFILM_MI_TABLE_CACHE"]
    own_table_store()   # a reload of our scene reads the tables its first load built
    try:
        conductor = mi.load_dict(scene("conductor"))
        rows = pair_rounds([conductor] * len(configs),
                           [lambda c=c: mi.load_dict(scene(c)) for c in configs], repeats)
    finally:
        os.environ["THINFILM_MI_TABLE_CACHE"] = store
    print(f"\n### Steady render (256x256, 16 spp; median of {repeats} rounds of back-to-back "
          "pairs with `conductor`, our scene loaded alone)\n")
    print("| configuration | mode obtained | median (s) | conductor (s) | CPU-time ratio to conductor |")
    print("|---|---|---:|---:|---:|")
    for c, row in zip(configs, rows):
        print(f"| {c} | {row['mode']} | {row['ours']:.3f} | {row['native']:.3f} | "
              f"{row['ratio']:.2f} |", flush=True)


def first_image_child(config: str) -> None:
    import mitsuba as mi
    mi.set_variant(rb.VARIANT)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    s = mi.load_dict(scene(config))
    t1 = time.perf_counter()
    rb.render_sync(s, seed=0)
    t2 = time.perf_counter()
    print(json.dumps({"load": t1 - t0, "render": t2 - t1, "mode": rb.mode_of(s)}))


def first_image(repeats: int) -> None:
    configs = ["conductor", "10:default", "10:exact", "30:default", "30:exact"]
    runs = rb.first_images(__file__, configs, repeats)
    warm = rb.first_images(__file__, ["10:default", "30:default"], repeats, store="warm")
    print(f"\n### First image, empty kernel cache (median total of {repeats} round-robin runs)\n")
    print("| configuration | table store | mode obtained | mi.load (s) | first render (s) | total (s) "
          "| ratio to conductor |")
    print("|---|---|---|---:|---:|---:|---:|")
    base = None
    rows = [(c, "off", runs[c]) for c in configs] + [(c, "warm", warm[c]) for c in warm]
    for c, store, r in rows:
        tot = r["load"] + r["render"]
        base = base or tot
        print(f"| {c} | {store} | {r['mode']} | {r['load']:.2f} | {r['render']:.2f} | {tot:.2f} | "
              f"{tot / base:.2f} |", flush=True)


def blocks(img, k=4):
    a = np.array(img, dtype=np.float64)[..., :3]
    h, w = a.shape[0] // k * k, a.shape[1] // k * k
    return a[:h, :w].reshape(h // k, k, w // k, k, 3).mean(axis=(1, 3))


def image_error(spp: int) -> None:
    import mitsuba as mi
    print(f"\n### Image error of default mode against tabulate=false (128x128, {spp} spp, "
          "same seed, 4x4-pixel blocks)\n")
    print("| films | mode obtained | mean ΔE2000 | p95 | max | noise floor (exact seed 0 vs 1), "
          "mean |")
    print("|---:|---|---:|---:|---:|---:|")
    for L in (10, 30):
        ex = mi.load_dict(scene(f"{L}:exact", 128, spp))
        df = mi.load_dict(scene(f"{L}:default", 128, spp))
        img_e = rb.render_sync(ex, seed=0)
        img_d = rb.render_sync(df, seed=0)
        img_e1 = rb.render_sync(ex, seed=1)
        de = rb.delta_e(blocks(img_d), blocks(img_e))
        noise = rb.delta_e(blocks(img_e1), blocks(img_e))
        print(f"| {L} | {rb.mode_of(df)} | {de.mean():.4f} | {np.percentile(de, 95):.4f} | "
              f"{de.max():.3f} | {noise.mean():.3f} |", flush=True)


def specular_only(config: str, res: int, spp: int) -> dict:
    """The sphere alone under the constant emitter, direct reflection only: a
    pixel's noise is then the spectral estimate's (and the pixel jitter's)."""
    s = scene(config, res, spp)
    del s["floor"]
    s["integrator"] = {"type": "path", "max_depth": 2}
    return s


def variance(seeds: int = 16, spp: int = 4) -> None:
    import mitsuba as mi
    print(f"\n### Noise at equal spp (128x128, {spp} spp, {seeds} seeds)\n")
    print("| films | scene | exact: mean per-pixel variance of Y | default (table) "
          "| ratio exact / table |")
    print("|---:|---|---:|---:|---:|")
    Yw = np.array([0.2126, 0.7152, 0.0722])
    for L, (name, make) in ((L, v) for L in (10, 30) for v in (("sphere and floor", scene),
                                                               ("sphere only, direct",
                                                                specular_only))):
        out = {}
        for mode in ("exact", "default"):
            s = mi.load_dict(make(f"{L}:{mode}", 128, spp))
            Y = np.stack([np.array(rb.render_sync(s, seed=i), dtype=np.float64)[..., :3] @ Yw
                          for i in range(seeds)])
            out[mode] = float(Y.var(axis=0, ddof=1).mean())
        print(f"| {L} | {name} | {out['exact']:.4e} | {out['default']:.4e} | "
              f"{out['exact'] / out['default']:.3f} |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--first-repeats", type=int, default=3)
    ap.add_argument("--de-spp", type=int, default=1024)
    ap.add_argument("--skip-first", action="store_true")
    ap.add_argument("--skip-fig8", action="store_true")
    ap.add_argument("--only", choices=("build", "steady", "first", "de", "fig8", "noise"))
    ap.add_argument("--first-image-child")
    args = ap.parse_args()
    if args.first_image_child:
        return first_image_child(args.first_image_child)
    import mitsuba as mi
    mi.set_variant(rb.VARIANT)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    def want(part):
        return args.only is None or args.only == part
    if want("build"):
        build()
    if want("steady"):
        steady(args.repeats)
    if want("first") and not args.skip_first:
        first_image(args.first_repeats)
    if want("de"):
        image_error(args.de_spp)
    if want("fig8") and not args.skip_fig8:
        rb.image_error(200, 256)
    if want("noise"):
        variance()


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("band_bench"):   # --write-docs: docs/_generated/band_bench.md
        main()
