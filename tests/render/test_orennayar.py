"""``thinfilm_diffuse``'s Oren–Nayar base (``roughness``, ``roughness_model``).

* no films: ``eval`` is the seed's formula (written here with angles, float64) and the
  EON formula (written here from the paper's definitions), reciprocal;
* ``roughness = 0``: today's plugin bit for bit (evals, samples, an image);
* chi2 of the sampled directions with films, ``sample``'s weight = ``eval/pdf``;
* furnace: EON's white base reflects 1, the qualitative one its closed-form albedo;
  with films the albedo stays <= 1 (absorbing films) or within the model's stated
  error of 1 (lossless films);
* RGB: the integrated rough term against the spectral plugin integrated here;
* gradients with respect to a constant and a bitmap roughness against finite differences;
* mono and polarized variants; bad values.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
from mitsuba.chi2 import ChiSquareTest, SphericalDomain  # noqa: E402

import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from tests.support.bsdf import make_si, mc_albedo
from thinfilm_mi.errors import ThinFilmError  # noqa: E402

SIGMAS = (0.1, 0.4, 1.0, math.pi / 2)


def load(layers="", sigma=0.5, base="qualitative", reflectance=0.8, **extra):
    d = {"type": "thinfilm_diffuse", "layers": layers, "reflectance": reflectance,
         "roughness_model": base, **extra}
    if sigma is not None:
        d["roughness"] = sigma
    return mi.load_dict(d)


def directions(n, seed):
    """Random directions on the upper hemisphere, grazing ones included (float64)."""
    rng = np.random.default_rng(seed)
    mu = rng.uniform(0.0, 1.0, n) ** 2          # many near grazing
    mu[:8] = [1.0, 1e-4, 1e-3, 0.01, 0.5, 0.999, 0.02, 0.3]
    phi = rng.uniform(0, 2 * math.pi, n)
    s = np.sqrt(1 - mu ** 2)
    return np.stack([s * np.cos(phi), s * np.sin(phi), mu])


def vec(d):
    return mi.Vector3f(*[mi.Float(x.astype(np.float32)) for x in d])


def qualitative(rho, sigma, wi, wo):
    """The seed's formula with the angles themselves (float64)."""
    ti, to = np.arccos(np.clip(wi[2], -1, 1)), np.arccos(np.clip(wo[2], -1, 1))
    dphi = np.arctan2(wo[1], wo[0]) - np.arctan2(wi[1], wi[0])
    s2 = sigma ** 2
    A, B = 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
    alpha, beta = np.maximum(ti, to), np.minimum(ti, to)
    return rho / np.pi * (A + B * np.maximum(0, np.cos(dphi)) * np.sin(alpha) * np.tan(beta))


def eon(rho, sigma, wi, wo):
    """EON (Portsmouth, Kutz, Hill 2025, eq. for f_ss, f_ms, E_FON with its G term in the
    paper's form), with r = B/A of the seed's formula at sigma (float64)."""
    s2 = sigma ** 2
    r = (0.45 * s2 / (s2 + 0.09)) / (1 - 0.5 * s2 / (s2 + 0.33))
    c1, c2 = 0.5 - 2 / (3 * np.pi), 2 / 3 - 28 / (15 * np.pi)
    af = 1 / (1 + c1 * r)

    def e_fon(mu):
        si = np.sqrt(1 - mu * mu)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = si * (np.arccos(mu) - si * mu) + 2 / 3 * ((si / mu) * (1 - si ** 3) - si)
        g = np.where(mu > 1e-6, g, np.pi / 2 - 2 / 3)   # the limit at grazing
        return af + r * af / np.pi * g
    s = wi[0] * wo[0] + wi[1] * wo[1]
    st = np.where(s > 0, s / np.maximum(wi[2], wo[2]), s)
    f_ss = rho / np.pi * af * (1 + r * st)
    avg = af * (1 + c2 * r)
    rho_ms = rho * rho * avg / (1 - rho * (1 - avg))
    f_ms = rho_ms / np.pi * (1 - e_fon(wo[2])) * (1 - e_fon(wi[2])) / (1 - avg)
    return f_ss + f_ms


