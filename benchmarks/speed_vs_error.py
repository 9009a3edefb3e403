"""Speed against accuracy of the three ways to get a stack's reflectance R.

    python benchmarks/speed_vs_error.py [--points 1000000] [--tmm-points 2000]
                                        [--repeats 7] [--material Al] [--stop-at-failure]

Stacks: 1, 3, 10 and 30 dielectric films alternating n = 2.3 / 1.46 with random
thicknesses 50-200 nm (``numpy.random.default_rng(6)``, drawn once for 30 films;
the L-film stack uses the first L) on a metal (default Al), ambient air
(1.000277, the plugins' default ``ext_ior``), through ``thinfilm_conductor``.

For each stack and way it reports the time per (cos theta, lambda) point and
the max / RMS absolute error in R against the float64 reference
(``thinfilm_mi.Stack(...).rt``) on the same points, and the max error outside
the grazing sliver (cos theta >= ``tabulate_base.GRAZING_COS``) that table builds verify:

* exact: ``bsdf.stack.reflectance(si, cos, active)`` with ``tabulate`` false,
  the float32 recursion as traced into the render kernels (llvm_ad_spectral,
  4 wavelengths per lane; --points (cos, lambda) pairs in all);
* table: the same call with ``tabulate`` true and ``table_error`` 1e-2, 3e-3,
  1e-3, 3e-4: the interpolation (cubic B-spline, or "bilinear KUxKV of a cubic": the
  spline resampled KU x KV times finer, thinfilm_mi/tabulate/bilinear.py; "split" where
  the angle axis is split at a critical angle), the spline's nu x nv, its build time
  (first build, which includes compiling the float64 build kernels, and a
  second build of the same stack with the table cache cleared), the verified
  error the build reports, and the measured errors. A stack whose sharp resonances cannot be resolved within
  ``policy.MAX_TEXELS`` texels and ``policy.MAX_BUILD_POINTS`` evaluations gets
  no table: the row says so. Every target is tried (a failing build took
  0.02-0.06 s in our runs: the probe rejects it); with --stop-at-failure
  the smaller targets of a stack are skipped once one has failed;
* band: the same call with ``tabulate`` true and the default ``spectral_resolution``
  (1 nm) at ``table_error`` 1e-2, 3e-3, 1e-3, for the stacks whose exact values
  no table resolves (10 and 30 films): a table of ``R_σ``, the exact ``R``
  convolved with a Gaussian in wavenumber (thinfilm_mi/tabulate/band.py). Its
  errors are against ``R_σ`` (what it approximates; against ``R`` a resonance
  far narrower than 1 nm makes them ~0.5 by design), computed by brute force on
  the first --band-points points: the build's float64 evaluator on a grid of
  0.002 nm over ±6 σ, a Gaussian-weighted sum. The colour check the build made
  (ΔE2000 of ``R_σ`` against ``R`` under D65 / A / F11) is in the row too. The
  "table" rows above pass ``spectral_resolution`` 0 (tables of the exact values);
* tmm: ``coh_tmm`` s + p on the first --tmm-points points, time per point.

Timings: median of --repeats runs after a warm-up run (kernel compiled; inputs
opaque), each ending with ``dr.eval`` + ``dr.sync_thread``. Writes a markdown
table to stdout and benchmarks/speed_vs_error.png (time vs max error, log-log).
"""
from __future__ import annotations

import argparse
import os
import time
import warnings

# builds are timed: no tables from the store on disk unless the environment names one
os.environ.setdefault("THINFILM_MI_TABLE_CACHE", "off")

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi as tf  # noqa: E402  (registers the plugins)
from thinfilm_mi.render import stack_build as tf_build  # noqa: E402
from thinfilm_mi.tabulate import base as tabulate_base  # noqa: E402
from thinfilm_mi.tabulate import policy  # noqa: E402
from thinfilm_mi.tabulate.band import sigma_nu  # noqa: E402

AMBIENT = 1.000277
ERRORS = (1e-2, 3e-3, 1e-3, 3e-4)
FILMS = (1, 3, 10, 30)
HERE = os.path.dirname(os.path.abspath(__file__))


