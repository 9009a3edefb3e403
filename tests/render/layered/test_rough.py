"""thinfilm_mi.render.layered.rough: the estimator under a rough top, against independent
references: Mitsuba's chi2 test of ``sample`` against ``pdf``; an explicit random walk
through ``thinfilm_roughdielectric`` (the top as its own plugin) and the base, sampling
every event (no next-event estimation, no MIS, no mixture), for the albedo and the white
furnace; reciprocity in expectation; the smooth top as ``alpha -> 0``; gradients against
finite differences. Tolerances: 4 standard errors of the compared means (a false failure
rate of 6e-5 per comparison). Cost: ~40-60 s on 2 cores (kernel compilation dominates)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import LOSSLESS, WLS  # noqa: E402
from thinfilm_mi.render.layered.rough import RoughEstimator  # noqa: E402

BASES = {
    "diffuse": {"type": "diffuse", "reflectance": 0.8},
    "roughconductor": {"type": "roughconductor", "alpha": 0.2},
    "principled": {"type": "principled", "roughness": 0.4, "metallic": 0.2,
                   "base_color": {"type": "rgb", "value": [0.7, 0.3, 0.2]}},
}
FILMS = "TiO2 120; SiO2 200"
#: bases whose walks link the light side: through a mirror, and a near-specular lobe
DELTA_BASES = {"conductor": {"type": "conductor", "material": "Au"},
               "polished": {"type": "roughconductor", "alpha": 0.05}}


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


def rough(base, alpha, **extra):
    return mi.load_dict({"type": "thinfilm_coating", "int_ior": 1.5, "alpha": alpha,
                         "distribution": "ggx", "bsdf": base, **extra})


def interaction(theta, n, phi=0.4):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wavelengths = mi.UnpolarizedSpectrum(*WLS)
    t = np.radians(theta)
    si.wi = mi.Vector3f(float(np.sin(t) * np.cos(phi)), float(np.sin(t) * np.sin(phi)),
                        float(np.cos(t)))
    return si


def numbers(rng, n):
    return (mi.Float(rng.random(n, dtype=np.float32)),
            mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32)))


def mean_err(x):
    """Per-channel mean and standard error of samples ``x`` (channels x n)."""
    x = np.asarray(x, np.float64)
    return x.mean(axis=1), x.std(axis=1) / np.sqrt(x.shape[1])


def coating_albedo(b, theta, n, seed, component=None):
    """The mean sample weight (``∫ f cos``) and its standard error."""
    ctx = mi.BSDFContext()
    if component is not None:
        ctx.component = component
    _, w = b.sample(ctx, interaction(theta, n), *numbers(np.random.default_rng(seed), n))
    return mean_err(w)


def explicit_albedo(top, base, theta, n, seed, bounces=30):
    """The albedo of ``top`` (a ``thinfilm_roughdielectric``) over ``base`` by sampling
    every event, the top from both sides with both its lobes: an analogue walk whose
    tallies are the light that leaves upwards. ``bounces`` base vertices (the light left
    after 30 over a white base under a 1.5 interface is < 0.7^30 = 2e-5)."""
    rng = np.random.default_rng(seed)
    ctx = mi.BSDFContext()
    si = interaction(theta, n)
    bs, w = top.sample(ctx, si, *numbers(rng, n))
    up = bs.wo.z > 0
    total = dr.select(up & (bs.pdf > 0), w, 0.0)
    beta, alive, d = mi.Spectrum(w), (~up) & (bs.pdf > 0), -bs.wo
    for _ in range(bounces):
        si.wi = d
        bb, g = base.sample(ctx, si, *numbers(rng, n), alive)
        alive &= (bb.pdf > 0) & (bb.wo.z > 0)
        beta = beta * g
        si.wi = -bb.wo
        bt, wt = top.sample(ctx, si, *numbers(rng, n), alive)
        alive &= bt.pdf > 0
        total = total + dr.select(alive & (bt.wo.z > 0), beta * wt, 0.0)
        alive &= bt.wo.z < 0
        beta, d = beta * wt, -bt.wo
        dr.eval(total, beta, alive, d)
    return mean_err(total)


def test_rough_top_builds_its_own_estimator_and_alpha_zero_the_smooth_one():
    b = rough(BASES["diffuse"], 0.3)
    assert isinstance(b.coating, RoughEstimator) and not b.coating.top.smooth
    for extra in ({}, {"alpha": 0.0}, {"alpha_u": 0.0, "alpha_v": 0.0}):
        s = mi.load_dict({"type": "thinfilm_coating", "bsdf": BASES["diffuse"], **extra})
        assert s.coating.top.smooth and not isinstance(s.coating, RoughEstimator)


@pytest.mark.parametrize("base", list(BASES))
@pytest.mark.parametrize("alpha", [0.1, 0.5])
def test_chi2_sample_against_pdf(base, alpha):
    """``sample``'s directions have the density ``pdf`` returns (both components: the
    top's reflection lobe, the base's lobe refracted out, the cosine lobe): Mitsuba's chi2
    test at significance 0.01, 24 x 48 cells, 16 x 16 points per cell (40 degrees)."""
    b = rough(BASES[base], alpha, layers=FILMS)
    test = run_chi2(b)
    # a base direction beyond the critical angle is a failed sample (pdf leaves it out
    # alike): over diffuse, 1 - 1/1.5² of the base lobe's share
    assert float(test.histogram_sum[0]) > 0.6


def test_chi2_anisotropic_beckmann_top():
    """The same over an anisotropic Beckmann top (``alpha_u`` 0.1, ``alpha_v`` 0.4)."""
    b = mi.load_dict({"type": "thinfilm_coating", "int_ior": 1.5, "alpha_u": 0.1, "alpha_v": 0.4,
                      "distribution": "beckmann", "layers": FILMS, "bsdf": BASES["roughconductor"]})
    run_chi2(b)


def run_chi2(b):
    """Mitsuba's chi2 test of ``b``'s ``sample`` against its ``pdf`` at 40 degrees; asserts
    that it passes and returns it."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    ctx = mi.BSDFContext()

    def sample_func(sample):
        n = dr.width(sample)
        bs, _ = b.sample(ctx, interaction(40.0, n), sample[0], mi.Point2f(sample[1], sample[2]))
        return bs.wo, dr.select(bs.pdf > 0, 1.0, 0.0)

    def pdf_func(wo):
        return b.pdf(ctx, interaction(40.0, dr.width(wo)), wo)

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=100_000, res=24, ires=16)
    assert test.run(0.01), test.messages
    return test