def evaluate(b, wi, wo):
    n = wi.shape[1]
    f = np.array(b.eval(mi.BSDFContext(), make_si(n, vec(wi)), vec(wo)), np.float64)
    return f.reshape(-1, n)


# ---------------------------------------------------------------------------
# no films: the formulas
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("model, reference", [("qualitative", qualitative), ("eon", eon)])
def test_no_films_is_the_formula_and_reciprocal(model, reference):
    wi, wo = directions(20000, 1), directions(20000, 2)
    for sigma in SIGMAS:
        b = load("", sigma, model, reflectance=0.8)
        got = evaluate(b, wi, wo)
        want = reference(0.8, sigma, wi, wo) * wo[2]
        # float32 evaluation of values <= rho/pi (A + B) ~ 0.4 and of directions rounded
        # to float32 (the tan(beta) sin(alpha) cos(theta_o) product is bounded): the
        # largest error seen is ~1e-6; the issue's bound is 1e-5
        assert np.max(np.abs(got - want)) <= 1e-5, (sigma, np.max(np.abs(got - want)))
        back = evaluate(b, wo, wi)
        ok = (wi[2] > 1e-3) & (wo[2] > 1e-3)
        np.testing.assert_allclose((got / wo[2])[:, ok], (back / wi[2])[:, ok], rtol=2e-5, atol=1e-6)


def test_sigma_zero_is_todays_plugin_bit_for_bit():
    n = 4096
    wi, wo = vec(directions(n, 3)), vec(directions(n, 4))
    rng = mi.PCG32(size=n, initstate=5)
    s1, s2 = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
    ctx = mi.BSDFContext()
    for layers in ("", "SiO2 500; Au 2", "1.46 300"):
        for model in ("qualitative", "eon"):
            a, b = load(layers, None), load(layers, 0.0, model)
            assert not b.base.rough
            si = make_si(n, wi)
            for x, y in zip(a.eval_pdf(ctx, si, wo), b.eval_pdf(ctx, si, wo)):
                assert np.array_equal(np.array(x), np.array(y))
            (bs_a, w_a), (bs_b, w_b) = a.sample(ctx, si, s1, s2), b.sample(ctx, si, s1, s2)
            assert np.array_equal(np.array(w_a), np.array(w_b))
            assert np.array_equal(np.array(bs_a.wo), np.array(bs_b.wo))
    # the rough code at sigma -> 0 is Lambert's to float32 rounding
    lam, rough = load("SiO2 500; Au 2", None), load("SiO2 500; Au 2", 1e-6)
    assert rough.base.rough
    si = make_si(n, wi)
    np.testing.assert_allclose(np.array(rough.eval(ctx, si, wo)), np.array(lam.eval(ctx, si, wo)),
                               rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("variant", ["llvm_ad_spectral", "llvm_ad_rgb"])
def test_sigma_zero_image_is_bit_identical(variant):
    previous = mi.variant()
    mi.set_variant(variant)
    try:
        def image(**extra):
            scene = mi.load_dict({
                "type": "scene", "integrator": {"type": "path", "max_depth": 3},
                "sensor": {"type": "perspective", "fov": 30,
                           "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                           "film": {"type": "hdrfilm", "width": 16, "height": 16,
                                    "rfilter": {"type": "box"}},   # 1 spp + box: deterministic
                           "sampler": {"type": "independent", "sample_count": 1}},
                "emitter": {"type": "constant"},
                "ball": {"type": "sphere", "bsdf": {"type": "thinfilm_diffuse",
                                                    "layers": "SiO2 300; Au 4", **extra}}})
            return scene, np.array(mi.render(scene, seed=3))
        _, before = image()
        scene, zero = image(roughness=0.0)
        assert np.array_equal(before, zero) and before.max() > 0
        params = mi.traverse(scene)
        params["ball.bsdf.roughness.value"] = 0.8      # an edit switches the rough base on ...
        params.update()
        rough = np.array(mi.render(scene, seed=3))
        assert np.all(np.isfinite(rough)) and not np.array_equal(rough, before)
        params["ball.bsdf.roughness.value"] = 0.0      # ... and off again: the old image
        params.update()
        assert np.array_equal(np.array(mi.render(scene, seed=3)), before)
    finally:
        mi.set_variant(previous)