def thicknesses(seed=6, n=max(FILMS)):
    return np.random.default_rng(seed).uniform(50.0, 200.0, n)


def films_of(L, d):
    return [(2.3 if i % 2 == 0 else 1.46, float(d[i])) for i in range(L)]


def layers_string(films):
    return "; ".join(f"{n} {t!r}" for n, t in films)


def band_reference(bsdf, cos64, wl64, n, step=0.002):
    """``R_σ`` at the first ``n`` points by brute force: the build's float64
    evaluator on a grid of ``step`` nm over ±6 σ_ν, Gaussian-weighted."""
    side = tf_build.side_data(bsdf.stack.plan[False], False)
    sig = sigma_nu(bsdf.stack.spectral_resolution)
    cos, wl = np.broadcast_to(cos64[None, :], wl64.shape).ravel()[:n], wl64.ravel()[:n]
    out = np.empty(n)
    for i in range(n):
        nu0 = 1.0 / wl[i]
        lam = np.arange(1.0 / (nu0 + 6 * sig), 1.0 / (nu0 - 6 * sig), step)
        R = tabulate_base.evaluate_side(side, np.full(lam.size, cos[i]), np.arange(lam.size), lam,
                                        tabulate_base.side_indices(side, lam))[:, 0]
        g = np.exp(-0.5 * ((1.0 / lam - nu0) / sig) ** 2) / (lam * lam)    # dν = dλ / λ²
        out[i] = float(np.sum(R * g) / np.sum(g))
    return out


def load(films, material, **kw):
    return mi.load_dict({"type": "thinfilm_conductor", "material": material,
                         "layers": layers_string(films), "ext_ior": AMBIENT, **kw})


def make_points(n_points, seed=1):
    """``n_points`` (cos, lambda) pairs as n_points/4 lanes of 4 wavelengths."""
    rng = np.random.default_rng(seed)
    lanes = n_points // 4
    cos = rng.uniform(0.0, 1.0, lanes)
    wl = rng.uniform(360.0, 830.0, (4, lanes))
    si = dr.zeros(mi.SurfaceInteraction3f, lanes)
    si.wavelengths = mi.Spectrum(*[mi.Float(w.astype(np.float32)) for w in wl])
    c = mi.Float(cos.astype(np.float32))
    dr.make_opaque(c, si.wavelengths)
    # the reference sees the float32-rounded inputs
    cos64 = np.array(c, dtype=np.float64)
    wl64 = np.array(si.wavelengths, dtype=np.float64)   # (4, lanes)
    return si, c, cos64, wl64


def time_reflectance(stack, si, cos, repeats):
    def run():
        R = stack.reflectance(si, cos, True)
        dr.eval(R)
        dr.sync_thread()
        return R
    R = run()   # warm-up: traces and compiles
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        run()
        ts.append(time.perf_counter() - t)
    return float(np.median(ts)), np.array(R, dtype=np.float64)


def errors(R, ref, cos=None):
    """Max and RMS |R - ref|; with ``cos``, also the max over the points outside
    the grazing sliver that table builds do not verify (cos >= GRAZING_COS)."""
    e = np.abs(R - ref)
    out = (float(e.max()), float(np.sqrt(np.mean(e * e))))
    if cos is None:
        return out
    keep = np.broadcast_to(cos >= tabulate_base.GRAZING_COS, e.shape)
    return out + (float(e[keep].max()),)