def test_sample_pdf_is_pdf_and_weight_estimates_eval():
    """``bs.pdf`` is ``pdf`` at the direction (float32, 1e-5), and the sample weight times it
    estimates ``eval`` (independent walks: their means agree within 4σ)."""
    b = rough(BASES["roughconductor"], 0.3, layers=FILMS, coat_sigma_a=0.3)
    n = 1 << 14
    si = interaction(50.0, n)
    ctx = mi.BSDFContext()
    bs, w = b.sample(ctx, si, *numbers(np.random.default_rng(3), n))
    ok = np.array(bs.pdf) > 0
    # the base lobe's directions beyond the critical angle are failed samples
    assert ok.mean() > 0.8
    np.testing.assert_allclose(np.array(bs.pdf)[ok], np.array(b.pdf(ctx, si, bs.wo))[ok], rtol=1e-5)
    diff = (np.array(w, np.float64) * np.array(bs.pdf) - np.array(b.eval(ctx, si, bs.wo)))[:, ok]
    m, e = mean_err(diff)
    assert np.all(np.abs(m) <= 4 * e)


@pytest.mark.parametrize("base", ["diffuse", "roughconductor", "conductor", "polished"])
@pytest.mark.parametrize("layers", ["", FILMS], ids=["bare", "films"])
def test_albedo_is_the_explicit_walks(base, layers):
    """The albedo (mean sample weight) at 0, 30, 60, 80 degrees is the explicit walk's
    through ``thinfilm_roughdielectric`` and the base (2^16 paths each; 4σ of the
    difference)."""
    alpha = 0.3
    # (tabulate false: no tables to build for two plugins; the same stack either way)
    top = mi.load_dict({"type": "thinfilm_roughdielectric", "int_ior": 1.5, "alpha": alpha,
                        "distribution": "ggx", "layers": layers, "tabulate": False})
    spec = {**BASES, **DELTA_BASES}[base]
    b = rough(spec, alpha, layers=layers, tabulate=False)
    ref_base = mi.load_dict(spec)
    n = 1 << 16
    for theta in (0.0, 30.0, 60.0, 80.0):
        (r, re), (c, ce) = explicit_albedo(top, ref_base, theta, n, 1), coating_albedo(b, theta, n, 2)
        assert np.all(np.abs(c - r) <= 4 * np.hypot(re, ce)), (theta, r, c)


