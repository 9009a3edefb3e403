"""Render time of ``thinfilm_conductor`` in ``llvm_ad_spectral_polarized`` against
Mitsuba's polarized ``conductor``: steady renders and the first image.

    python benchmarks/polarized_bench.py [--repeats 7] [--res 256] [--spp 16]
                                         [--films 1,2,3,10,30] [--first-repeats 3]
                                         [--skip-steady] [--skip-first]

The scene of ``render_bench.py`` (a sphere on a diffuse floor under a constant
emitter, path integrator, max_depth 8, 256x256, 16 spp): the sphere is Mitsuba's
``conductor`` (Al) or ``thinfilm_conductor`` on Al with the benchmark stacks
(alternating 2.3 / 1.46 films of 50-200 nm), each with ``tabulate`` false
("exact": the Mueller matrix of the exact amplitudes, films unrolled), true
("table": the Mueller components read from a table, :mod:`thinfilm_mi.tabulate.mueller`)
and at default settings ("auto"); the mode obtained is printed.

1. Steady: one process; one warm-up render per configuration (its time, kernel
   compilation included, is reported as "first render"; load time, table builds
   included, separately), then --repeats rounds in which every configuration
   renders once (round-robin), median per configuration (``dr.eval`` +
   ``dr.sync_thread``) of the wall-clock time and of the process's CPU time.
2. First image with an empty kernel cache (``render_bench.first_images``: a fresh
   process and ``DRJIT_CACHE_DIR`` per run, ``mi.load_dict`` + the first
   ``mi.render``, imports not timed; always 256x256, 16 spp), for ``conductor`` and
   every stack at default settings and exact; the run with the median total of
   --first-repeats.
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
from render_bench import first_image_table, first_images, mode_of, render_sync  # noqa: E402
from render_bench import scene_dict as base_scene_dict  # noqa: E402

VARIANT = "llvm_ad_spectral_polarized"
FILMS = (1, 2, 3, 10, 30)


def scene_dict(config: str, res=256, spp=16) -> dict:
    """``"conductor"`` or ``"L:exact"`` / ``"L:table"`` / ``"L:auto"``."""
    if config.endswith(":auto"):
        scene = base_scene_dict(config.replace(":auto", ":table"), res=res, spp=spp)
        del scene["sphere"]["bsdf"]["tabulate"]
        return scene
    return base_scene_dict(config, res=res, spp=spp)


def first_image_child(config: str, res: int, spp: int):
    """Runs in the subprocess: time mi.load_dict + first mi.render."""
    import mitsuba as mi
    mi.set_variant(VARIANT)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    scene = mi.load_dict(scene_dict(config, res, spp))
    t1 = time.perf_counter()
    render_sync(scene, seed=0)
    t2 = time.perf_counter()
    print(json.dumps({"load": t1 - t0, "render": t2 - t1, "mode": mode_of(scene)}))


def steady(films, args):
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(VARIANT)
    import thinfilm_mi  # noqa: F401

    configs = ["conductor"] + [f"{L}:{m}" for L in films for m in ("exact", "table", "auto")]
    scenes, first, load = {}, {}, {}
    for c in configs:
        t = time.perf_counter()
        scenes[c] = mi.load_dict(scene_dict(c, res=args.res, spp=args.spp))
        load[c] = time.perf_counter() - t
        t = time.perf_counter()
        render_sync(scenes[c], seed=0)
        first[c] = time.perf_counter() - t
        print(f"  {c}: load {load[c]:.2f} s, first render {first[c]:.2f} s, "
              f"mode {mode_of(scenes[c])}", file=sys.stderr, flush=True)
    ts = {c: [] for c in configs}
    cpu = {c: [] for c in configs}
    for i in range(args.repeats):
        for c in configs:
            t, p = time.perf_counter(), time.process_time()
            render_sync(scenes[c], seed=i + 1)
            ts[c].append(time.perf_counter() - t)
            cpu[c].append(time.process_time() - p)
    base, base_cpu = float(np.median(ts["conductor"])), float(np.median(cpu["conductor"]))
    print(f"\n### {VARIANT}: steady render time ({args.res}x{args.res}, {args.spp} spp, "
          f"median of {args.repeats} round-robin; Dr.Jit {dr.__version__}, "
          f"Mitsuba {mi.__version__})\n")
    print("Wall-clock time and the process's CPU time (all its threads; steadier than the "
          "wall clock on a shared machine).\n")
    print("| BSDF | films | tabulate | mode obtained | load (s) | render median (s) | min (s) "
          "| ratio to conductor | CPU median (s) | CPU ratio | first render incl. compile (s) |")
    print("|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for c in configs:
        med, mn, mc = float(np.median(ts[c])), float(np.min(ts[c])), float(np.median(cpu[c]))
        if c == "conductor":
            name, L, m = "conductor (Al)", "–", "–"
        else:
            name, (L, m) = "thinfilm_conductor", c.split(":")
        print(f"| {name} | {L} | {m} | {mode_of(scenes[c])} | {load[c]:.2f} | {med:.3f} | "
              f"{mn:.3f} | {med / base:.2f} | {mc:.3f} | {mc / base_cpu:.2f} | {first[c]:.2f} |")


def first(films, args):
    configs = ["conductor"] + [f"{L}:{m}" for L in films for m in ("auto", "exact")]
    out = first_images(__file__, configs, args.first_repeats)
    print(f"\n### {VARIANT}: first image, empty kernel cache (fresh process and "
          f"DRJIT_CACHE_DIR per run; the run with the median total of {args.first_repeats})\n")
    first_image_table(out, configs, asked="tabulate")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--first-repeats", type=int, default=3)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--films", default=",".join(map(str, FILMS)))
    ap.add_argument("--skip-steady", action="store_true")
    ap.add_argument("--skip-first", action="store_true")
    ap.add_argument("--first-image-child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.first_image_child:
        first_image_child(args.first_image_child, 256, 16)
        return
    films = [int(x) for x in args.films.split(",")]
    if not args.skip_steady:
        steady(films, args)
    if not args.skip_first:
        first(films, args)


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("polarized_bench"):   # --write-docs: docs/_generated/polarized_bench.md
        main()
