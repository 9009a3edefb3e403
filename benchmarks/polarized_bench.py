"""Render time of ``thinfilm_conductor`` in ``llvm_ad_spectral_polarized`` against
Mitsuba's polarized ``conductor``.

    python benchmarks/polarized_bench.py [--repeats 7] [--res 256] [--spp 16]

The scene of ``render_bench.py`` (a sphere on a diffuse floor under a constant
emitter, path integrator, max_depth 8, 256x256, 16 spp): the sphere is Mitsuba's
``conductor`` (Al) or ``thinfilm_conductor`` on Al with 1, 2, 3, 10 and 30 films
(the same stacks). In polarized variants every stack is evaluated exactly from its
complex amplitudes (films unrolled in the kernel; no tables, no film loops). One
process; one warm-up render per configuration (compiles; its time is reported as
"first"), then --repeats rounds in which every configuration renders once
(round-robin), median per configuration (``dr.eval`` + ``dr.sync_thread``).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from render_bench import render_sync, scene_dict  # noqa: E402

VARIANT = "llvm_ad_spectral_polarized"
FILMS = (1, 2, 3, 10, 30)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    args = ap.parse_args(argv)

    import drjit as dr
    import mitsuba as mi
    mi.set_variant(VARIANT)
    import thinfilm_mi  # noqa: F401

    configs = ["conductor"] + [f"{L}:exact" for L in FILMS]
    scenes, first = {}, {}
    for c in configs:
        scenes[c] = mi.load_dict(scene_dict(c, res=args.res, spp=args.spp))
        t = time.perf_counter()
        render_sync(scenes[c], seed=0)
        first[c] = time.perf_counter() - t
        print(f"  {c}: first render {first[c]:.2f} s", file=sys.stderr, flush=True)
    ts = {c: [] for c in configs}
    for i in range(args.repeats):
        for c in configs:
            t = time.perf_counter()
            render_sync(scenes[c], seed=i + 1)
            ts[c].append(time.perf_counter() - t)
    base = float(np.median(ts["conductor"]))
    print(f"\n### {VARIANT}: steady render time ({args.res}x{args.res}, {args.spp} spp, "
          f"median of {args.repeats} round-robin; Dr.Jit {dr.__version__}, "
          f"Mitsuba {mi.__version__})\n")
    print("| BSDF | films | render median (s) | min (s) | ratio to conductor "
          "| first render incl. compile (s) |")
    print("|---|---:|---:|---:|---:|---:|")
    for c in configs:
        med, mn = float(np.median(ts[c])), float(np.min(ts[c]))
        name, films = ("conductor (Al)", "–") if c == "conductor" else \
            ("thinfilm_conductor", c.split(":")[0])
        print(f"| {name} | {films} | {med:.3f} | {mn:.3f} | {med / base:.2f} | "
              f"{first[c]:.2f} |")


if __name__ == "__main__":
    main()
