"""thinfilm_mi.render.layered.walk: the random walk of ``thinfilm_coating`` against closed forms.

Independent references (``tests/support/layered.py``): Fresnel's equations and the
interreflection series of a Lambertian base under a bare interface in float64, and
Mitsuba's ``plastic`` (``nonlinear`` true, whose series is that one with a fitted internal
reflectance). Monte Carlo tolerances are 4 standard errors of the mean, measured from the
samples themselves (a false failure rate of 6e-5 per comparison).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import (  # noqa: E402
    LOSSLESS,
    albedo,
    coating,
    diffuse_albedo_quadrature,
    fresnel,
    interaction,
    internal_diffuse_reflectance,
    plastic_series,
)


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


def test_single_bounce_is_the_closed_form():
    """``max_bounces`` 1 over a Lambertian: ``eval = (1-F_i)(1-F_o) ρ/π cos_o / η²``, no
    noise (the walk's first vertex is fixed); float32 rounding 1e-5 relative."""
    b = coating(max_bounces=1)
    mu = np.array([0.95, 0.7, 0.4, 0.15])
    wo = mi.Vector3f(mi.Float(-np.sqrt(1 - mu ** 2)), 0.0, mi.Float(mu))
    for cos in (1.0, 0.5):
        got = np.array(b.eval(mi.BSDFContext(), interaction(cos, 4), wo), np.float64).T
        want = (1 - fresnel(cos, 1.5)) * (1 - fresnel(mu, 1.5)) * 0.5 / np.pi * mu / 1.5 ** 2
        np.testing.assert_allclose(got, np.repeat(want[:, None], 4, axis=1), rtol=1e-5)


def test_albedo_is_plastic_nonlinear():
    """Check 2: no films, ``int_ior`` 1.5 over ``diffuse`` 0.5 is ``plastic`` with
    ``nonlinear`` true. Both against the float64 series (4σ of our samples); ``plastic``
    (from its deterministic ``eval`` and its specular weight) within its fit error: its
    ``F_dr,int`` is ``mi.fresnel_diffuse_reflectance``'s polynomial, 0.59681 against the
    integral's 0.59635 at η = 1.5, which moves the albedo by ∂A/∂F_fit · δ (evaluated here,
    <= 1e-4 at ρ = 0.5). At 0/30/60/80°."""
    ours_bsdf = coating()
    plastic = mi.load_dict({"type": "plastic", "int_ior": 1.5, "ext_ior": 1.0, "nonlinear": True,
                            "diffuse_reflectance": 0.5})
    f_fit = float(np.array(mi.fresnel_diffuse_reflectance(mi.Float(1 / 1.5)))[0])
    f_dr = internal_diffuse_reflectance(1.5)
    ctx = mi.BSDFContext()
    ctx.component = 0
    for deg in (0, 30, 60, 80):
        cos = float(np.cos(np.radians(deg)))
        ours, tol = albedo(ours_bsdf, cos)
        exact = plastic_series(cos, 0.5, 1.5)
        np.testing.assert_allclose(ours, exact, atol=tol.max())
        _, spec = plastic.sample(ctx, interaction(cos), 0.5, mi.Point2f(0.5, 0.5))
        plastic_albedo = float(np.array(spec)[0, 0]) + diffuse_albedo_quadrature(plastic, cos)
        f_i = fresnel(cos, 1.5)
        # plastic's albedo is (1 - F_i) ρ (1 - F_dr) / (1 - ρ F_fit): its escape integral
        # is exact, the fit enters the series' denominator only: ∂A/∂F_fit = (1 - F_i) ρ²
        # (1 - F_dr) / (1 - ρ F_dr)²; times the fit's error, with a 1 % margin
        fit_error = (1 - f_i) * 0.25 * (1 - f_dr) / (1 - 0.5 * f_dr) ** 2 \
            * abs(f_fit - f_dr) * 1.01
        assert fit_error < 1e-4
        np.testing.assert_allclose(plastic_albedo, exact, atol=fit_error + 1e-5)  # + float32
        np.testing.assert_allclose(ours, plastic_albedo, atol=tol.max() + fit_error + 1e-5)


def test_eval_is_plastic_nonlinear_in_expectation():
    """The walk's ``eval`` summed over the hemisphere (the diffuse albedo) is the series'
    diffuse part. Each direction has its own seeded walk; over 4096 directions
    (stratified in μ) the noise of the mean is measured and 4σ allowed."""
    b = coating()
    n = 4096
    rng = np.random.default_rng(5)
    mu = (np.arange(n) + rng.random(n)) / n
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - mu ** 2)
    wo = mi.Vector3f(mi.Float(s * np.cos(phi)), mi.Float(s * np.sin(phi)), mi.Float(mu))
    value = np.array(b.eval(mi.BSDFContext(), interaction(0.8, n), wo), np.float64).T
    est = 2 * np.pi * value            # uniform μ on [0, 1], uniform φ: pdf 1/(2π) per sr·cos
    want = plastic_series(0.8, 0.5, 1.5) - fresnel(0.8, 1.5)
    np.testing.assert_allclose(est.mean(axis=0), want, atol=4 * est.std(axis=0).max() / np.sqrt(n))


