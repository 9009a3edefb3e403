"""Where one ``sample()`` of a thin-film BSDF spends its time: the kernel's size, the
table lookups and exact recursions it traces, and its cost per sample against
Mitsuba's counterpart.

    python benchmarks/sample_profile.py [--n 1000000] [--repeats 9]
                                        [--variant llvm_ad_spectral] [--plugins dielectric]

For each configuration one kernel evaluates ``bsdf.sample`` (and, for the plugins
with a non-delta lobe, ``bsdf.eval_pdf``) on ``--n`` directions drawn uniformly
over the sphere (half of them from inside, where the plugin has one), at 4
wavelengths drawn uniformly over 360-830 nm per lane. While the kernel is traced,
calls are counted (per lane: every traced call runs for every lane):

* ``lookups``: cubic lookups of a table of ``R`` [, ``T``] (one per wavelength;
  ``x channels`` is what each lookup interpolates), and bilinear reads of
  ``thinfilm_diffuse``'s factor table (one per wavelength: 4 channels, ``k_r``, ``t``,
  ``R_dh``, ``T_hemi``, at ``θ_i``; 1, ``t``, at ``θ_o``; ``tabulate/factors.py``), as
  traced: the kernel reads once what several calls read alike (Dr.Jit merges them);
* ``recursions``: exact evaluations of a side's films (the unrolled recursion or
  the film loop), each over all the wavelengths of the lane.

``ops`` is the operation count of the launched kernel (``dr.JitFlag.KernelHistory``);
``kernel ns/sample`` its execution time (from the same history) per lane, the median over
``--repeats`` rounds, every configuration once per
round (round-robin, fresh inputs each round, kernels compiled in a warm-up), and
``ratio`` that median over the counterpart's; ``trace + launch`` is the rest of
the wall clock (Python tracing the calls, a kernel-cache lookup), paid again by every
``mi.render`` in a JIT variant. On the shared machine read the ratios, not the
nanoseconds.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time

import numpy as np

# this checkout's package, not an installed one
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

STACK = "SiO2 500"
METALS = "SiO2 500; Au 20; Al 10"

#: name -> (Mitsuba counterpart, [(label, thin-film dict)])
CONFIGS = {
    "dielectric": ({"type": "dielectric", "int_ior": 1.6}, [
        ("no films", {"type": "thinfilm_dielectric", "int_ior": 1.6}),
        (f"{STACK} (auto)", {"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": STACK}),
        (f"{STACK} exact", {"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": STACK,
                            "tabulate": False}),
        (f"{METALS} (auto)", {"type": "thinfilm_dielectric", "int_ior": 1.6,
                              "layers": METALS}),
        (f"{METALS} exact", {"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": METALS,
                             "tabulate": False}),
    ]),
    "roughdielectric": ({"type": "roughdielectric", "int_ior": 1.6, "alpha": 0.2}, [
        ("no films", {"type": "thinfilm_roughdielectric", "int_ior": 1.6, "alpha": 0.2}),
        (f"{STACK} (auto)", {"type": "thinfilm_roughdielectric", "int_ior": 1.6,
                             "alpha": 0.2, "layers": STACK}),
    ]),
    "diffuse": ({"type": "diffuse"}, [
        ("SiO2 500; Au 5 exact model", {"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"}),
        ("SiO2 500; Au 5 single model", {"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5",
                                         "model": "single"}),
    ]),
    "conductor": ({"type": "conductor", "material": "Au"}, [
        (f"{STACK} on Au (auto)", {"type": "thinfilm_conductor", "material": "Au",
                                   "layers": STACK}),
    ]),
}


class Counter:
    """Counts the table lookups and exact side evaluations traced."""

    def __init__(self):
        self.lookups = 0
        self.texels = 0
        self.recursions = 0

    @contextlib.contextmanager
    def patched(self):
        from thinfilm_mi.render import side_eval
        from thinfilm_mi.render.loop import LoopFilms
        from thinfilm_mi.tabulate import base, factors

        orig_lookup, orig_rt = base.Table.lookup_channels, side_eval.exact_rt
        orig_loop = LoopFilms.rt
        orig_factors = factors.FactorTable.lookup
        counter = self

        def factor_lookup(table, cos_theta, cells, active=True, reflectance=True):
            counter.lookups += len(cells)
            counter.texels += len(cells) * (4 if reflectance else 1)
            return orig_factors(table, cos_theta, cells, active, reflectance)

        def lookup_channels(table, cos_i, n0, n_exit, wavelengths, *a, **k):
            counter.lookups += len(wavelengths)
            counter.texels += len(wavelengths) * table.channels
            return orig_lookup(table, cos_i, n0, n_exit, wavelengths, *a, **k)

        def rt(*a, **k):
            counter.recursions += 1
            return orig_rt(*a, **k)

        def loop_rt(loop, *a, **k):
            counter.recursions += 1
            return orig_loop(loop, *a, **k)

        base.Table.lookup_channels, side_eval.exact_rt, LoopFilms.rt = lookup_channels, rt, loop_rt
        factors.FactorTable.lookup = factor_lookup
        try:
            yield self
        finally:
            base.Table.lookup_channels, side_eval.exact_rt = orig_lookup, orig_rt
            LoopFilms.rt = orig_loop
            factors.FactorTable.lookup = orig_factors


def inputs(n: int, seed: int, two_sided: bool):
    import drjit as dr
    import mitsuba as mi

    # Dr.Jit maps a NumPy array's memory as it is, and compiles its loads with `align 1`
    # where that address is not 64-byte aligned: the kernel's hash then followed NumPy's
    # allocator, and about every other call recompiled (~0.4 s of LLVM backend for the
    # exact stacks' kernels). An array that a kernel computed is Dr.Jit's own, aligned.
    one = dr.opaque(mi.Float, 1.0)

    def F(values):
        return mi.Float(values) * one

    rng = np.random.default_rng(seed)
    z = rng.uniform(-1.0 if two_sided else 0.0, 1.0, n)
    phi = rng.uniform(0.0, 2 * np.pi, n)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(F(r * np.cos(phi)), F(r * np.sin(phi)), F(z))
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    si.wavelengths = mi.UnpolarizedSpectrum(*[F(rng.uniform(360.0, 830.0, n))
                                              for _ in range(4)])
    s1 = F(rng.uniform(0.0, 1.0, n))
    s2 = mi.Point2f(F(rng.uniform(0.0, 1.0, n)), F(rng.uniform(0.0, 1.0, n)))
    z2 = rng.uniform(0.0, 1.0, n)
    r2 = np.sqrt(1.0 - z2 * z2)
    wo = mi.Vector3f(F(r2 * np.cos(phi + 1.0)), F(r2 * np.sin(phi + 1.0)), F(z2))
    dr.eval(si, s1, s2, wo)
    return si, s1, s2, wo


def kernel_outputs(bsdf, si, s1, s2, wo, smooth: bool):
    import mitsuba as mi

    ctx = mi.BSDFContext()
    bs, w = bsdf.sample(ctx, si, s1, s2)
    out = [bs.wo, bs.pdf, w]
    if not smooth:
        out += list(bsdf.eval_pdf(ctx, si, wo))
    return out


def run(bsdf, n, seed, smooth, two_sided):
    import drjit as dr

    si, s1, s2, wo = inputs(n, seed, two_sided)
    dr.sync_thread()
    dr.kernel_history()
    t0 = time.perf_counter()
    out = kernel_outputs(bsdf, si, s1, s2, wo, smooth)
    dr.eval(*out)
    dr.sync_thread()
    dt = time.perf_counter() - t0
    hist = [h for h in dr.kernel_history() if h.get("type") == dr.KernelType.JIT]
    ops = max((h.get("operation_count", 0) for h in hist), default=0)
    run_s = sum(h.get("execution_time", 0.0) for h in hist) * 1e-3
    return dt - run_s, run_s, ops


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--variant", default="llvm_ad_spectral")
    ap.add_argument("--plugins", default=",".join(CONFIGS))
    args = ap.parse_args()

    import drjit as dr
    import mitsuba as mi
    mi.set_variant(args.variant)
    import thinfilm_mi  # noqa: F401
    dr.set_flag(dr.JitFlag.KernelHistory, True)

    rows = []   # (group, label, bsdf, smooth, two_sided, counts)
    for group in args.plugins.split(","):
        native, ours = CONFIGS[group]
        smooth = group in ("dielectric", "conductor")
        two_sided = "dielectric" in group
        rows.append((group, f"`{native['type']}`", mi.load_dict(native), smooth, two_sided, None))
        for label, d in ours:
            bsdf = mi.load_dict(d)
            c = Counter()
            with c.patched():
                run(bsdf, 1024, 0, smooth, two_sided)   # traced here: counted once
            mode = bsdf.stack.mode() if hasattr(bsdf, "stack") else bsdf.coating.mode()
            if getattr(getattr(bsdf, "coated", None), "table", None) is not None:
                mode = "factor table"   # thinfilm_diffuse reads its model's table instead
            rows.append((group, f"`{d['type']}` {label} [{mode}]", bsdf, smooth, two_sided, c))
    for r in rows:
        run(r[2], args.n, 0, r[3], r[4])   # warm-up: compiles
    times = {i: [] for i in range(len(rows))}
    traces = {i: [] for i in range(len(rows))}
    ops = {}
    for k in range(args.repeats):
        order = range(len(rows)) if k % 2 == 0 else reversed(range(len(rows)))
        for i in order:
            tr, dt, ops[i] = run(rows[i][2], args.n, k + 1, rows[i][3], rows[i][4])
            times[i].append(dt)
            traces[i].append(tr)
    print(f"mitsuba {mi.__version__}, drjit {dr.__version__}, {args.variant}, "
          f"{dr.thread_count()} threads, {args.n} lanes, median of {args.repeats}\n")
    print("| configuration | lookups per lane (channel reads) | recursions per lane | kernel ops "
          "| kernel ns/sample | ratio | trace + launch (ms) |")
    print("|---|---|---:|---:|---:|---:|---:|")
    base = None
    for i, (group, label, _, _, _, c) in enumerate(rows):
        med = float(np.median(times[i])) / args.n * 1e9
        tr = float(np.median(traces[i])) * 1e3
        if c is None:
            base = med
            print(f"| {label} | – | – | {ops[i]} | {med:.1f} | 1.00 | {tr:.1f} |")
        else:
            ch = f"{c.lookups} ({c.texels})" if c.lookups else "0"
            print(f"| {label} | {ch} | {c.recursions} | {ops[i]} | {med:.1f} | {med / base:.2f} "
                  f"| {tr:.1f} |")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