# ---------------------------------------------------------------------------
# sampling
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("model, theta", [("qualitative", 20.0), ("eon", 70.0)])
def test_chi2_and_weights_with_films(model, theta):
    b = load("SiO2 500; Si 20", 1.2, model, reflectance={"type": "rgb", "value": [0.7, 0.4, 0.2]})
    t = math.radians(theta)
    wi = mi.Vector3f(math.sin(t) * 0.6, math.sin(t) * 0.8, math.cos(t))
    ctx = mi.BSDFContext()

    def sample_func(sample):
        bs, w = b.sample(ctx, make_si(dr.width(sample), wi), sample[0], mi.Point2f(sample[1], sample[2]))
        return bs.wo, dr.select((bs.sampled_component == 1) & dr.any(w != 0), 1.0, 0.0)

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func,
                         pdf_func=lambda wo: b.pdf(ctx, make_si(dr.width(wo), wi), wo),
                         sample_dim=3, sample_count=200_000, res=32, ires=4)
    assert test.run(0.01), test.messages
    # weight = eval / pdf on the diffuse samples
    n = 4096
    rng = mi.PCG32(size=n, initstate=8)
    si = make_si(n, wi)
    bs, w = b.sample(ctx, si, rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32()))
    f, p = b.eval_pdf(ctx, si, bs.wo)
    diff = np.array(bs.sampled_component) == 1
    np.testing.assert_allclose(np.array(w)[:, diff], (np.array(f) / np.array(p))[:, diff], rtol=2e-5)


def test_reciprocal_with_films():
    wi, wo = directions(4000, 6), directions(4000, 7)
    for model in ("qualitative", "eon"):
        for mult in ("single", "multiple"):
            b = load("SiO2 500; Cu 5", 0.9, model, model=mult)
            f, back = evaluate(b, wi, wo), evaluate(b, wo, wi)
            ok = (wi[2] > 1e-3) & (wo[2] > 1e-3)
            np.testing.assert_allclose((f / wo[2])[:, ok], (back / wi[2])[:, ok], rtol=2e-5, atol=1e-7)


# ---------------------------------------------------------------------------
# energy (furnace)
# ---------------------------------------------------------------------------
def test_furnace_bare_bases():
    for sigma in (0.3, math.pi / 2):
        white = load("", sigma, "eon", reflectance=1.0)
        q = load("", sigma, "qualitative", reflectance=1.0)
        s2 = sigma ** 2
        A, B = 1 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)
        for theta in (0.0, 45.0, 80.0, 89.0):
            mean, err = mc_albedo(white, theta, n=1 << 17)
            # EON reflects everything: 5 standard errors (<= 2e-3 here) plus float32
            assert np.all(np.abs(mean - 1.0) <= 5 * err + 1e-5), (sigma, theta, mean, err)
            mu = math.cos(math.radians(theta))
            S = math.sin(math.radians(theta))
            h = (S * (math.radians(theta) - S * mu) + 2 / 3 * S * mu * (1 + S + S * S) / (1 + S)) / math.pi
            mean, err = mc_albedo(q, theta, n=1 << 17)
            assert np.all(np.abs(mean - (A + B * h)) <= 5 * err + 1e-5), (sigma, theta, mean, A + B * h)
        if sigma == math.pi / 2:     # the seed's model loses 44 % at normal incidence here
            assert A < 0.56


