"""Energy of ``thinfilm_diffuse``'s rough base (``roughness``), measured by quadrature.

The albedo for light from ``θ_i`` is ``k_r(θ_i) + ∫ eval dω_o`` (``eval`` includes
``cos θ_o``), integrated over the hemisphere on a product rule (Gauss-Legendre in
``μ_o``, split at ``μ_i`` where the lobe has a kink, and the trapezoidal rule in ``φ``,
which is exact for the lobe's ``max(0, cos φ)`` up to the kink at ±90°: 720 nodes).
Prints, for a white base, the bare qualitative model's albedo range (closed form
``A + B h(μ)``) and the coated albedo's range over ``θ_i`` and wavelength for a few
stacks, for both ``roughness_model`` values.

    .venv/bin/python benchmarks/orennayar_energy.py
    .venv/bin/python benchmarks/orennayar_energy.py --render   # render cost of the rough base
"""
from __future__ import annotations

import math
import os
import sys

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from thinfilm_mi.render.orennayar import H_AVG, coefficients  # noqa: E402

WAVELENGTHS = (450.0, 520.0, 600.0, 680.0)
THETAS = (0.0, 20.0, 40.0, 60.0, 75.0, 85.0)
SIGMAS = (0.1, 0.3, 0.5, 1.0, math.pi / 2)
STACKS = ("", "1.46 500", "TiO2 120", "1.46 500; 2.35 80; 1.38 120", "SiO2 500; Au 2", "SiO2 300; Au 4")


def albedo(bsdf, theta_deg: float, n_mu: int = 96, n_phi: int = 720) -> np.ndarray:
    """``k_r + ∫ eval dω_o`` per wavelength for light from ``theta_deg``."""
    mu_i = math.cos(math.radians(theta_deg))
    x, w = np.polynomial.legendre.leggauss(n_mu)
    parts = [(0.0, mu_i), (mu_i, 1.0)] if 0.0 < mu_i < 1.0 else [(0.0, 1.0)]
    mus = np.concatenate([0.5 * (b - a) * x + 0.5 * (a + b) for a, b in parts])
    wmu = np.concatenate([0.5 * (b - a) * w for a, b in parts])
    phi = (np.arange(n_phi) + 0.5) * (2 * math.pi / n_phi)
    M, P = np.meshgrid(mus, phi, indexing="ij")
    W = np.meshgrid(wmu, np.full(n_phi, 2 * math.pi / n_phi), indexing="ij")
    W = (W[0] * W[1]).ravel()
    S = np.sqrt(1 - M ** 2)
    wo = mi.Vector3f((S * np.cos(P)).ravel(), (S * np.sin(P)).ravel(), M.ravel())
    n = M.size
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(math.sin(math.radians(theta_deg)), 0.0, mu_i)
    si.wavelengths = mi.Spectrum(*WAVELENGTHS)
    f = np.array(bsdf.eval(mi.BSDFContext(), si, wo), np.float64)
    ctx = mi.BSDFContext()
    ctx.component = 0
    _, k_r = bsdf.sample(ctx, si[0] if False else _one(si), mi.Float(0.5), mi.Point2f(0.5, 0.5))
    return (f * W).sum(axis=1) + np.array(k_r, np.float64).reshape(-1)[:len(WAVELENGTHS)]


def _one(si):
    one = dr.zeros(mi.SurfaceInteraction3f, 1)
    one.wi, one.wavelengths = mi.Vector3f(si.wi.x[0], si.wi.y[0], si.wi.z[0]), si.wavelengths
    return one


def main() -> None:
    print("bare qualitative model, white base: directional albedo A + B h(mu), hemispherical A + B H")
    mu = np.linspace(0.0, 1.0, 100001)
    s = np.sqrt(1 - mu ** 2)
    h = (s * (np.arccos(mu) - s * mu) + (2 / 3) * s * mu * (1 + s + s * s) / (1 + s)) / math.pi
    for sigma in SIGMAS:
        a, b = coefficients(sigma)
        e = a + b * h
        print(f"  sigma {sigma:.3f}: min {e.min():.4f} (normal), max {e.max():.4f} (grazing), "
              f"hemispherical {a + b * H_AVG:.4f}")
    for model in ("qualitative", "eon"):
        print(f"{model}: coated albedo of a white base over theta_i {THETAS} and {WAVELENGTHS} nm")
        for layers in STACKS:
            for sigma in (0.3, math.pi / 2):
                b = mi.load_dict({"type": "thinfilm_diffuse", "layers": layers, "roughness": sigma,
                                  "roughness_model": model, "reflectance": 1.0, "tabulate": False})
                a = np.array([albedo(b, t) for t in THETAS])
                print(f"  {layers or '(no films)':30s} sigma {sigma:.3f}: min {a.min():.4f} max {a.max():.4f}"
                      f" (at {THETAS[int(np.argmax(a.max(axis=1)))]} deg)")


def render_cost(repeats: int = 5) -> None:
    """Steady render time (median of ``repeats`` rounds, after an untimed one) of a coated
    sphere (SiO2 300 nm; Au 4 nm) at 128 x 128, 16 spp, Lambertian against the rough bases.
    Each scene is loaded alone for its render and freed (``timing.alone``: a live Python BSDF
    is traced into every render). Ours against ours: Mitsuba 3 has no Oren-Nayar BSDF; the
    Lambertian plugin against ``diffuse`` is ``plugin_bench.py``'s."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from timing import alone, own_table_store
    own_table_store()
    for variant in ("llvm_ad_spectral", "llvm_ad_rgb"):
        mi.set_variant(variant)
        bases = {"lambert": {}, "qualitative": {"roughness": 0.6},
                 "eon": {"roughness": 0.6, "roughness_model": "eon"}}

        def load(extra):
            return mi.load_dict({
                "type": "scene", "integrator": {"type": "path", "max_depth": 4},
                "sensor": {"type": "perspective", "fov": 30,
                           "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": 128, "height": 128},
                           "sampler": {"type": "independent", "sample_count": 16}},
                "emitter": {"type": "constant"},
                "ball": {"type": "sphere", "bsdf": {"type": "thinfilm_diffuse",
                                                    "layers": "SiO2 300; Au 4", **extra}}})

        runs = {label: [] for label in bases}
        for k in range(repeats + 1):
            for label, extra in (bases.items() if k % 2 == 0 else reversed(bases.items())):
                wall = alone(lambda extra=extra: load(extra), k)[0]
                if k:                                   # round 0 compiles
                    runs[label].append(wall)
        times = {label: float(np.median(v)) for label, v in runs.items()}
        base = times["lambert"]
        print(variant, ", ".join(f"{k} {v * 1e3:.0f} ms ({v / base:.2f}x)" for k, v in times.items()))


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("orennayar_energy"):   # --write-docs: docs/_generated/orennayar_energy.md
        if "--render" in sys.argv:
            render_cost()
        else:
            main()
