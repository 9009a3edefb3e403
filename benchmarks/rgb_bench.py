"""RGB and mono variants: render time of ``thinfilm_conductor`` against Mitsuba's
``conductor``, and the load-time cost of the colour tables of every plugin.

    python benchmarks/rgb_bench.py [--quick] [--repeats 9] [--res 256] [--spp 16]
                                   [--variants llvm_ad_rgb,llvm_ad_mono] [--films 1,2,3,10,30]
                                   [--build-repeats 5] [--build-films 1,2,3,10,30]
                                   [--build-variant llvm_ad_rgb] [--stack random|periodic]
                                   [--skip-render] [--skip-build]

In RGB and mono variants every stack's ``R`` (and ``T``) integrated against colour
matching is tabulated over the angle when the scene loads
(``thinfilm_mi/tabulate/integrated.py``; ``thinfilm_mi/tabulate/diffuse.py`` for
``thinfilm_diffuse``), so at render time a deep stack costs one texture lookup,
whatever its depth. One process, two parts:

1. Render time. The scene of ``render_bench.py`` (a sphere on a diffuse floor under
   a constant emitter, path integrator, max_depth 8, --res x --res, --spp spp);
   the sphere is Mitsuba's ``conductor`` (Al) or ``thinfilm_conductor`` on Al with
   --films films. For each of --variants (``mi.set_variant`` in the same process):
   every scene is loaded (its colour tables built) and rendered once (warm-up:
   compiles; reported as "first"), then --repeats rounds in which every
   configuration renders once (round-robin, the order reversed every other round,
   so that a slow spell of the shared machine and the position in a round hit all
   alike), different seeds; median per configuration (``dr.eval`` +
   ``dr.sync_thread``), ratio to ``conductor``'s median in the same variant. "first"
   includes compiling the kernel, or reading it from Dr.Jit's disk cache if an
   earlier run compiled it (in RGB/mono the kernel does not depend on the depth).
2. Table build. ``mi.load_dict`` of the BSDF alone (plus ``dr.sync_thread``) for each
   of the five plugins and --build-films depths in --build-variant. Every load in
   this part uses a stack of its own (every thickness shifted by a distinct
   multiple of 0.01 nm, at most 1.5 nm in the default run: the same optics to the
   eye), so the colour-table cache (keyed by the optics) never serves one (the rough
   plugins would otherwise get the smooth ones' tables); the render part's stacks
   are not shifted. First a warm-up load per (plugin, depth), with a stack of its own too,
   which takes the process's one-off costs (imports, Dr.Jit kernels compiled or
   read from the disk cache for that depth), then --build-repeats round-robin
   rounds; median per (plugin, depth). The kernels compiled during the timed loads
   (``dr.JitFlag.KernelHistory``: JIT kernels neither in the in-memory nor the disk
   cache) are counted: they are part of the build's cost.

Stacks (--stack): ``random`` (default), the stacks of ``render_bench.py`` and
``polarized_bench.py`` (alternating n = 2.3 / 1.46, thicknesses 50-200 nm from
``numpy.random.default_rng(6)``), or ``periodic``: ``"2.3 60; 1.46 90"`` repeated
(a Bragg mirror, as in the issue). Conductors are on Al; ``thinfilm_dielectric``
and ``thinfilm_roughdielectric`` on their default interior (BK7), ``thinfilm_diffuse``
on its default base (0.5), the rough plugins with their default roughness (0.1).

The output tables are Markdown, for benchmarks/README.md; progress goes to stderr.
--quick: a smoke run (64x64, 4 spp, 2 rounds, 1 and 30 films; builds of 1 and 3
films, 2 rounds), a few tens of seconds.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from render_bench import render_sync, scene_dict, thicknesses  # noqa: E402

VARIANTS = ("llvm_ad_rgb", "llvm_ad_mono")
FILMS = (1, 2, 3, 10, 30)
PLUGINS = ("thinfilm_conductor", "thinfilm_dielectric", "thinfilm_diffuse",
           "thinfilm_roughconductor", "thinfilm_roughdielectric")
#: Targets of the issue (numbers to report, not tests).
TARGET_RATIO_30 = 1.05
TARGET_BUILD_SHALLOW = 0.1   # s, 1-3 films
TARGET_BUILD_DEEP = 1.0      # s, 30 films
#: Thickness shift (nm) between two stacks of the build part.
SHIFT = 0.01


def layers(n: int, stack: str = "random", shift: float = 0.0) -> str:
    """``n`` alternating 2.3 / 1.46 films, every thickness + ``shift`` nm."""
    if stack == "periodic":
        d = [60.0 if i % 2 == 0 else 90.0 for i in range(n)]
    else:
        d = [float(x) for x in thicknesses()[:n]]
    return "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {round(d[i] + shift, 6)!r}"
                     for i in range(n))


def bsdf(plugin: str, n: int, stack: str, shift: float = 0.0) -> dict:
    d = {"type": plugin, "layers": layers(n, stack, shift)}
    if "conductor" in plugin:
        d["material"] = "Al"
    return d


def render_scene(config: str, stack: str, res: int, spp: int) -> dict:
    """``"conductor"`` or the number of films of ``thinfilm_conductor`` on Al."""
    import mitsuba as mi
    d = scene_dict("conductor", res=res, spp=spp)
    if mi.is_monochromatic:   # what HDRFilm would switch to, with a warning
        d["sensor"]["film"]["pixel_format"] = "luminance"
    if config != "conductor":
        d["sphere"]["bsdf"] = bsdf("thinfilm_conductor", int(config), stack)
    return d


def new_kernels(history) -> int:
    import drjit as dr
    return sum(1 for h in history if h.get("type") == dr.KernelType.JIT
               and not h.get("cache_hit") and not h.get("cache_disk"))


# -- 1. render time ---------------------------------------------------------------
def render_part(variant: str, films, repeats: int, res: int, spp: int, stack: str) -> dict:
    import mitsuba as mi
    mi.set_variant(variant)
    configs = ["conductor"] + [str(n) for n in films]
    scenes, first, load = {}, {}, {}
    for c in configs:
        t = time.perf_counter()
        scenes[c] = mi.load_dict(render_scene(c, stack, res, spp))
        load[c] = time.perf_counter() - t
        t = time.perf_counter()
        render_sync(scenes[c], seed=0)   # warm-up: compiles
        first[c] = time.perf_counter() - t
        print(f"  {variant} {c}: load {load[c]:.2f} s, first render {first[c]:.2f} s",
              file=sys.stderr, flush=True)
    ts = {c: [] for c in configs}
    for i in range(repeats):
        for c in (configs if i % 2 == 0 else configs[::-1]):
            t = time.perf_counter()
            render_sync(scenes[c], seed=i + 1)
            ts[c].append(time.perf_counter() - t)
    out = {c: {"median": float(np.median(ts[c])), "min": float(np.min(ts[c])),
               "first": first[c], "load": load[c]} for c in configs}
    base = out["conductor"]["median"]
    for c in configs:
        out[c]["ratio"] = out[c]["median"] / base
        print(f"  {variant} {c}: median {out[c]['median']:.3f} s, min {out[c]['min']:.3f} s, "
              f"ratio {out[c]['ratio']:.2f}", file=sys.stderr, flush=True)
    return out


def print_render(results: dict, films, repeats: int, res: int, spp: int, stack: str):
    variants = list(results)
    short = {v: v.replace("llvm_ad_", "") for v in variants}
    print(f"\n### Render time against Mitsuba's `conductor` (Al): {res}x{res}, {spp} spp, "
          f"path max_depth 8, median of {repeats} round-robin rounds, {stack} stacks\n")
    head = "| BSDF | films |" + "".join(
        f" {short[v]}: median (s) | {short[v]}: ratio | {short[v]}: first render (s) |"
        for v in variants)
    print(head)
    print("|---|---:|" + "---:|---:|---:|" * len(variants))
    for c in ["conductor"] + [str(n) for n in films]:
        name, n = ("conductor (Al)", "–") if c == "conductor" else ("thinfilm_conductor", c)
        row = f"| {name} | {n} |"
        for v in variants:
            r = results[v][c]
            row += f" {r['median']:.3f} | {r['ratio']:.2f} | {r['first']:.2f} |"
        print(row)
    print()
    for v in variants:
        deepest = str(max(films))
        r = results[v][deepest]["ratio"]
        verdict = "met" if r <= TARGET_RATIO_30 else "not met"
        target = f" (target for 30 films in llvm_ad_rgb: <= {TARGET_RATIO_30:.2f}x, {verdict})" \
            if v == "llvm_ad_rgb" and deepest == "30" else ""
        print(f"{v}: {deepest} films {r:.2f}x `conductor`{target}; scene loads "
              + ", ".join(f"{c}: {results[v][c]['load']:.2f} s" for c in results[v]))


# -- 2. table build ---------------------------------------------------------------
def build_part(variant: str, films, repeats: int, stack: str) -> dict:
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(variant)
    configs = [(p, n) for p in PLUGINS for n in films]
    shift = [0]

    def load(p, n):
        shift[0] += 1          # a stack of its own: the colour-table cache cannot serve it
        d = bsdf(p, n, stack, SHIFT * shift[0])
        dr.kernel_history()    # clear
        t = time.perf_counter()
        b = mi.load_dict(d)
        dr.sync_thread()
        dt = time.perf_counter() - t
        return b, dt, new_kernels(dr.kernel_history())

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        first = {}
        for c in configs:
            _, first[c], k = load(*c)
            print(f"  build {c[0]} {c[1]}: warm-up load {first[c]:.3f} s ({k} kernels "
                  "compiled)", file=sys.stderr, flush=True)
        ts = {c: [] for c in configs}
        kernels = {c: 0 for c in configs}
        for i in range(repeats):
            for c in (configs if i % 2 == 0 else configs[::-1]):
                _, dt, k = load(*c)
                ts[c].append(dt)
                kernels[c] += k
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    out = {c: {"median": float(np.median(ts[c])), "max": float(np.max(ts[c])),
               "first": first[c], "kernels": kernels[c]} for c in configs}
    for c in configs:
        print(f"  build {c[0]} {c[1]}: median {out[c]['median']:.3f} s, max "
              f"{out[c]['max']:.3f} s, {out[c]['kernels']} kernels compiled in "
              f"{repeats} loads", file=sys.stderr, flush=True)
    return out


def print_build(out: dict, films, repeats: int, variant: str, stack: str):
    print(f"\n### Table build: `mi.load_dict` of the BSDF (s), {variant}, median of "
          f"{repeats} round-robin loads, every load a new stack ({stack} stacks)\n")
    print("| plugin |" + "".join(f" {n} film{'s' if n > 1 else ''} |" for n in films)
          + " kernels compiled in the timed loads |")
    print("|---|" + "---:|" * len(films) + "---:|")
    for p in PLUGINS:
        print(f"| {p} |" + "".join(f" {out[(p, n)]['median']:.3f} |" for n in films)
              + f" {sum(out[(p, n)]['kernels'] for n in films)} |")
    print("\nwarm-up load (first at each depth: one-off imports, kernels compiled or read "
          "from the disk cache): "
          + "; ".join(f"{p}: " + ", ".join(f"{out[(p, n)]['first']:.2f}" for n in films)
                      for p in PLUGINS) + " s")
    shallow = [n for n in films if n <= 3]
    lines = []
    if shallow:
        worst = max((out[(p, n)]["median"], p, n) for p in PLUGINS for n in shallow)
        lines.append(f"1-3 films <= {TARGET_BUILD_SHALLOW} s: "
                     + ("met" if worst[0] <= TARGET_BUILD_SHALLOW else "not met")
                     + f" (slowest: {worst[1]}, {worst[2]} films, {worst[0]:.3f} s)")
    if 30 in films:
        slow = [f"{p} {out[(p, 30)]['median']:.2f} s" for p in PLUGINS
                if out[(p, 30)]["median"] > TARGET_BUILD_DEEP]
        lines.append(f"30 films <= {TARGET_BUILD_DEEP} s: "
                     + ("met" if not slow else "not met: " + ", ".join(slow)))
    if lines:
        print("\ntargets: " + "; ".join(lines))


def ints(s: str):
    return tuple(int(x) for x in s.split(",") if x.strip())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: tiny sizes and few rounds (overrides the sizes below)")
    ap.add_argument("--repeats", type=int, default=9, help="render rounds (default 9)")
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--films", type=ints, default=FILMS, help="render part, e.g. 1,2,3,10,30")
    ap.add_argument("--build-repeats", type=int, default=5)
    ap.add_argument("--build-films", type=ints, default=FILMS)
    ap.add_argument("--build-variant", default="llvm_ad_rgb")
    ap.add_argument("--stack", choices=("random", "periodic"), default="random")
    ap.add_argument("--skip-render", action="store_true")
    ap.add_argument("--skip-build", action="store_true")
    args = ap.parse_args(argv)
    sys.stdout.reconfigure(line_buffering=True)   # tables and stderr progress in order
    if args.quick:
        args.repeats, args.res, args.spp, args.films = 2, 64, 4, (1, 30)
        args.build_repeats, args.build_films = 2, (1, 3)

    import drjit as dr
    import mitsuba as mi
    variants = [v for v in args.variants.split(",") if v]
    mi.set_variant(variants[0] if not args.skip_render else args.build_variant)
    import thinfilm_mi  # noqa: F401  (registers the plugins, again at every set_variant)
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    print(f"Mitsuba {mi.__version__}, Dr.Jit {dr.__version__}, {dr.thread_count()} threads, "
          f"{os.cpu_count()} CPUs" + (" (--quick)" if args.quick else ""))
    if not args.skip_render:
        results = {v: render_part(v, args.films, args.repeats, args.res, args.spp, args.stack)
                   for v in variants}
        print_render(results, args.films, args.repeats, args.res, args.spp, args.stack)
    if not args.skip_build:
        out = build_part(args.build_variant, args.build_films, args.build_repeats, args.stack)
        print_build(out, args.build_films, args.build_repeats, args.build_variant, args.stack)
    print(f"\ntotal run time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("rgb_bench"):   # --write-docs: docs/_generated/rgb_bench.md
        main()
