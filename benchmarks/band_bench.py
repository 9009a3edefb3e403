"""Band-limited tables (``spectral_resolution``, issue 21): build, steady render time,
image error against exact evaluation, and noise at equal spp.

    python benchmarks/band_bench.py [--repeats 5] [--resolution 1.0] [--skip-30]

Variant llvm_ad_spectral, one process, the sphere scene and the Al stacks of
render_bench.py (2.3/1.46 films, 50-200 nm from ``default_rng(6)``):

1. Build: ``mi.load_dict`` of the BSDF with ``tabulate`` true and
   ``spectral_resolution`` set (empty table cache, the build kernels compiled by
   a first load of another stack), 10 and 30 films: load time, what the build
   obtained (``tables.last_build``: result, rounds' (nu, nv, err_u, err_v),
   exact evaluations, colour check).
2. Steady render time, 256x256, 16 spp: ``conductor``, 10 films exact
   (``tabulate`` false) and 10 films band-limited; one warm-up render each, then
   --repeats round-robin rounds, medians.
3. Image error of the band-limited table against exact evaluation, 10 films,
   128x128 at 1024 spp, the same seed: CIEDE2000 of 4x4-pixel block means (linear
   sRGB clipped to [0, 1]); noise floor: exact seed 0 against exact seed 1.
4. Noise at equal spp: 16 renders (seeds 0..15) at 4 spp in each mode; the mean
   over pixels of the per-pixel variance of the luminance, exact / table.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import render_bench as rb  # noqa: E402


def bsdf(L: int, mode: str, resolution: float) -> dict:
    d = rb.thicknesses()
    layers = "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(L))
    out = {"type": "thinfilm_conductor", "material": "Al", "layers": layers,
           "tabulate": mode != "exact"}
    if mode == "band":
        out["spectral_resolution"] = resolution
    return out


def scene(config: str, resolution: float, res=256, spp=16) -> dict:
    s = rb.scene_dict("conductor", res, spp)
    if config != "conductor":
        L, mode = config.split(":")
        s["sphere"]["bsdf"] = bsdf(int(L), mode, resolution)
    return s


def build(resolution: float, films) -> None:
    import mitsuba as mi
    from thinfilm_mi import kernel as K, tables
    print("\n### Band-limited builds (tabulate true, spectral_resolution "
          f"{resolution} nm)\n")
    print("| films | load (s) | result | rounds (nu, nv, err_u, err_v) | exact evaluations "
          "| colour check (max ΔE2000) |")
    print("|---:|---:|---|---|---:|---:|")
    mi.load_dict(bsdf(10, "band", resolution * 1.01))   # compiles the build kernels
    for L in films:
        K._TABLE_CACHE.clear()
        t = time.perf_counter()
        mi.load_dict(bsdf(L, "band", resolution))
        dt = time.perf_counter() - t
        s = tables.last_build
        rounds = "; ".join(f"{nu}x{nv}: {eu:.1e}, {ev:.1e}" for nu, nv, eu, ev in s.get("errors", []))
        print(f"| {L} | {dt:.2f} | {s['result']} | {rounds} | {s['points']:,} | "
              f"{s.get('colour_error') or 0:.3f} |", flush=True)


def steady(repeats: int, resolution: float) -> None:
    import mitsuba as mi
    configs = ["conductor", "10:exact", "10:band"]
    scenes = {c: mi.load_dict(scene(c, resolution)) for c in configs}
    for s in scenes.values():
        rb.render_sync(s, seed=0)
    ts = {c: [] for c in configs}
    for i in range(repeats):
        for c in configs:
            t = time.perf_counter()
            rb.render_sync(scenes[c], seed=i + 1)
            ts[c].append(time.perf_counter() - t)
    base = float(np.median(ts["conductor"]))
    print(f"\n### Steady render (256x256, 16 spp, median of {repeats} round-robin)\n")
    print("| configuration | mode obtained | median (s) | ratio to conductor |")
    print("|---|---|---:|---:|")
    for c in configs:
        m = float(np.median(ts[c]))
        print(f"| {c} | {rb.mode_of(scenes[c])} | {m:.3f} | {m / base:.2f} |")


def blocks(img, k=4):
    a = np.array(img, dtype=np.float64)[..., :3]
    h, w = a.shape[0] // k * k, a.shape[1] // k * k
    return a[:h, :w].reshape(h // k, k, w // k, k, 3).mean(axis=(1, 3))


def image_error(resolution: float, spp: int) -> None:
    import mitsuba as mi
    ex = mi.load_dict(scene("10:exact", resolution, 128, spp))
    bd = mi.load_dict(scene("10:band", resolution, 128, spp))
    img_e = rb.render_sync(ex, seed=0)
    img_b = rb.render_sync(bd, seed=0)
    img_e1 = rb.render_sync(ex, seed=1)
    de = rb.delta_e(blocks(img_b), blocks(img_e))
    noise = rb.delta_e(blocks(img_e1), blocks(img_e))
    print(f"\n### Image error, 10 films, band-limited table against exact (128x128, {spp} spp, "
          "same seed, 4x4 blocks)\n")
    print(f"mean ΔE2000 {de.mean():.3f}, p95 {np.percentile(de, 95):.3f}, max {de.max():.3f}; "
          f"noise floor (exact seed 0 vs 1) mean {noise.mean():.3f}")


def variance(resolution: float, seeds: int = 16, spp: int = 4) -> None:
    import mitsuba as mi
    out = {}
    for mode in ("exact", "band"):
        s = mi.load_dict(scene(f"10:{mode}", resolution, 128, spp))
        imgs = np.stack([np.array(rb.render_sync(s, seed=i), dtype=np.float64)[..., :3]
                         for i in range(seeds)])
        Y = imgs @ np.array([0.2126, 0.7152, 0.0722])
        out[mode] = float(Y.var(axis=0, ddof=1).mean())
    print(f"\n### Noise at equal spp (10 films, 128x128, {spp} spp, {seeds} seeds)\n")
    print(f"mean per-pixel variance of luminance: exact {out['exact']:.4e}, band-limited table "
          f"{out['band']:.4e}; ratio exact / table {out['exact'] / out['band']:.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--de-spp", type=int, default=1024)
    ap.add_argument("--skip-30", action="store_true")
    args = ap.parse_args()
    import mitsuba as mi
    mi.set_variant(rb.VARIANT)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    build(args.resolution, (10,) if args.skip_30 else (10, 30))
    steady(args.repeats, args.resolution)
    image_error(args.resolution, args.de_spp)
    variance(args.resolution)


if __name__ == "__main__":
    main()
