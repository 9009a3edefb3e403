"""RGB and mono variants: the load-time cost of the colour tables of every plugin.

    python benchmarks/rgb_bench.py [--quick] [--build-repeats 5] [--build-films 1,2,3,10,30]
                                   [--build-variant llvm_ad_rgb] [--stack random|periodic]

In RGB and mono variants every stack's ``R`` (and ``T``) integrated against colour
matching is tabulated over the angle when the scene loads
(``thinfilm_mi/tabulate/integrated.py``; ``thinfilm_mi/tabulate/diffuse.py`` for
``thinfilm_diffuse``), so at render time a deep stack costs one texture lookup,
whatever its depth; what that costs against each plugin's Mitsuba counterpart, at every
depth, is ``render_bench.py``'s (its steady part in ``llvm_ad_rgb`` and ``llvm_ad_mono``).
Here the build, which Mitsuba's plugins have no counterpart of: ``mi.load_dict`` of the
BSDF alone (plus ``dr.sync_thread``) for each BSDF plugin (with the settings of
``timing.COUNTERPARTS``: conductors on Al, dielectrics on 1.6, ``thinfilm_diffuse`` on 0.5,
the rough ones at α 0.2, ``thinfilm_coating`` over rough Al) and --build-films depths in
--build-variant. Every load uses a stack of its own (every thickness shifted by a
distinct multiple of 0.01 nm, at most 1.8 nm in the default run: the same optics to the
eye), so the colour-table cache (keyed by the optics) never serves one (the rough plugins
would otherwise get the smooth ones' tables). First a warm-up load per (plugin, depth),
with a stack of its own too, which takes the process's one-off costs (imports, Dr.Jit
kernels compiled or read from the disk cache for that depth), then --build-repeats
round-robin rounds; median per (plugin, depth). The kernels compiled during the timed
loads (``dr.JitFlag.KernelHistory``: JIT kernels neither in the in-memory nor the disk
cache) are counted: they are part of the build's cost. No render: the loaded BSDFs are
dropped, and nothing here is timed against a render.

Stacks (--stack): ``random`` (default), the stacks of ``render_bench.py``
(alternating n = 2.3 / 1.46, thicknesses 50-200 nm from ``numpy.random.default_rng(6)``),
or ``periodic``: ``"2.3 60; 1.46 90"`` repeated (a Bragg mirror, as in the issue).

The output tables are Markdown, for benchmarks/README.md; progress goes to stderr.
--quick: a smoke run (builds of 1 and 3 films, 2 rounds), a few seconds.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from render_bench import thicknesses  # noqa: E402
from timing import COUNTERPARTS  # noqa: E402

FILMS = (1, 2, 3, 10, 30)
#: every BSDF plugin, with the settings it is timed at against its counterpart
PLUGINS = tuple(COUNTERPARTS)
#: Targets of the issue (numbers to report, not tests).
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
    return COUNTERPARTS[plugin].ours(layers(n, stack, shift))


def new_kernels(history) -> int:
    import drjit as dr
    return sum(1 for h in history if h.get("type") == dr.KernelType.JIT
               and not h.get("cache_hit") and not h.get("cache_disk"))


# -- the table build ---------------------------------------------------------------
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
                    help="smoke run: few depths and rounds (overrides the options below)")
    ap.add_argument("--build-repeats", type=int, default=5)
    ap.add_argument("--build-films", type=ints, default=FILMS)
    ap.add_argument("--build-variant", default="llvm_ad_rgb")
    ap.add_argument("--stack", choices=("random", "periodic"), default="random")
    args = ap.parse_args(argv)
    sys.stdout.reconfigure(line_buffering=True)   # tables and stderr progress in order
    if args.quick:
        args.build_repeats, args.build_films = 2, (1, 3)

    import drjit as dr
    import mitsuba as mi
    mi.set_variant(args.build_variant)
    import thinfilm_mi  # noqa: F401  (registers the plugins)
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    print(f"Mitsuba {mi.__version__}, Dr.Jit {dr.__version__}, {dr.thread_count()} threads, "
          f"{os.cpu_count()} CPUs" + (" (--quick)" if args.quick else ""))
    out = build_part(args.build_variant, args.build_films, args.build_repeats, args.stack)
    print_build(out, args.build_films, args.build_repeats, args.build_variant, args.stack)
    print(f"\ntotal run time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("rgb_bench"):   # --write-docs: docs/_generated/rgb_bench.md
        main()
