"""thinfilm_mi.render.layered.walk (and nested): the walk of ``thinfilm_coating`` against closed forms.

Independent references: Fresnel's equations and the interreflection series of a
Lambertian base under a bare interface in float64 (written here), Mitsuba's ``plastic``
(``nonlinear`` true, whose series is that one with a fitted internal reflectance),
``thinfilm_diffuse``'s model ``"exact"`` (the same series over a film stack, summed in
closed form), and ``tmm`` (the stacks' and a conductor's Fresnel reflectances, for the
delta chains of a smooth base: ``R + T² ρ / (1 - R_in ρ)``). Monte Carlo tolerances are
4 standard errors of the mean, measured from the samples themselves (a false failure rate
of 6e-5 per comparison).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tmm

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from thinfilm_mi.render.layered.top import inward, outward  # noqa: E402

WLS = [450.0, 520.0, 610.0, 700.0]
#: samples per albedo: the weights' standard deviation is ~0.5, so the mean's
#: standard error is ~3.5e-4 (4σ ≈ 1.4e-3)
N = 1 << 19
LOSSLESS = "1.46 300; 2.3 80"
#: the stacks of the closed-form checks: bare (no films over a base medium unlike the
#: ambient: an interface), lossless and absorbing
STACKS = {"bare": "", "lossless": LOSSLESS, "absorbing": "1.46 200; 0.42+2.47j 4"}


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


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


def test_snell_maps_are_inverse_and_conserve_the_tangent_momentum():
    rng = np.random.default_rng(3)
    mu = rng.uniform(0.01, 1, 64)
    phi = rng.uniform(0, 2 * np.pi, 64)
    s = np.sqrt(1 - mu ** 2)
    w = mi.Vector3f(mi.Float(s * np.cos(phi)), mi.Float(s * np.sin(phi)), mi.Float(mu))
    w_in, ok = inward(w, 1.5)
    back, leaves = outward(w_in, 1.5)
    assert np.all(np.array(ok)) and np.all(np.array(leaves))
    # z = sqrt(1 - x² - y²) in float32 loses ~6e-8/μ near grazing (μ >= 0.01 here)
    np.testing.assert_allclose(np.array(back), np.array(w), atol=1e-5)
    # 1.0 sin θ = 1.5 sin θ' and unit length
    np.testing.assert_allclose(1.5 * np.hypot(*np.array(w_in)[:2]), s, rtol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(np.array(w_in), axis=0), 1.0, rtol=1e-6)
    # beyond the critical angle an inner direction does not leave
    _, leaves = outward(mi.Vector3f(0.8, 0.0, 0.6), 1.5)
    assert not bool(leaves[0])


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


@pytest.mark.parametrize("layers", ["", LOSSLESS], ids=["bare", "lossless"])
def test_lambertian_closed_form_is_the_walks_expectation(layers):
    """Over ``diffuse`` the base part is the closed form ``ρ/π cos θ_o' / (1 - ρ R_dh)``
    (``thinfilm_mi/render/layered/forms.py``); a blend of two ``diffuse`` (the same
    Lambertian, unknown to the registry) is walked. Over 2^14 random direction pairs at
    cos θ_i 0.7 the walk minus the closed form has mean 0 within 4σ of its spread, and the
    closed form returns the same value for other random numbers (no noise)."""
    base = {"type": "diffuse", "reflectance": 0.5}
    closed = coating(layers=layers, bsdf=base)
    walked = coating(layers=layers, bsdf={"type": "blendbsdf", "weight": 0.5,
                                          "bsdf_0": base, "bsdf_1": base})
    assert closed.coating.form is not None and walked.coating.form is None
    n = 1 << 14
    rng = np.random.default_rng(5)
    mu, phi = rng.uniform(0.02, 1, n), rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - mu ** 2)
    wo = mi.Vector3f(mi.Float(s * np.cos(phi)), mi.Float(s * np.sin(phi)), mi.Float(mu))
    si = interaction(0.7, n)
    a = np.array(closed.eval(mi.BSDFContext(), si, wo), np.float64)
    d = np.array(walked.eval(mi.BSDFContext(), si, wo), np.float64) - a
    assert np.all(np.abs(d.mean(axis=1)) <= 4 * d.std(axis=1) / np.sqrt(n)), d.mean(axis=1)
    seeds = [(mi.UInt32(np.arange(n, dtype=np.uint32) + k), mi.UInt32(np.full(n, 7 * k + 1, np.uint32)))
             for k in (1, 2)]
    runs = [np.array(b.coating.transmitted(mi.TransportMode.Radiance, si, wo, seed, mi.Bool(True)),
                     np.float64) for b in (closed, walked) for seed in seeds]
    np.testing.assert_array_equal(runs[0], runs[1])   # other random numbers, the same value
    assert np.any(runs[2] != runs[3])                 # (the walk's change)


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


@pytest.mark.parametrize("layers", list(STACKS.values()), ids=list(STACKS))
def test_films_over_diffuse_are_thinfilm_diffuse_exact(layers):
    """Check 3: films over ``diffuse`` equal ``thinfilm_diffuse`` ``model="exact"`` with
    ``base_ior`` = ``int_ior`` (its series in closed form, deterministic: its delta ``R``
    plus the quadrature of its ``eval``), at cos θ 1, 0.5 and 0.17. Bare (no films over
    a base medium unlike the ambient: an interface), lossless and absorbing stacks."""
    ours_bsdf = coating(layers=layers)
    ref = mi.load_dict({"type": "thinfilm_diffuse", "model": "exact", "base_ior": 1.5,
                        "ext_ior": 1.0, "layers": layers, "reflectance": 0.5})
    ctx = mi.BSDFContext()
    ctx.component = 0
    for cos in (1.0, 0.5, 0.17):
        ours, tol = albedo(ours_bsdf, cos)
        _, spec = ref.sample(ctx, interaction(cos), 0.5, mi.Point2f(0.5, 0.5))
        want = np.array(spec, np.float64)[:, 0] + diffuse_albedo_quadrature(ref, cos, 256)
        # 4σ of ours + the stacks' float32 evaluation (1e-5) and the reference's R_dh
        # quadrature (its Gauss-Legendre rule: 1e-6)
        np.testing.assert_allclose(ours, want, atol=tol.max() + 2e-5)


def tmm_rt(indices, thicknesses, cos, wl):
    """Unpolarised ``(R, T)`` of a stack by ``tmm`` (float64): ``indices`` from the
    medium of incidence (at ``cos``) to the exit medium, ``thicknesses`` of the films."""
    d = [np.inf, *thicknesses, np.inf]
    out = [tmm.coh_tmm(pol, list(indices), d, float(np.arccos(cos)), wl) for pol in "sp"]
    return 0.5 * (out[0]["R"] + out[1]["R"]), 0.5 * (out[0]["T"] + out[1]["T"])


@pytest.mark.parametrize("layers", list(STACKS.values()), ids=list(STACKS))
def test_smooth_conductor_base_is_the_closed_form(layers):
    """A smooth ``conductor`` (``eta`` 2, ``k`` 3, relative to the coat) under a coat: a
    pure delta BSDF whose weight is ``R + T² ρ / (1 - R_in ρ)`` (the stack's ``R`` and
    ``T`` from outside at θ, its ``R_in`` from the coat at θ', the conductor's ``ρ`` at
    θ': unpolarised, as the spectral variant composes them), every term from ``tmm`` in
    float64. No noise (the delta chain is summed in closed form); float32: 2e-5. The stack
    is evaluated exactly whatever ``auto`` would choose: this checks the composition, not a
    table's error (tests/tabulate)."""
    b = coating(layers=layers, bsdf={"type": "conductor", "eta": 2.0, "k": 3.0}, tabulate=False)
    assert b.component_count() == 1 and not b.flags() & mi.BSDFFlags.Smooth
    films = [f.split() for f in layers.split(";") if f.strip()]
    n = [1.0, *(complex(f[0]) for f in films), 1.5]
    d = [float(f[1]) for f in films]
    for cos in (1.0, 0.5, 0.17):
        bs, w = b.sample(mi.BSDFContext(), interaction(cos), 0.3, mi.Point2f(0.5, 0.5))
        np.testing.assert_allclose(np.array(bs.wo)[:, 0],
                                   [-np.sqrt(1 - cos * cos), 0.0, cos], atol=1e-6)
        cos_in = float(np.sqrt(1 - (1 - cos * cos) / 1.5 ** 2))
        want = []
        for wl in WLS:
            r, t = tmm_rt(n, d, cos, wl)
            r_in, _ = tmm_rt(n[::-1], d[::-1], cos_in, wl)
            rho, _ = tmm_rt([1.0, 2.0 + 3.0j], [], cos_in, wl)
            want.append(r + t * t * rho / (1 - r_in * rho))
        np.testing.assert_allclose(np.array(w, np.float64)[:, 0], want, atol=2e-5)


def test_a_randomly_picked_delta_lobe_has_the_stated_bias():
    """A base that picks its delta lobe at random (``blendbsdf`` of a ``conductor`` and a
    black ``diffuse``, weight 0.5: ``B_δ`` is ``ρ`` or 0): the round trips' estimate ``1 +
    M_1 (1 + M_2 (1 - M_3)^-1)`` (``TAIL_LEVELS`` = 2) has the expectation ``1 + m (1 + m
    E[(1 - M)^-1])``, ``m = U ρ/2``, where the truth is ``(1 - m)^-1``. Over 2^16 samples of
    the delta lobe its mean is that expectation within 4σ, and the bias it leaves,
    ``T² (ρ/2) m² (E[(1 - M)^-1] - (1 - m)^-1)``, is < 1e-4 at cos θ 1, 0.5 and 0.17 (one
    closed form of one sample, ``E[ρ/2 (1 - M)^-1]``, was 1-3 % off). ``tmm`` for every
    factor (unpolarised, as above)."""
    b = coating(bsdf={"type": "blendbsdf", "weight": 0.5,
                      "bsdf_0": {"type": "conductor", "eta": 2.0, "k": 3.0},
                      "bsdf_1": {"type": "diffuse", "reflectance": 0.0}})
    ctx = mi.BSDFContext()
    ctx.component = 0
    n = 1 << 16
    rng = np.random.default_rng(3)
    for cos in (1.0, 0.5, 0.17):
        _, w = b.sample(ctx, interaction(cos, n), mi.Float(rng.random(n, dtype=np.float32)),
                        mi.Point2f(rng.random(n, dtype=np.float32),
                                   rng.random(n, dtype=np.float32)))
        w = np.array(w, np.float64)[0]
        cos_in = float(np.sqrt(1 - (1 - cos * cos) / 1.5 ** 2))
        r, t = tmm_rt([1.0, 1.5], [], cos, WLS[0])
        u, _ = tmm_rt([1.5, 1.0], [], cos_in, WLS[0])
        rho, _ = tmm_rt([1.0, 2.0 + 3.0j], [], cos_in, WLS[0])
        m = u * rho / 2
        closed = 0.5 / (1 - u * rho) + 0.5          # E[(1 - M)^-1], M = U ρ or 0
        expected = r + t * t * rho / 2 * (1 + m * (1 + m * closed))
        exact = r + t * t * rho / 2 / (1 - m)
        assert abs(w.mean() - expected) <= 4 * w.std() / np.sqrt(n), (cos, w.mean(), expected)
        assert 0 < expected - exact < 1e-4 * exact, (cos, expected, exact)


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


def test_absorbing_coat_is_beer_lambert():
    """``coat_sigma_a`` over ``coat_thickness``: with one bounce the factor is
    ``exp(-σ d (1/μ_i' + 1/μ_o'))`` on the inner cosines, exactly."""
    clear, murky = coating(max_bounces=1), coating(max_bounces=1, coat_sigma_a=0.3,
                                                   coat_thickness=0.5)
    wo = mi.Vector3f(-0.6, 0.0, 0.8)
    ratio = (np.array(murky.eval(mi.BSDFContext(), interaction(0.5), wo), np.float64)
             / np.array(clear.eval(mi.BSDFContext(), interaction(0.5), wo), np.float64))
    mu_i, mu_o = np.sqrt(1 - 0.75 / 2.25), np.sqrt(1 - 0.36 / 2.25)
    np.testing.assert_allclose(ratio, np.exp(-0.15 * (1 / mu_i + 1 / mu_o)), rtol=1e-5)


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