@pytest.mark.parametrize("base", [{"type": "roughconductor", "material": "none", "alpha": 0.2},
                                  {"type": "conductor", "material": "none"}],
                         ids=["roughconductor", "conductor"])
def test_white_furnace(base):
    """A lossless stack over a white conductor (``material="none"``) loses only what the
    microfacets lose to their single-scattering model: the top's from outside (the
    light that ``thinfilm_roughdielectric``'s R + T albedo misses), the underside's and the
    base's from inside. So the albedo is at most the top's own R + T albedo, less by the
    inner losses, and it is the explicit walk's (which loses at the same microfacets), at
    0, 45 and 80 degrees (4σ)."""
    top = mi.load_dict({"type": "thinfilm_roughdielectric", "int_ior": 1.5, "alpha": 0.3,
                        "distribution": "ggx", "layers": LOSSLESS})
    b = rough(base, 0.3, layers=LOSSLESS)
    ref_base = mi.load_dict(base)
    n = 1 << 16
    for theta in (0.0, 45.0, 80.0):
        # the energy R + T the top keeps: importance transport (no (η_e/η_c)² on T)
        own = mean_err(np.array(top.sample(mi.BSDFContext(mi.TransportMode.Importance),
                                           interaction(theta, n),
                                           *numbers(np.random.default_rng(5), n))[1]))
        (r, re), (c, ce) = explicit_albedo(top, ref_base, theta, n, 1), coating_albedo(b, theta, n, 2)
        assert np.all(np.abs(c - r) <= 4 * np.hypot(re, ce)), (theta, r, c)
        assert np.all(c <= own[0] + 4 * np.hypot(own[1], ce)), (theta, own, c)
        assert np.all(c > 0.5)


def test_reciprocity_in_expectation():
    """``f(ω_i, ω_o) = f(ω_o, ω_i)`` (a reflection in one medium, the base reciprocal):
    the estimates of ``f cos θ_o / cos θ_o`` at 2^16 seeds of each order agree within 4σ,
    at three direction pairs (coat absorption, films and a glossy base)."""
    b = rough(BASES["roughconductor"], 0.3, layers=FILMS, coat_sigma_a=0.4)
    n = 1 << 16
    rng = np.random.default_rng(8)
    ctx = mi.BSDFContext()
    pairs = [((0.3, 0.1), (-0.5, 0.2)), ((0.8, 0.0), (0.1, -0.4)), ((0.1, 0.6), (-0.7, -0.6))]

    def f(a, c):
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wavelengths = mi.UnpolarizedSpectrum(*WLS)
        si.wi = mi.Vector3f(a[0], a[1], float(np.sqrt(1 - a[0] ** 2 - a[1] ** 2)))
        wo = mi.Vector3f(c[0], c[1], float(np.sqrt(1 - c[0] ** 2 - c[1] ** 2)))
        seed = tuple(mi.UInt32(rng.integers(0, 2 ** 32, n, dtype=np.uint64).astype(np.uint32))
                     for _ in range(2))
        value = b.coating.value(ctx, si, wo, seed, mi.Bool(True), True, True)
        return mean_err(np.array(value) / float(wo.z[0]))

    for a, c in pairs:
        (x, xe), (y, ye) = f(a, c), f(c, a)
        assert np.all(np.abs(x - y) <= 4 * np.hypot(xe, ye)), (a, c, x, y)