def time_tmm(films, material, cos64, wl64, n):
    import tmm
    ref_stack = tf.Stack(layers=films, substrate=material, ambient=AMBIENT)
    wl = wl64[0, :n]
    th = np.arccos(np.clip(cos64[:n], 0.0, 1.0))
    n0, fl, nsub = ref_stack.indices(wl)
    dl = [np.inf] + [d for _, d in films] + [np.inf]
    R = np.empty(n)
    t = time.perf_counter()
    for i in range(n):
        nl = [n0[i]] + [f[i] for f in fl] + [nsub[i]]
        rs = tmm.coh_tmm("s", nl, dl, th[i], wl[i])["R"]
        rp = tmm.coh_tmm("p", nl, dl, th[i], wl[i])["R"]
        R[i] = 0.5 * (rs + rp)
    per = (time.perf_counter() - t) / n
    ref = ref_stack.rt(wl, th).R
    return per, errors(R, ref)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--tmm-points", type=int, default=2000)
    ap.add_argument("--band-points", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--material", default="Al")
    ap.add_argument("--films", type=int, nargs="*", default=list(FILMS))
    ap.add_argument("--stop-at-failure", action="store_true")
    ap.add_argument("--png", default=os.path.join(HERE, "speed_vs_error.png"))
    args = ap.parse_args()
    warnings.simplefilter("ignore")   # "cannot be tabulated" warnings: reported in the table
    t_start = time.perf_counter()

    si, cos, cos64, wl64 = make_points(args.points)
    npts = wl64.size
    d = thicknesses()
    print(f"mitsuba {mi.__version__}, drjit {dr.__version__}, LLVM "
          f"{'.'.join(map(str, dr.detail.llvm_version()))}, {dr.thread_count()} threads; "
          f"{npts} (cos, lambda) points, median of {args.repeats}; substrate {args.material}; "
          f"MAX_TEXELS = {policy.MAX_TEXELS}\n")
    print("| films | method | table_error | nu x nv | build 1st / 2nd (s) | verified err "
          "| ns/pt | max err | max err, cos ≥ 0.02 | RMS err |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    results = []   # (L, method, ns, max_err)
    for L in args.films:
        films = films_of(L, d)
        ref = tf.Stack(layers=films, substrate=args.material, ambient=AMBIENT)
        ref_R = ref.rt(wl64, np.arccos(np.clip(cos64, 0.0, 1.0))[None, :]).R

        b = load(films, args.material, tabulate=False)
        t, R = time_reflectance(b.stack, si, cos, args.repeats)
        mx, rms, mx_v = errors(R, ref_R, cos64)
        ns = t / npts * 1e9
        results.append((L, "exact", ns, mx))
        print(f"| {L} | exact float32 | – | – | – | – | {ns:.2f} | {mx:.1e} | {mx_v:.1e} | "
              f"{rms:.1e} |", flush=True)

        failed = False
        for e in ERRORS:
            if failed and args.stop_at_failure:
                print(f"| {L} | table | {e:g} | **no table** (not tried: a larger "
                      f"table_error already failed) | – | – | – | – | – | – |", flush=True)
                continue
            tf_build.TABLE_CACHE.clear()
            t0 = time.perf_counter()
            b = load(films, args.material, tabulate=True, table_error=e, spectral_resolution=0.0)
            t_first = time.perf_counter() - t0
            tab = b.stack.plan[False].table
            if tab is None:
                failed = True
                print(f"| {L} | table | {e:g} | **no table** (target not met within "
                      f"the texel and build budgets; evaluated exactly) | {t_first:.2f} / – | – | – | – | – | – |",
                      flush=True)
                continue
            t_b = time.perf_counter()
            b0 = load(films, args.material, tabulate=False)
            t_noload = time.perf_counter() - t_b
            tf_build.TABLE_CACHE.clear()
            t0 = time.perf_counter()
            b = load(films, args.material, tabulate=True, table_error=e, spectral_resolution=0.0)
            t_second = time.perf_counter() - t0 - t_noload
            del b0
            tab = b.stack.plan[False].table
            t, R = time_reflectance(b.stack, si, cos, args.repeats)
            mx, rms, mx_v = errors(R, ref_R, cos64)
            ns = t / npts * 1e9
            results.append((L, f"table {e:g}", ns, mx))
            kind = (f"bilinear {tab.factors[0]}x{tab.factors[1]} of a cubic"
                    if tab.interpolation.name == "linear" else "cubic")
            kind += ", split" if tab.axis.split else ""
            print(f"| {L} | table ({kind}) | {e:g} | {tab.nu} x {tab.nv} | {t_first:.3f} / "
                  f"{t_second:.3f} | {tab.error:.1e} | {ns:.2f} | {mx:.1e} | {mx_v:.1e} | "
                  f"{rms:.1e} |", flush=True)

        if failed:
            band_rows(L, films, args, si, cos, cos64, wl64, results)

        per, (mx, rms) = time_tmm(films, args.material, cos64, wl64, args.tmm_points)
        results.append((L, "tmm", per * 1e9, mx))
        print(f"| {L} | tmm (float64) | – | – | – | – | {per * 1e9:.0f} | {mx:.1e} | – | "
              f"{rms:.1e} |", flush=True)
    print(f"\ntotal run time {time.perf_counter() - t_start:.0f} s")
    plot(results, args.png)


BAND_ERRORS = (1e-2, 3e-3, 1e-3)


def band_rows(L, films, args, si, cos, cos64, wl64, results):
    """The band-limited table rows of a stack (see the module docstring)."""
    n = args.band_points
    ref = None
    for e in BAND_ERRORS:
        tf_build.TABLE_CACHE.clear()
        t0 = time.perf_counter()
        b = load(films, args.material, tabulate=True, table_error=e)
        t_build = time.perf_counter() - t0
        tab = b.stack.plan[False].table
        stats = b.stack.plan[False].build_report
        if tab is not None and tab.resolution == 0:
            print(f"| {L} | band | {e:g} | a table of the exact values meets this target "
                  "(row above) | – | – | – | – | – | – |", flush=True)
            continue
        if tab is None:
            print(f"| {L} | band | {e:g} | **no table** ({stats['result']}) | {t_build:.2f} "
                  "| – | – | – | – | – |", flush=True)
            continue
        if ref is None:
            ref = band_reference(b, cos64, wl64, n)
        t, R = time_reflectance(b.stack, si, cos, args.repeats)
        got = R.ravel()[:n]
        keep = np.broadcast_to(cos64[None, :], wl64.shape).ravel()[:n] >= tabulate_base.GRAZING_COS
        err = np.abs(got - ref)
        ns = t / wl64.size * 1e9
        colours = " / ".join(f"{v:.3f}" for v in stats["colour_errors"].values())
        results.append((L, f"band {e:g}", ns, float(err.max())))
        print(f"| {L} | band (σ 1 nm; errors vs R_σ, {n} pts; colour ΔE {colours}) | {e:g} | "
              f"{tab.nu} x {tab.nv} | {t_build:.3f} | {tab.error:.1e} | {ns:.2f} | "
              f"{err.max():.1e} | {err[keep].max():.1e} | {np.sqrt(np.mean(err ** 2)):.1e} |",
              flush=True)


def plot(results, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    markers = {"exact": "o", "tmm": "s"}
    colours = {L: c for L, c in zip(FILMS, ("C0", "C1", "C2", "C3"))}
    for L in sorted({r[0] for r in results}):
        rows = [r for r in results if r[0] == L]
        tab = [r for r in rows if r[1].startswith("table")]
        if tab:
            ax.plot([r[3] for r in tab], [r[2] for r in tab], "-^", color=colours.get(L),
                    label=f"{L} films: table")
        band = [r for r in rows if r[1].startswith("band")]
        if band:
            ax.plot([r[3] for r in band], [r[2] for r in band], "--v", color=colours.get(L),
                    label=f"{L} films: band table (vs R_σ)")
        for r in rows:
            if r[1] in markers:
                ax.plot(max(r[3], 1e-17), r[2], markers[r[1]], color=colours.get(L),
                        mfc="none" if r[1] == "tmm" else None,
                        label=f"{L} films: {r[1]}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("max |R - R_float64|")
    ax.set_ylabel("time per (cos θ, λ) point [ns]")
    ax.set_title("Reflectance: exact float32 kernel, tables, band tables, tmm")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {os.path.relpath(path)}")


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("speed_vs_error"):   # --write-docs: docs/_generated/speed_vs_error.md
        main()