@pytest.mark.parametrize("model", ["qualitative", "eon"])
def test_furnace_with_films(model):
    for layers in ("SiO2 500; Au 2", "SiO2 300; Au 4", "Si 50; SiO2 100; Cu 5"):
        b = load(layers, math.pi / 2, model, reflectance=1.0)
        for theta in (0.0, 60.0, 85.0):
            mean, err = mc_albedo(b, theta, n=1 << 17)
            assert np.all(mean <= 1.0 + 5 * err + 1e-5), (layers, theta, mean, err)
    # lossless films over a white EON base: the interreflection weighs the coating's
    # reflection of the base's exitance by the cosine (R_dh) where the base's lobe is not
    # Lambert's; benchmarks/orennayar_energy.py measures the albedo within [0.987, 1.011]
    # (1.46 500 nm, sigma = pi/2, by quadrature); 5 standard errors on top
    b = load("1.46 500", math.pi / 2, model, reflectance=1.0)
    mean, err = mc_albedo(b, 0.0, n=1 << 18)
    assert np.all(mean <= 1.012 + 5 * err), mean
    if model == "eon":
        assert np.all(np.abs(mean - 1.0) <= 0.013 + 5 * err), mean


# ---------------------------------------------------------------------------
# RGB: the rough term integrated
# ---------------------------------------------------------------------------
def test_rgb_rough_term_integrates_the_spectral_one():
    """The RGB value against the spectral plugin's eval integrated over 360-830 nm with
    the colour weights the tables use (trapezoid, 1 nm)."""
    from thinfilm_mi.colour import cie
    layers, kd, sigma = "SiO2 500; Au 5", [0.9, 0.6, 0.3], 1.0
    wi, wo = directions(20, 9)[:, 4:10], directions(20, 10)[:, 4:10]
    wl = np.arange(360.0, 831.0)
    w = cie.channel_weights("rgb", wl) * cie.trapezoid_weights(wl)[None, :]
    w /= w.sum(axis=1, keepdims=True)
    for mult in ("single", "multiple"):
        spec = []
        for c in range(3):
            b = load(layers, sigma, "eon", reflectance=kd[c], model=mult)
            # one lane per (group of 4 wavelengths, direction pair)
            groups, n = -(-wl.size // 4), wi.shape[1]
            lam = np.minimum(np.arange(groups * 4), wl.size - 1).reshape(groups, 4)
            si = make_si(groups * n, vec(np.tile(wi, groups)))
            si.wavelengths = mi.Spectrum(*[mi.Float(np.repeat(wl[lam[:, j]], n)) for j in range(4)])
            f = np.array(b.eval(mi.BSDFContext(), si, vec(np.tile(wo, groups))), np.float64)
            per_wl = f.reshape(4, groups, n).transpose(1, 0, 2).reshape(groups * 4, n)[:wl.size]
            spec.append(w[c] @ per_wl)
        spec = np.array(spec)
        mi.set_variant("llvm_ad_rgb")
        try:
            b = load(layers, sigma, "eon", reflectance={"type": "rgb", "value": kd}, model=mult)
            assert not b.colour.fixed
            got = evaluate(b, wi, wo)
        finally:
            mi.set_variant("llvm_ad_spectral")
        # the tables' interpolation (<= 3e-4 of pi f, LINEAR_ABS) and the series expansion
        np.testing.assert_allclose(got, spec, atol=3e-4 / math.pi + 1e-5)


# ---------------------------------------------------------------------------
# gradients
# ---------------------------------------------------------------------------
def _grad_vs_fd(variant, model, texture):
    mi.set_variant(variant)
    try:
        rough = ({"type": "bitmap", "raw": True, "filter_type": "nearest",
                  "bitmap": mi.Bitmap(np.array([[0.4, 0.9], [0.6, 1.2]], np.float32)[..., None])}
                 if texture else 0.7)
        b = load("SiO2 300; Au 4", rough, model, reflectance=0.8)
        wi, wo = directions(256, 11), directions(256, 12)
        params = mi.traverse(b)
        key = "roughness.data" if texture else "roughness.value"
        x0 = np.array(params[key], np.float64).ravel()

        def total(x):
            params[key] = type(params[key])(np.asarray(x, np.float32).reshape(np.shape(params[key])))
            params.update()
            return float(np.sum(evaluate(b, wi, wo)))
        h = 1e-2
        fd = []
        for j in range(x0.size):
            e = np.zeros_like(x0)
            e[j] = h
            fd.append((total(x0 + e) - total(x0 - e)) / (2 * h))
        total(x0)
        value = params[key]
        dr.enable_grad(value)
        params.update()
        n = wi.shape[1]
        si = make_si(n, vec(wi))      # uv (0.3, 0.7): one texel of a 2 x 2 nearest bitmap
        f = b.eval(mi.BSDFContext(), si, vec(wo))
        dr.backward(dr.sum(f, axis=None))
        g = np.array(dr.grad(value), np.float64).ravel()
        return g, np.array(fd)
    finally:
        mi.set_variant("llvm_ad_spectral")


@pytest.mark.parametrize("variant", ["llvm_ad_spectral", "llvm_ad_rgb"])
@pytest.mark.parametrize("model", ["qualitative", "eon"])
def test_roughness_gradient_constant(variant, model):
    g, fd = _grad_vs_fd(variant, model, False)
    # central difference in float32 sums of 256 x channels values: the truncation
    # (h^2 f'''/6) and rounding (~1e-6 x sum / h) are < 1e-3 relative here
    np.testing.assert_allclose(g, fd, rtol=2e-3)
    assert abs(fd[0]) > 1e-2


def test_roughness_gradient_texture():
    g, fd = _grad_vs_fd("llvm_ad_spectral", "eon", True)
    # every hit reads one texel (nearest filter): its derivative, zero for the others;
    # tolerance as for a constant roughness
    assert g.size == 4 and np.count_nonzero(g) == 1 and np.count_nonzero(fd) == 1
    np.testing.assert_allclose(g, fd, rtol=2e-3)
    assert np.max(np.abs(fd)) > 1e-2


# ---------------------------------------------------------------------------
# variants and input
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("variant", ["llvm_ad_mono", "llvm_ad_rgb", "llvm_ad_spectral_polarized"])
def test_other_variants_no_films_formula(variant):
    mi.set_variant(variant)
    try:
        wi, wo = directions(2000, 13), directions(2000, 14)
        b = load("", 0.8, "qualitative", reflectance=0.8)
        n = wi.shape[1]
        f = b.eval(mi.BSDFContext(), make_si(n, vec(wi)), vec(wo))
        if mi.is_polarized:      # a depolarizer: only the (0, 0) Mueller entry
            f = f[0, 0]
        got = np.array(f, np.float64).reshape(-1, n)
        assert np.max(np.abs(got - qualitative(0.8, 0.8, wi, wo) * wo[2])) <= 1e-5
        filmed = load("SiO2 300; Au 4", 0.8, "eon")
        _, w = filmed.sample(mi.BSDFContext(), make_si(n, vec(wi)), mi.Float(0.9),
                             mi.Point2f(0.3, 0.6))
        w = w[0, 0] if mi.is_polarized else w
        assert np.all(np.isfinite(np.array(w, np.float64))) and np.any(np.array(w, np.float64) > 0)
    finally:
        mi.set_variant("llvm_ad_spectral")


@pytest.mark.parametrize("value, pattern", [
    (-0.1, r"'roughness'.*-0\.1"), (2.0, r"'roughness'.*2\.0"), (math.nan, r"'roughness'.*nan"),
    ("rough", r"'roughness'.*'rough'"),
    ({"type": "bitmap", "raw": True, "bitmap": mi.Bitmap(np.full((2, 2, 1), 3.0, np.float32))},
     r"'roughness'.*values in \[3\.0, 3\.0\]"),
])
def test_bad_roughness(value, pattern):
    with pytest.raises(Exception, match=pattern) as info:
        load("SiO2 300; Au 4", value)
    assert "ThinFilmError" in str(info.value) or isinstance(info.value, ThinFilmError)
    with pytest.raises(Exception, match=r"'roughness_model'.*'fujii'"):
        load("", 0.3, "fujii")
