"""The spread of ``thinfilm_coating``'s sample weights against its base's own.

    python benchmarks/coating_weights.py [--samples 1000000] [--variant llvm_ad_spectral]
                                         [--alpha 0] [--json] [--compare BEFORE.json]

A path tracer multiplies its throughput by ``sample()``'s weight: heavy weights are the
fireflies of a render. For each base of :data:`BASES`, alone and under the coating
:data:`COAT` (films "TiO2 80; SiO2 120" on a 1.5 coat), at ``cos θ_i`` 1.0 and 0.3, this
draws --samples calls of ``sample()`` with independent uniform numbers at one wavelength
(550 nm: every lane of the spectrum carries it, so a weight is one number) and reports
the variance of the weights, the largest, and the share of the total weight carried by
weights over :data:`HEAVY` (the energy a render gets from rare, bright samples), and the
process CPU seconds of the coating's draws (after one untimed call: the kernel compiled).
``--alpha`` > 0 gives the coating a rough top of that roughness (GGX).

--compare reads the --json output of an earlier run (another commit, the same
--samples) and prints its coating figures beside these: before and after a change of the
estimator, e.g.::

    git stash; python benchmarks/coating_weights.py --json > /tmp/before.json; git stash pop
    python benchmarks/coating_weights.py --compare /tmp/before.json
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

# this checkout's package, not an installed one (the script's folder is first on sys.path)
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: the coating of every row: a TiO2 film under SiO2 on a clear 1.5 coat
COAT = {"layers": "TiO2 80; SiO2 120", "int_ior": 1.5}
#: (label, the nested BSDF)
BASES = [
    ("roughconductor α 0.3", {"type": "roughconductor", "alpha": 0.3}),
    ("roughconductor Al, α 0.3", {"type": "roughconductor", "material": "Al", "alpha": 0.3}),
    # the same aluminium as `regular` spectra (thinfilm_mi.materials.conductor_spectra): the
    # same weights within 1e-4, the draws' time without Mitsuba's knot searches
    ("roughconductor Al (regular spectra), α 0.3",
     {"type": "roughconductor", "spectra": "mitsuba:Al", "alpha": 0.3}),
    ("conductor Al (smooth)", {"type": "conductor", "material": "Al"}),
    ("roughconductor α 0.05 (polished)", {"type": "roughconductor", "alpha": 0.05}),
    ("principled grey, roughness 0.3", {"type": "principled", "roughness": 0.3,
                                        "base_color": {"type": "rgb", "value": 0.5}}),
    ("diffuse 0.5", {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}),
]
COSINES = (1.0, 0.3)
#: a weight above this is "heavy" (a firefly's scale at the spp of a preview)
HEAVY = 10.0
WAVELENGTH = 550.0


def weights(bsdf, cos_theta: float, n: int, seed: int = 7):
    """``sample()``'s weights at ``cos_theta`` (first channel), for ``n`` uniform draws."""
    import drjit as dr
    import mitsuba as mi

    rng = np.random.default_rng(seed)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    sin_theta = float(np.sqrt(max(0.0, 1.0 - cos_theta ** 2)))
    si.wi = mi.Vector3f(sin_theta, 0.0, cos_theta)
    if mi.is_spectral:
        si.wavelengths = dr.full(mi.Spectrum, WAVELENGTH, n)
    ctx = mi.BSDFContext()
    s1 = mi.Float(rng.random(n, dtype=np.float32))
    s2 = mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32))
    _, w = bsdf.sample(ctx, si, s1, s2, True)
    w = np.asarray(mi.unpolarized_spectrum(w))
    # a weight the same in every lane (a constant albedo) is one column
    w = np.broadcast_to(w[:, None] if w.ndim == 1 else w, (w.shape[0], n))[0]
    return np.nan_to_num(w)


def timed(bsdf, cos_theta: float, n: int) -> float:
    """Process CPU seconds of ``n`` draws (the kernel compiled by an untimed call first)."""
    weights(bsdf, cos_theta, n, seed=11)
    start = time.process_time()
    weights(bsdf, cos_theta, n, seed=12)
    return time.process_time() - start


def stats(w: np.ndarray) -> dict:
    total = float(w.sum())
    heavy = float(w[w > HEAVY].sum())
    return {"mean": float(w.mean()), "variance": float(w.var()), "max": float(w.max()),
            "heavy_share": heavy / total if total > 0 else 0.0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=1_000_000)
    parser.add_argument("--variant", default="llvm_ad_spectral")
    parser.add_argument("--alpha", type=float, default=0.0,
                        help="the coating's top roughness (0: the smooth top)")
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument("--compare", metavar="BEFORE.json",
                        help="an earlier run's --json output, printed beside this one")
    args = parser.parse_args()
    import mitsuba as mi

    mi.set_variant(args.variant)
    import thinfilm_mi  # noqa: F401  (registers the plugins)
    from thinfilm_mi.materials import conductor_spectra

    rows = []
    for label, base in BASES:
        if "spectra" in base:
            if not mi.is_spectral:      # Mitsuba evaluates `regular` spectra there only
                continue
            base = {k: v for k, v in base.items() if k != "spectra"} | conductor_spectra(base["spectra"])
        alone = mi.load_dict(base)
        coat = mi.load_dict({"type": "thinfilm_coating", **COAT, "alpha": args.alpha,
                             "bsdf": base})
        for c in COSINES:
            rows.append({"base": label, "cos_theta_i": c,
                         "alone": stats(weights(alone, c, args.samples)),
                         "coating": {**stats(weights(coat, c, args.samples)),
                                     "seconds": timed(coat, c, args.samples)}})
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print(table(rows, load_rows(args.compare) if args.compare else None))


def load_rows(path: str) -> dict:
    """An earlier run's rows by (base, cos θ_i)."""
    with open(path, encoding="utf-8") as f:
        return {(r["base"], r["cos_theta_i"]): r for r in json.load(f)}


def cells(c: dict) -> str:
    """A coating's figures: variance, max, heavy share, seconds (where measured)."""
    seconds = f", {c['seconds']:.2f} s" if "seconds" in c else ""
    return f"{c['variance']:.3f}, {c['max']:.1f}, {100 * c['heavy_share']:.2f} %{seconds}"


def table(rows: list, before: dict | None) -> str:
    """The markdown table; with ``before``, the earlier run's coating column first."""
    head = (f"coating: variance, max, share of weight in weights > {HEAVY:g}, CPU seconds of "
            f"the draws")
    cols = ["base", "cos θ_i", "base alone: variance, max"]
    cols += [f"before, {head}", f"after, {head}"] if before else [head]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        a = r["alone"]
        line = [r["base"], f"{r['cos_theta_i']:.1f}", f"{a['variance']:.3f}, {a['max']:.2f}"]
        if before:
            old = before.get((r["base"], r["cos_theta_i"]))
            line.append(cells(old["coating"]) if old else "–")
        line.append(cells(r["coating"]))
        lines.append("| " + " | ".join(line) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
