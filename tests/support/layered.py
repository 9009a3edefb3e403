"""The references and sampling helpers of the layered engine's tests
(``tests/render/layered/``): float64 Fresnel terms and the interreflection series of a
Lambertian base under a bare interface (written here), ``tmm``'s stacks, and sample
weights and albedos of a BSDF with their 4-standard-error tolerances (a false failure rate
of 6e-5 per comparison). Callers set the variant (``llvm_ad_spectral``)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import tmm

__all__ = ["WLS", "N", "LOSSLESS", "STACKS", "interaction", "weights", "albedo", "fresnel",
           "internal_diffuse_reflectance", "plastic_series", "coating",
           "diffuse_albedo_quadrature", "tmm_rt"]

WLS = [450.0, 520.0, 610.0, 700.0]
#: samples per albedo: the weights' standard deviation is ~0.5, so the mean's
#: standard error is ~3.5e-4 (4σ ≈ 1.4e-3)
N = 1 << 19
LOSSLESS = "1.46 300; 2.3 80"
#: the stacks of the closed-form checks: bare (no films over a base medium unlike the
#: ambient: an interface), lossless and absorbing
STACKS = {"bare": "", "lossless": LOSSLESS, "absorbing": "1.46 200; 0.42+2.47j 4"}


def interaction(cos, n=1):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wavelengths = mi.Spectrum(*WLS)
    si.wi = mi.Vector3f(float(np.sqrt(1 - cos * cos)), 0.0, float(cos))
    return si


def weights(bsdf, cos, n=N, seed=1, component=None):
    """Sample weights (n x channels, float64) from ``cos``."""
    rng = np.random.default_rng(seed)
    ctx = mi.BSDFContext()
    if component is not None:
        ctx.component = component
    s1 = mi.Float(rng.random(n, dtype=np.float32))
    s2 = mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32))
    _, w = bsdf.sample(ctx, interaction(cos, n), s1, s2)
    return np.array(w, dtype=np.float64).T


def albedo(bsdf, cos, n=N, seed=1):
    """Mean sample weight per wavelength and 4 standard errors."""
    w = weights(bsdf, cos, n, seed)
    return w.mean(axis=0), 4.0 * w.std(axis=0) / np.sqrt(n)


def fresnel(cos, eta):
    """Unpolarised Fresnel reflectance (float64) for light at ``cos`` in the medium of
    index 1 onto index ``eta`` (total reflection where the transmitted cosine is
    imaginary)."""
    cos = np.asarray(cos, np.float64)
    s2 = (1 - cos ** 2) / eta ** 2
    ct = np.sqrt(np.maximum(1 - s2, 0))
    rs = (cos - eta * ct) / (cos + eta * ct)
    rp = (eta * cos - ct) / (eta * cos + ct)
    return np.where(s2 >= 1, 1.0, 0.5 * (rs ** 2 + rp ** 2))


def internal_diffuse_reflectance(eta, nodes=256):
    """``F_dr,int = 2 ∫ F_in(μ) μ dμ`` from inside a medium of index ``eta`` (Gauss-Legendre
    on each side of the critical cosine)."""
    mu_c = np.sqrt(1 - 1 / eta ** 2)
    x, w = np.polynomial.legendre.leggauss(nodes)
    total = 0.0
    for a, b in ((0.0, mu_c), (mu_c, 1.0)):
        mu = 0.5 * (b - a) * (x + 1) + a
        total += np.sum(0.5 * (b - a) * w * fresnel(mu, 1 / eta) * mu)
    return 2 * total


def plastic_series(cos, rho, eta):
    """The exact albedo of a Lambertian ``rho`` under a bare interface (float64)."""
    f_i, f_dr = fresnel(cos, eta), internal_diffuse_reflectance(eta)
    return f_i + (1 - f_i) * rho * (1 - f_dr) / (1 - rho * f_dr)


def coating(**extra):
    return mi.load_dict({"type": "thinfilm_coating", "int_ior": 1.5, "ext_ior": 1.0,
                         "bsdf": {"type": "diffuse", "reflectance": 0.5}, **extra})


def diffuse_albedo_quadrature(bsdf, cos, nodes=128):
    """``2π ∫ eval dμ_o`` of a BSDF whose ``eval`` does not depend on the azimuth
    (Lambertian terms), by Gauss-Legendre in ``μ_o``: deterministic."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu = 0.5 * (x + 1)
    wo = mi.Vector3f(mi.Float(np.sqrt(1 - mu ** 2)), 0.0, mi.Float(mu))
    value = np.array(bsdf.eval(mi.BSDFContext(), interaction(cos, nodes), wo), np.float64).T
    return 2 * np.pi * np.sum(0.5 * w[:, None] * value, axis=0)


def tmm_rt(indices, thicknesses, cos, wl):
    """Unpolarised ``(R, T)`` of a stack by ``tmm`` (float64): ``indices`` from the
    medium of incidence (at ``cos``) to the exit medium, ``thicknesses`` of the films."""
    d = [np.inf, *thicknesses, np.inf]
    out = [tmm.coh_tmm(pol, list(indices), d, float(np.arccos(cos)), wl) for pol in "sp"]
    return 0.5 * (out[0]["R"] + out[1]["R"]), 0.5 * (out[0]["T"] + out[1]["T"])
