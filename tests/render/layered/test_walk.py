"""thinfilm_mi.render.layered.walk: the random walk of ``thinfilm_coating`` against closed forms.

Independent references (``tests/support/layered.py``): Fresnel's equations and the
interreflection series of a Lambertian base under a bare interface in float64, and
Mitsuba's ``plastic`` (``nonlinear`` true, whose series is that one with a fitted internal
reflectance), and over glossy bases the figures of the walk and the sampling before their
links, fold and probe (another estimator of the same quantities). Monte Carlo tolerances
are 4 standard errors of the mean, measured from the samples themselves (a false failure
rate of 6e-5 per comparison).
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


#: The walk before its links and roulette threshold (commit 6ec9010: next-event estimation
#: alone, survival min(β, 0.95)) over ``roughconductor`` α 0.3 under "TiO2 80; SiO2 120" on
#: 1.5: ``transmitted`` at 520 nm, mean and standard error over 2^21 seeds
#: (``max_bounces``, ω_i, ω_o's x and y) -> (mean, standard error)
PRE_LINK_WALK = {
    (2, (0.0, 0.0, 1.0), (-0.5, 0.2)): (0.184233, 0.000022),
    (2, (0.95, 0.0, 0.3122), (0.3, 0.6)): (0.019807, 0.000008),
    (64, (0.0, 0.0, 1.0), (-0.5, 0.2)): (0.225405, 0.000088),
    (64, (0.8, 0.0, 0.6), (-0.7, 0.1)): (0.365025, 0.000165),
    (64, (0.95, 0.0, 0.3122), (0.3, 0.6)): (0.042931, 0.000051),
}
#: The albedo (``sample``'s mean weight at 450/520/610/700 nm, 2^20 samples) before the
#: links, the fold, the probe's ``P_R`` and cosine share: (base, cos θ_i) -> (means, errors)
PRE_LINK_ALBEDO = {
    ("roughconductor", 1.0): ([0.95677, 0.95306, 0.95333, 0.95416], [0.000973, 0.000768, 0.000745, 0.00075]),
    ("roughconductor", 0.6): ([0.914, 0.91869, 0.92033, 0.92016], [0.001174, 0.000934, 0.000901, 0.000906]),
    ("roughconductor", 0.3): ([0.91124, 0.91176, 0.90894, 0.90785], [0.001086, 0.000945, 0.000948, 0.000959]),
    ("principled", 1.0): ([0.22818, 0.43918, 0.66069, 0.8062], [0.000116, 0.000307, 0.000457, 0.000627]),
    ("principled", 0.6): ([0.27201, 0.46314, 0.65263, 0.79349], [0.000188, 0.000367, 0.000447, 0.000631]),
    ("principled", 0.3): ([0.38315, 0.50205, 0.64785, 0.78552], [0.000344, 0.000407, 0.000428, 0.000661]),
}
GLOSSY = {"roughconductor": {"type": "roughconductor", "alpha": 0.3},
          "principled": {"type": "principled", "roughness": 0.3, "metallic": 0.5,
                         "base_color": {"type": "rgb", "value": [0.8, 0.5, 0.2]}}}


def glossy_coating(base, **extra):
    return mi.load_dict({"type": "thinfilm_coating", "layers": "TiO2 80; SiO2 120", "int_ior": 1.5,
                         "bsdf": GLOSSY[base], **extra})


@pytest.mark.parametrize("key", list(PRE_LINK_WALK), ids=lambda k: f"{k[0]}-{k[1][2]}-{k[2][0]}")
def test_links_keep_the_walks_expectation(key):
    """The walk with its links (power heuristic against a reverse sample) and its roulette
    threshold estimates what the plain walk did (its figures in :data:`PRE_LINK_WALK`, an
    independent estimator of the same sum): at 2 vertices (the links' MIS alone, no
    roulette) and at 64, over 2^18 seeds, within 4σ of the difference of the two means."""
    bounces, wi, (ox, oy) = key
    n = 1 << 18
    b = glossy_coating("roughconductor", max_bounces=bounces)
    si = interaction(1.0, n)
    si.wi = mi.Vector3f(*wi)
    wo = mi.Vector3f(ox, oy, float(np.sqrt(1 - ox * ox - oy * oy)))
    seeds = (mi.UInt32(np.arange(n, dtype=np.uint32) * 5 + 3),
             mi.UInt32(np.arange(n, dtype=np.uint32) ^ 0x2545F491))
    v = np.array(b.coating.transmitted(mi.TransportMode.Radiance, si, wo, seeds, mi.Bool(True)),
                 np.float64)[1]
    mean, error = PRE_LINK_WALK[key]
    assert abs(v.mean() - mean) <= 4 * np.hypot(error, v.std() / np.sqrt(n))


@pytest.mark.parametrize("base, cos", list(PRE_LINK_ALBEDO), ids=lambda x: str(x))
def test_new_sampling_keeps_the_albedo(base, cos):
    """``sample``'s mean weight (2^19 samples) is the albedo the sampling before the links,
    the fold and the probe gave (:data:`PRE_LINK_ALBEDO`), within 4σ of the difference
    at each wavelength."""
    got, tol = albedo(glossy_coating(base), cos)
    mean, error = (np.array(x) for x in PRE_LINK_ALBEDO[base, cos])
    assert np.all(np.abs(got - mean) <= np.hypot(tol, 4 * error)), (got, mean)


@pytest.mark.parametrize("cos", [0.95, 0.3])
def test_steered_steps_keep_the_base_in_expectation(cos):
    """A walk's step (``RandomWalk.steer``: escape-cone samples unfolded beyond the critical
    angle) is an unbiased estimate of the base's reflection: its mean weight over the escape
    cone and over the trapped directions equals the base's own sampling's (a glossy
    ``roughconductor``, whose lobe spans both at these inner cosines), within 4 standard
    errors of both; and its density is :meth:`RandomWalk.step_pdf` at the direction it draws
    (1e-3 relative: an unfolded sample's partner ``fold(unfold(x))`` is ``x`` to float32's
    rounding of the cosine maps, 1.4e-4 relative in the density at most here). The draws
    take 0.5 s."""
    from thinfilm_mi.render.layered.bottom import base_interaction
    from thinfilm_mi.render.layered.escape import critical_cosine

    walk = coating(bsdf={"type": "roughconductor", "alpha": 0.3}).coating.sum
    base, n = walk.layer.base, 1 << 18
    rng = np.random.default_rng(3)
    si = base_interaction(interaction(cos, n), mi.Vector3f(float(np.sqrt(1 - cos * cos)), 0.0, cos))
    ctx = mi.BSDFContext()
    numbers = [mi.Float(rng.random(n, dtype=np.float32)) for _ in range(4)]
    bs, g = base.sample(ctx, si, numbers[0], mi.Point2f(numbers[1], numbers[2]))
    own = (np.array(bs.wo.z), np.array(g, np.float64)[0])
    w, weight, p = walk.steer(ctx, si, bs, g, numbers[3], mi.Bool(True))
    steered = (np.array(w.z), np.array(weight, np.float64)[0])
    mu_c = float(np.array(critical_cosine(walk.layer.top.eta_f))[0])
    for inside in (lambda z: z >= mu_c, lambda z: (z > 0) & (z < mu_c)):
        a, b = (np.where(inside(z), v, 0.0) for z, v in (own, steered))
        tol = 4.0 * np.hypot(a.std(), b.std()) / np.sqrt(n)
        assert abs(a.mean() - b.mean()) < tol, (cos, a.mean(), b.mean(), tol)
    up = steered[0] > 0  # the walk stops at a sample below the base
    p_b = base.pdf(ctx, si, w)
    np.testing.assert_allclose(np.array(walk.step_pdf(ctx, si, w, p_b, mi.Bool(True)))[up],
                               np.array(p)[up], rtol=1e-3)
