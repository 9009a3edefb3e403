"""Datasets on their own knots against datasets resampled on uniform grids: one
``sample()`` kernel of an exact stack, A/B in one process.

    python benchmarks/index_bench.py [--layers "SiO2 500"] [--plugin conductor]
                                     [--material Au] [--n 300000] [--rounds 11]

Two BSDFs of the same stack with ``tabulate=false`` are loaded in one process: one with
every dataset on its own knots (``irregular`` spectra; the resampling switched off while
it loads), one as the plugins load it (``regular`` spectra on the uniform grid of
``DispersiveMaterial.uniform_resampling``). Their ``sample()`` kernels run alternately
(the order swapped each round, the first round untimed) on one thread, so that the
machine's other load hits both alike; the figure is the minimum over the rounds of the
kernel's time per lane (Dr.Jit's kernel history), with the median beside it.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
# this checkout's package, not an installed one
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
os.environ.setdefault("THINFILM_MI_TABLE_CACHE", "off")


def load(spec: dict, resampled: bool):
    import mitsuba as mi

    from thinfilm_mi.materials.model import DispersiveMaterial
    original = DispersiveMaterial.uniform_resampling
    if not resampled:
        DispersiveMaterial.uniform_resampling = lambda self: None
    try:
        return mi.load_dict(spec)
    finally:
        DispersiveMaterial.uniform_resampling = original


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--layers", default="SiO2 500")
    ap.add_argument("--plugin", default="conductor", choices=("conductor", "dielectric"))
    ap.add_argument("--material", default="Au", help="the conductor's substrate")
    ap.add_argument("--n", type=int, default=300_000)
    ap.add_argument("--rounds", type=int, default=11)
    args = ap.parse_args()

    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    import sample_profile as sp

    import thinfilm_mi  # noqa: F401
    extra = {"int_ior": 1.6} if args.plugin == "dielectric" else {"material": args.material}
    spec = {"type": f"thinfilm_{args.plugin}", "layers": args.layers, "tabulate": False, **extra}
    bsdfs = {"own knots": load(spec, False), "uniform grid": load(spec, True)}
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    dr.set_thread_count(1)
    times = {k: [] for k in bsdfs}
    for r in range(args.rounds):
        order = list(bsdfs.items()) if r % 2 == 0 else list(bsdfs.items())[::-1]
        for name, bsdf in order:
            _, run_s, _ = sp.run(bsdf, args.n, r, True, True)
            if r:
                times[name].append(1e9 * run_s / args.n)
    print(f"thinfilm_{args.plugin} {args.layers!r} {extra}, sample() on {args.n} lanes, "
          f"one thread, {args.rounds - 1} rounds")
    for name, t in times.items():
        print(f"  {name:13s} min {min(t):6.1f} ns/lane, median {statistics.median(t):6.1f}")


if __name__ == "__main__":
    main()