def test_truncation_bias_is_the_dropped_series():
    """``max_bounces`` N keeps the first N terms of ``ρ^k F_dr^k``: the albedo's diffuse
    part at N = 1 is the series' first term (measured bias: the rest)."""
    cos = 0.9
    f_i, f_dr = fresnel(cos, 1.5), internal_diffuse_reflectance(1.5)
    first = (1 - f_i) * 0.5 * (1 - f_dr)
    got = diffuse_albedo_quadrature(coating(max_bounces=1), cos, nodes=256)
    # the quadrature of (1 - F_o) μ over μ: 128 nodes resolve the kink at the critical
    # angle of nothing (outside there is none); 1e-5 for float32
    np.testing.assert_allclose(got, first, rtol=1e-4)
    full = plastic_series(cos, 0.5, 1.5) - f_i
    # the bias of max_bounces = 1 (what 63 more bounces add at ρ = 0.5): 0.082, 30 %
    assert full - first > 0.05


@pytest.mark.parametrize("base", [{"type": "diffuse", "reflectance": 1.0},
                                  {"type": "thinfilm_diffuse", "layers": "2.0 100",
                                   "ext_ior": 1.5, "reflectance": 1.0}],
                         ids=["diffuse", "thinfilm_diffuse"])
def test_white_base_under_lossless_films_conserves_energy(base):
    """Check 5: lossless films, a white Lambertian base: the albedo is 1 within noise,
    never above it beyond noise. Also over our ``thinfilm_diffuse`` (a delta reflection
    of its film over a white Lambertian, lossless: its exact model keeps every photon)."""
    b = coating(layers=LOSSLESS, bsdf=base)
    for cos in (1.0, 0.6, 0.2):
        a, tol = albedo(b, cos)
        assert np.all(np.abs(a - 1) <= tol), (cos, a, tol)


@pytest.mark.parametrize("base", [{"type": "roughconductor", "alpha": 0.3},
                                  {"type": "principled", "roughness": 0.4, "metallic": 0.3}],
                         ids=["roughconductor", "principled"])
def test_reciprocity(base):
    """Check 5: ``f(ω_i, ω_o) = f(ω_o, ω_i)`` for reciprocal bases: exactly for the single
    bounce (``max_bounces`` 1; float32: 1e-5), in expectation for the walk (the
    walk's estimate averaged over 2048 seeds each way, 4σ)."""
    wi = mi.Vector3f(0.5, 0.1, float(np.sqrt(1 - 0.26)))
    wo = mi.Vector3f(-0.3, 0.4, float(np.sqrt(1 - 0.25)))
    ctx = mi.BSDFContext()
    single = coating(layers=LOSSLESS, bsdf=base, max_bounces=1)

    def f(b, a, c):
        si = interaction(1.0)
        si.wi = a
        return np.array(b.eval(ctx, si, c), np.float64)[:, 0] / float(c.z[0])
    np.testing.assert_allclose(f(single, wi, wo), f(single, wo, wi), rtol=1e-5)

    full = coating(layers=LOSSLESS, bsdf=base)
    n = 2048
    seeds = (mi.UInt32(np.arange(n, dtype=np.uint32)), mi.UInt32(np.arange(n, dtype=np.uint32) * 7 + 1))
    est = []
    for a, c in ((wi, wo), (wo, wi)):
        si = interaction(1.0, n)
        si.wi = mi.Vector3f(a)
        v = full.coating.transmitted(mi.TransportMode.Radiance, si, mi.Vector3f(c), seeds, mi.Bool(True))
        est.append(np.array(v, np.float64).T / float(c.z[0]))
    diff = est[0] - est[1]
    assert np.all(np.abs(diff.mean(axis=0)) <= 4 * diff.std(axis=0) / np.sqrt(n) + 1e-6)