def test_alpha_to_zero_converges_to_the_smooth_top():
    """As ``alpha -> 0`` the rough top's reflection albedo tends to the smooth stack's
    ``R(θ)`` and the light through it to the smooth top's (over ``diffuse``, 45 degrees):
    the difference at ``alpha = 0.01`` is within 4σ plus 0.5 % (the microfacets' spread
    of angles moves ``R`` and ``T`` by O(alpha²)), and smaller than at ``alpha = 0.2``."""
    n = 1 << 16
    smooth = mi.load_dict({"type": "thinfilm_coating", "int_ior": 1.5, "layers": FILMS,
                           "bsdf": BASES["diffuse"]})
    ref = [coating_albedo(smooth, 45.0, n, 4, component=k) for k in (0, 1)]
    gaps = []
    for alpha in (0.2, 0.01):
        b = rough(BASES["diffuse"], alpha, layers=FILMS)
        got = [coating_albedo(b, 45.0, n, 4, component=k) for k in (0, 1)]
        gaps.append([np.abs(g[0] - r[0]).max() for g, r in zip(got, ref)])
        if alpha == 0.01:
            for (g, ge), (r, rel) in zip(got, ref):
                assert np.all(np.abs(g - r) <= 4 * np.hypot(ge, rel) + 5e-3 * r), (g, r)
    assert gaps[1][0] < gaps[0][0] and gaps[1][1] < gaps[0][1], gaps


@pytest.mark.parametrize("base", [{"type": "roughconductor", "alpha": 0.3},
                                  {"type": "conductor", "material": "Au"}],
                         ids=["roughconductor", "conductor"])
def test_film_gradient_matches_finite_differences(base):
    """Forward- and reverse-mode derivatives of ``eval`` in a film's thickness against
    central differences (h = 1 nm: the truncation (4π n h/λ)²/6 < 2e-4 relative):
    ``max_bounces`` 3 (no Russian roulette) and the directions the top samples do not
    depend on the films, so the fixed-seed estimate is a smooth function of the thickness;
    1e-3 relative as the smooth top's check."""
    b = rough(base, 0.3, layers="2.3 120; 1.46 200", coat_sigma_a=0.2, max_bounces=3,
              tabulate=False)
    params = mi.traverse(b)
    key = "layers.0.thickness"
    rng = np.random.default_rng(4)
    n = 64
    mu, phi = rng.uniform(0.05, 1.0, (2, n)), rng.uniform(0, 2 * np.pi, (2, n))
    s = np.sqrt(1 - mu ** 2)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wavelengths = mi.UnpolarizedSpectrum(*WLS)
    si.wi = mi.Vector3f(mi.Float(s[0] * np.cos(phi[0])), mi.Float(s[0] * np.sin(phi[0])), mi.Float(mu[0]))
    wo = mi.Vector3f(mi.Float(s[1] * np.cos(phi[1])), mi.Float(s[1] * np.sin(phi[1])), mi.Float(mu[1]))
    ctx = mi.BSDFContext()

    def value(x):
        params[key] = type(params[key])(x)
        params.update()
        return np.array(b.eval(ctx, si, wo), np.float64)

    x0 = float(np.array(params[key]).ravel()[0])
    fd = (value(x0 + 1.0) - value(x0 - 1.0)) / 2.0
    value(x0)
    theta = params[key]
    dr.enable_grad(theta)
    params.update()
    out = b.eval(ctx, si, wo)
    dr.set_grad(theta, 1.0)
    fwd = np.array(dr.forward_to(out), np.float64)
    np.testing.assert_allclose(fwd, fd, rtol=1e-3, atol=1e-3 * np.abs(fd).max())
    weights = rng.uniform(0.5, 1.5, fd.shape)
    out = b.eval(ctx, si, wo)
    dr.backward_from(dr.sum(sum(out[i] * mi.Float(weights[i]) for i in range(4))))
    bwd = float(np.array(dr.grad(theta)).ravel()[0])
    np.testing.assert_allclose(bwd, np.sum(weights * fd), atol=1e-3 * np.sum(np.abs(weights * fd)))


