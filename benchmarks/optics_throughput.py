"""Throughput of the float32 optics core (drjit.llvm.Float) against tmm.

    python benchmarks/optics_throughput.py [--points 4000000] [--tmm-points 2000]

For 1, 3, 10 and 30 films (alternating n = 2.35 / 1.46 dielectric films of 60 /
95 nm on glass n = 1.52, ambient air, constant indices traced as literals) it
evaluates Rs, Rp, Ts, Tp on N random (theta, lambda) points with
``optics.stack_rt`` and reports nanoseconds per point, after a warm-up run that
compiles the kernel (inputs are opaque, so the timed runs reuse it; each run
ends with dr.eval + dr.sync_thread). tmm (``coh_tmm`` for s and p, which
returns R and T together) runs on a subsample of the same points in the same
process and is extrapolated per point. The table prints the ratio.
"""
from __future__ import annotations

import argparse
import math
import time

import drjit as dr
import numpy as np
from drjit.llvm import Float

from thinfilm_mi.optics import core as optics


def stack(L):
    return [((2.35, 60.0) if i % 2 == 0 else (1.46, 95.0)) for i in range(L)]


def time_core(films, cos0, wl, repeats):
    def run():
        out = optics.stack_rt(1.0, cos0, films, 1.52, wl)
        dr.eval(*out)
        dr.sync_thread()
    run()  # warm-up: traces and compiles
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        run()
        ts.append(time.perf_counter() - t)
    return min(ts), float(np.median(ts))


def time_tmm(films, theta, wl):
    import tmm
    nl = [1.0] + [n for n, _ in films] + [1.52]
    dl = [np.inf] + [d for _, d in films] + [np.inf]
    t = time.perf_counter()
    for th, w in zip(theta, wl):
        tmm.coh_tmm("s", nl, dl, th, w)
        tmm.coh_tmm("p", nl, dl, th, w)
    return (time.perf_counter() - t) / len(theta)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=4_000_000)
    ap.add_argument("--tmm-points", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=10)
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    theta = rng.uniform(0, math.pi / 2, args.points)
    wl = rng.uniform(360.0, 830.0, args.points)
    cos0 = Float(np.cos(theta).astype(np.float32))
    wl_f = Float(wl.astype(np.float32))
    dr.make_opaque(cos0, wl_f)
    print(f"drjit {dr.__version__}, LLVM {'.'.join(map(str, dr.detail.llvm_version()))}, "
          f"{dr.thread_count()} threads, {args.points} points (s + p, R and T)")
    print(f"{'films':>5} | {'core ns/pt (min)':>16} | {'median':>8} | {'tmm us/pt':>9} | {'ratio':>9}")
    print("-" * 62)
    for L in (1, 3, 10, 30):
        films = stack(L)
        tmin, tmed = time_core(films, cos0, wl_f, args.repeats)
        per_core = tmin / args.points
        per_tmm = time_tmm(films, theta[: args.tmm_points], wl[: args.tmm_points])
        print(f"{L:>5} | {per_core * 1e9:>16.2f} | {tmed / args.points * 1e9:>8.2f} | "
              f"{per_tmm * 1e6:>9.1f} | {per_tmm / per_core:>8.0f}x")


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("optics_throughput"):   # --write-docs: docs/_generated/optics_throughput.md
        main()