def test_alpha_gradient_matches_finite_differences_in_expectation():
    """The roughness moves the directions the top samples, so the fixed-seed estimate's
    finite differences are not the detached-sampling derivative; both estimate the
    derivative of the expectation. At one direction pair and 2^16 seeds: central
    differences (h = 0.01, same seeds) against the forward-mode derivative, and the
    reverse-mode sum against the forward one (the same estimate, float32 sums: 1e-3)."""
    b = rough({"type": "roughconductor", "alpha": 0.3}, 0.3, layers=FILMS, max_bounces=3,
              tabulate=False)
    params = mi.traverse(b)
    n = 1 << 16
    rng = np.random.default_rng(1)
    si = interaction(30.0, n, phi=0.0)
    wo = mi.Vector3f(-0.3, 0.2, float(np.sqrt(0.87)))
    seed = tuple(mi.UInt32(rng.integers(0, 2 ** 32, n, dtype=np.uint64).astype(np.uint32))
                 for _ in range(2))
    ctx = mi.BSDFContext()

    def value():
        return b.coating.value(ctx, si, wo, seed, mi.Bool(True), True, True)

    def at(x):
        params["alpha.value"] = mi.Float(x)
        params.update()
        return np.array(value(), np.float64)

    fd = mean_err((at(0.31) - at(0.29)) / 0.02)
    at(0.3)
    alpha = params["alpha.value"]
    dr.enable_grad(alpha)
    params.update()
    out = value()
    dr.set_grad(alpha, 1.0)
    fwd = mean_err(np.array(dr.forward_to(out), np.float64))
    assert np.all(np.abs(fwd[0] - fd[0]) <= 4 * np.hypot(fwd[1], fd[1])), (fwd, fd)
    out = value()
    dr.backward_from(dr.sum(out[1]))
    np.testing.assert_allclose(float(np.array(dr.grad(alpha))[0]) / n, fwd[0][1], rtol=1e-3)


def test_a_failed_base_sample_is_no_direction():
    """A base sample that fails (a very rough conductor's reflection below its horizon:
    Mitsuba returns its direction there, our film-free plugins the zero vector, both with
    weight 0) is no direction of the mixture. Refracted out as it was, it left the top
    above the horizon (the zero vector along the normal) and its weight was counted where
    ``pdf`` has no density for it: over ``thinfilm_roughconductor`` this chi2 test failed
    and the albedo was 4 % high (``tests/cross/test_wrappers.py`` caught it); over
    Mitsuba's ``roughconductor`` α 0.3 the albedo was 0.3 % high (0.5284 against 0.5267
    ± 0.0003 at cos θ_i 0.9), which chi2 does not resolve."""
    for base in ("roughconductor", "thinfilm_roughconductor"):
        run_chi2(rough({"type": base, "alpha": 0.9}, 0.3, layers=FILMS))


def test_polarized_link_keeps_the_mueller_expectation():
    """Over a smooth conductor the polarized walk links the light side as the spectral one
    does: the mean Mueller matrix of the sample weights (the first wavelength's M00, M01,
    M22, M23 at 50 degrees) is the unlinked walk's within 4σ, with less variance (two
    polarized walk kernels to compile: most of the test's time)."""
    mi.set_variant("llvm_ad_spectral_polarized")
    n = 1 << 16
    spec = {"type": "thinfilm_coating", "layers": "TiO2 80", "int_ior": 1.5, "alpha": 0.2,
            "coat_sigma_a": 0.2, "bsdf": {"type": "conductor", "material": "Au"}}
    linked, plain = mi.load_dict(spec), mi.load_dict(spec)
    assert linked.coating.mirror
    plain.coating.mirror = False
    out = []
    for b in (linked, plain):
        rng = np.random.default_rng(3)
        _, w = b.sample(mi.BSDFContext(), interaction(50.0, n), *numbers(rng, n))
        out.append(np.array([[np.array(w[i][j])[0] for j in (0, 1, 2, 3)] for i in (0, 2)]))
    (a, ae), (c, ce) = (mean_err(x.reshape(-1, n)) for x in out)
    assert np.all(np.abs(a - c) <= 4 * np.hypot(ae, ce)), (a, c)
    assert out[0][0, 0].var() < out[1][0, 0].var()
