"""Tests of the coated Lambertian BSDF ``thinfilm_diffuse``.

Monte Carlo checks use fixed seeds (``mi.PCG32`` / the chi2 test's TEA streams)
and tolerances of several standard errors computed from the samples
themselves, plus a float32 allowance where stated.
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

WAVELENGTHS = (450.0, 520.0, 600.0, 680.0)
DIFFUSE = mi.BSDFFlags.DiffuseReflection


def make_si(n, wi, wavelengths=WAVELENGTHS, uv=(0.3, 0.7)):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = wi
    si.uv = mi.Point2f(*uv)
    si.wavelengths = mi.Spectrum(*wavelengths)
    return si


def direction(theta_deg, phi_deg=0.0):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return mi.Vector3f(math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def bsdf(layers, model="multiple", reflectance=None, **extra):
    d = {"type": "thinfilm_diffuse", "layers": layers, "model": model, "tabulate": False, **extra}
    if reflectance is not None:
        d["reflectance"] = reflectance
    return mi.load_dict(d)


def ctx_for(component=None):
    ctx = mi.BSDFContext()
    if component is not None:
        ctx.component = component
    return ctx


def to_np(spec):
    return np.array(spec, dtype=np.float64)


def mc_albedo(b, wi, n=1 << 18, seed=1, ctx=None):
    """Per-wavelength mean and standard error of the sample() weights."""
    rng = mi.PCG32(size=n, initstate=seed)
    s1 = rng.next_float32()
    s2 = mi.Point2f(rng.next_float32(), rng.next_float32())
    si = make_si(n, wi)
    _, w = b.sample(ctx or mi.BSDFContext(), si, s1, s2)
    w = to_np(w)  # (4, n)
    return w.mean(axis=1), w.std(axis=1) / math.sqrt(n)


# ---------------------------------------------------------------------------
# chi2: the sampled directions of the diffuse lobe (selection included) follow pdf()
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("theta, model", [(0.0, "multiple"), (50.0, "multiple"),
                                          (85.0, "single")])


def test_chi2_diffuse_lobe(theta, model):
    # Si 20 nm under SiO2 passes enough light that both lobes are picked often,
    # so a wrong selection probability in pdf() would show as a scale error.
    b = bsdf("SiO2 500; Si 20", model,
             reflectance={"type": "rgb", "value": [0.7, 0.4, 0.2]})
    wi = direction(theta, 30.0)
    ctx = mi.BSDFContext()

    def sample_func(sample):
        n = dr.width(sample)
        bs, w = b.sample(ctx, make_si(n, wi), sample[0], mi.Point2f(sample[1], sample[2]))
        # Delta samples are not part of the density: give them weight 0, so the
        # histogram integrates to P(diffuse) like the pdf does.
        keep = (bs.sampled_component == 1) & dr.any(w != 0)
        return bs.wo, dr.select(keep, 1.0, 0.0)

    def pdf_func(wo):
        return b.pdf(ctx, make_si(dr.width(wo), wi), wo)

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func,
                         pdf_func=pdf_func, sample_dim=3, sample_count=300_000,
                         res=32, ires=4)
    assert test.run(0.01), test.messages
    # The mass of the histogram is P(diffuse) < 1: the specular lobe is sampled too.
    assert 0.02 < float(test.histogram_sum[0]) < 0.98


# ---------------------------------------------------------------------------
# energy
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("layers", ["SiO2 500; Au 2", "SiO2 500; Si 50", "Au 20",
                                    "Si 50; SiO2 100; Cu 5", "Au 3; 1.46 200"])


@pytest.mark.parametrize("model", ["single", "multiple"])
def test_albedo_at_most_one(layers, model):
    b = bsdf(layers, model, reflectance=1.0)
    for theta in (0.0, 45.0, 80.0, 89.0):
        mean, err = mc_albedo(b, direction(theta))
        # 5 standard errors of the estimate plus 1e-5 for float32 sums.
        assert np.all(mean <= 1.0 + 5.0 * err + 1e-5), (layers, model, theta, mean, err)
        assert np.all(mean >= 0.0)


@pytest.mark.parametrize("layers", ["1.46 500", "1.46 500; 2.35 80; 1.38 120", "SiO2 300; 2.0 60"])
def test_lossless_white_albedo_is_one(layers):
    b = bsdf(layers, "multiple", reflectance=1.0)
    for theta in (0.0, 40.0, 75.0):
        mean, err = mc_albedo(b, direction(theta), n=1 << 20, seed=7)
        # The expectation is k_r + t*T_hemi/(1 - R_dh) with T_hemi + R_dh = 1 to
        # rounding (same quadrature nodes), so 1 up to the Gauss-Legendre error of
        # T_hemi (< 1e-6) and float32 (the stack in the kernel, ~1e-6 relative).
        # Allow 5 standard errors (sample std / sqrt(n), ~1e-3 here) plus 2e-5.
        assert np.all(np.abs(mean - 1.0) <= 5.0 * err + 2e-5), (layers, theta, mean, err)
    # ... while the first-order model loses the light the coating sends back.
    single = bsdf(layers, "single", reflectance=1.0)
    mean, err = mc_albedo(single, direction(0.0), n=1 << 18, seed=3)
    assert np.all(mean < 1.0 - 5.0 * err - 1e-3)


def test_single_at_most_multiple():
    rng = np.random.default_rng(5)
    n = 2000
    wi = dr.normalize(mi.Vector3f(*rng.normal(size=(2, n)), rng.uniform(0.05, 1.0, n)))
    wo = dr.normalize(mi.Vector3f(*rng.normal(size=(2, n)), rng.uniform(0.05, 1.0, n)))
    for layers in ("SiO2 500; Au 2", "SiO2 500; Ag 5", "1.46 500; 2.35 80", "Si 20"):
        si = make_si(n, wi)
        f1 = to_np(bsdf(layers, "single", reflectance=0.9).eval(mi.BSDFContext(), si, wo))
        f2 = to_np(bsdf(layers, "multiple", reflectance=0.9).eval(mi.BSDFContext(), si, wo))
        assert np.all(f1 <= f2), layers  # exact: same float32 factors times 1/(1 - k_d R_dh) >= 1
        assert np.all(f1 > 0) and np.any(f2 > f1 * 1.001), layers


# ---------------------------------------------------------------------------
# consistency of eval / pdf / eval_pdf / sample, reciprocity
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("model", ["single", "multiple"])
def test_eval_pdf_sample_consistent_and_reciprocal(model):
    b = bsdf("SiO2 500; Cu 5", model, reflectance={"type": "rgb", "value": [0.2, 0.6, 0.9]})
    n = 4096
    rng = mi.PCG32(size=n, initstate=11)
    wi = mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    s1, s2 = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
    ctx = mi.BSDFContext()
    si = make_si(n, wi)
    bs, w = b.sample(ctx, si, s1, s2)
    f, p = b.eval_pdf(ctx, si, bs.wo)
    np.testing.assert_allclose(to_np(f), to_np(b.eval(ctx, si, bs.wo)), rtol=1e-6, atol=0)
    np.testing.assert_allclose(np.array(p), np.array(b.pdf(ctx, si, bs.wo)), rtol=1e-6, atol=0)
    diff = np.array(bs.sampled_component) == 1
    assert 0 < diff.sum() < n
    # weight = eval / pdf for diffuse samples (float32: a few ulps)
    expect = to_np(f)[:, diff] / np.array(p)[diff]
    np.testing.assert_allclose(to_np(w)[:, diff], expect, rtol=2e-5)
    # delta samples: mirror direction, eval and pdf are zero there
    spec = ~diff
    wo = np.array(bs.wo)[:, spec]
    np.testing.assert_allclose(wo[2], np.array(wi)[2][spec], rtol=1e-6)
    # reciprocity: f(wi, wo)/cos_o == f(wo, wi)/cos_i
    si2 = make_si(n, bs.wo)
    f_rev = to_np(b.eval(ctx, si2, wi))
    cos_i, cos_o = np.array(wi)[2], np.array(bs.wo)[2]
    ok = diff & (cos_o > 1e-3)
    np.testing.assert_allclose((to_np(f) / cos_o)[:, ok], (f_rev / cos_i)[:, ok], rtol=1e-5)


def test_single_component_contexts():
    b = bsdf("SiO2 500; Au 2", reflectance=0.8)
    n = 512
    wi = direction(30.0)
    rng = mi.PCG32(size=n, initstate=2)
    s1, s2 = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
    si = make_si(n, wi)
    bs, w = b.sample(ctx_for(0), si, s1, s2)
    assert np.all(np.array(bs.sampled_component) == 0) and np.all(np.array(bs.pdf) == 1)
    full = bsdf("SiO2 500; Au 2", reflectance=0.8)
    # both exact (a 1-film conductor is tabulated by default, within table_error)
    conductor = mi.load_dict({"type": "thinfilm_conductor", "material": "Au", "layers": "SiO2 500",
                              "tabulate": False})
    _, w_c = conductor.sample(mi.BSDFContext(), si, s1, s2)
    np.testing.assert_allclose(to_np(w), np.broadcast_to(to_np(w_c), (4, n)), rtol=1e-6)
    bs, w = full.sample(ctx_for(1), si, s1, s2)
    assert np.all(np.array(bs.sampled_component) == 1)
    wo = bs.wo
    f = full.eval(ctx_for(1), si, wo)
    p = full.pdf(ctx_for(1), si, wo)
    np.testing.assert_allclose(np.array(p), np.array(mi.warp.square_to_cosine_hemisphere_pdf(wo)),
                               rtol=1e-6)
    np.testing.assert_allclose(to_np(w), to_np(f) / np.array(p), rtol=2e-5)
    # eval with only the delta component enabled is zero
    assert np.all(to_np(full.eval(ctx_for(0), si, wo)) == 0)


# ---------------------------------------------------------------------------
# limits
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("model", ["single", "multiple"])
def test_no_films_is_mitsuba_diffuse(model):
    refl = {"type": "checkerboard", "color0": {"type": "rgb", "value": [0.9, 0.2, 0.1]},
            "color1": {"type": "rgb", "value": [0.1, 0.3, 0.8]}}
    ours = bsdf("", model, reflectance=refl)
    ref = mi.load_dict({"type": "diffuse", "reflectance": refl})
    n = 4096
    rng = mi.PCG32(size=n, initstate=4)
    wi = dr.normalize(mi.Vector3f(rng.next_float32() - 0.5, rng.next_float32() - 0.5,
                                  rng.next_float32() - 0.2))   # some below the horizon
    wo = dr.normalize(mi.Vector3f(rng.next_float32() - 0.5, rng.next_float32() - 0.5,
                                  rng.next_float32() - 0.2))
    si = make_si(n, wi)
    si.uv = mi.Point2f(rng.next_float32(), rng.next_float32())
    ctx = mi.BSDFContext()
    assert np.array_equal(to_np(ours.eval(ctx, si, wo)), to_np(ref.eval(ctx, si, wo)))
    assert np.array_equal(np.array(ours.pdf(ctx, si, wo)), np.array(ref.pdf(ctx, si, wo)))
    f, p = ours.eval_pdf(ctx, si, wo)
    f_r, p_r = ref.eval_pdf(ctx, si, wo)
    assert np.array_equal(to_np(f), to_np(f_r)) and np.array_equal(np.array(p), np.array(p_r))
    s1, s2 = rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())
    bs, w = ours.sample(ctx, si, s1, s2)
    bs_r, w_r = ref.sample(ctx, si, s1, s2)
    assert np.array_equal(np.array(bs.wo), np.array(bs_r.wo))
    assert np.array_equal(np.array(bs.pdf), np.array(bs_r.pdf))
    assert np.array_equal(to_np(w), to_np(w_r))
    assert np.all(np.array(bs.sampled_type) == int(mi.BSDFFlags.DiffuseReflection))
    assert np.any(to_np(w) > 0) and np.any(np.array(wi)[2] < 0)


@pytest.mark.parametrize("layers, int_ior", [("1.46 300", None), ("SiO2 500", None),
                                             ("2.35 80; 1.38 120", None)])


def test_lossless_film_specular_equals_thinfilm_dielectric(layers, int_ior):
    # With no absorbing film N the coating is the whole stack over a base medium
    # of index ext_ior: the same stack as thinfilm_dielectric with int_ior = ext_ior.
    ext = 1.000277
    ours = bsdf(layers, reflectance=0.5)
    diel = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers, "int_ior": ext,
                         "tabulate": False})
    n = 256
    cos = np.linspace(0.01, 1.0, n)
    wi = mi.Vector3f(np.sqrt(1 - cos**2), 0.0 * cos, cos)
    si = make_si(n, wi)
    z = mi.Float(0.0)
    _, w = ours.sample(ctx_for(0), si, z, mi.Point2f(z, z))
    ctx_r = mi.BSDFContext()
    ctx_r.component = 0
    _, w_d = diel.sample(ctx_r, si, z, mi.Point2f(z, z))
    # Same float32 recursion on the same inputs: equal to float32 rounding.
    np.testing.assert_allclose(to_np(w), to_np(w_d), rtol=1e-6, atol=1e-7)
    assert np.ptp(to_np(w)) > 1e-3  # the films do interfere


@pytest.mark.parametrize("layers, material, cover", [("Au 20", "Au", ""),
                                                     ("SiO2 500; Au 2", "Au", "SiO2 500"),
                                                     ("1.46 500; Si 20", "Si", "1.46 500")])


def test_absorbing_film_specular_equals_thinfilm_conductor(layers, material, cover):
    # The paper's table step: k_r is films 1..N-1 over (bulk) film N.
    ours = bsdf(layers, reflectance=0.5)
    cond = mi.load_dict({"type": "thinfilm_conductor", "material": material, "layers": cover,
                         "tabulate": False})
    n = 128
    cos = np.linspace(0.02, 1.0, n)
    si = make_si(n, mi.Vector3f(np.sqrt(1 - cos**2), 0.0 * cos, cos))
    z = mi.Float(0.0)
    _, w = ours.sample(ctx_for(0), si, z, mi.Point2f(z, z))
    _, w_c = cond.sample(mi.BSDFContext(), si, z, mi.Point2f(z, z))
    np.testing.assert_allclose(to_np(w), to_np(w_c), rtol=1e-6, atol=1e-7)


def test_traverse_thickness_updates_hemispherical_factors():
    b = bsdf("SiO2 500; Au 2", reflectance=0.9)
    params = mi.traverse(b)
    assert "layers.1.thickness" in params and "layers.0.thickness" in params
    params["layers.1.thickness"] = 5.0
    params["layers.0.thickness"] = 420.0
    params.update()
    fresh = bsdf("SiO2 420; Au 5", reflectance=0.9)
    n = 64
    rng = mi.PCG32(size=n, initstate=9)
    wi = mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    wo = mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    si = make_si(n, wi)
    np.testing.assert_allclose(to_np(b.eval(mi.BSDFContext(), si, wo)),
                               to_np(fresh.eval(mi.BSDFContext(), si, wo)), rtol=1e-5)
    np.testing.assert_allclose(np.array(b.pdf(mi.BSDFContext(), si, wo)),
                               np.array(fresh.pdf(mi.BSDFContext(), si, wo)), rtol=1e-5)


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("extra, pattern", [
    ({"model": "double"}, r"model.*'double'"),
    ({"model": "single", "reflectance": 1.5}, r"reflectance.*1\.5"),
    ({"reflectance": -0.1}, r"reflectance.*-0\.1"),
    ({"reflectance": {"type": "uniform", "value": 2.0}}, r"reflectance.*<= 1\.001.*\[2\.0, 2\.0\]"),
    ({"reflectance": {"type": "uniform", "value": -1.0}}, r"reflectance.*\[-1\.0, -1\.0\]"),
    ({"reflectance": {"type": "uniform", "value": float("nan")}}, r"reflectance.*nan"),
    ({"layers": "SiO2"}, r"layers\[0\].*missing thickness"),
    ({"layers": "SiO2 500", "thin_film_ior": 1.4, "thin_film_thickness": 100.0}, r"layers"),
    ({"ext_ior": "Au"}, r"ext_ior"),
    ({"roughness": 2.0}, r"roughness.*2\.0"),          # sigma <= pi/2 (radians)
    ({"roughness_model": "oren"}, r"roughness_model.*'oren'"),
])


def test_bad_input(extra, pattern):
    d = {"type": "thinfilm_diffuse", **extra}
    with pytest.raises(Exception, match=pattern):
        mi.load_dict(d)


def test_shorthand_equals_layers():
    a = mi.load_dict({"type": "thinfilm_diffuse", "thin_film_ior": "Si", "thin_film_thickness": 20.0,
                      "model": "multiple"})
    b = bsdf("Si 20")
    si = make_si(3, direction(20.0))
    wo = dr.normalize(mi.Vector3f([0.1, 0.5, 0.9], [0.0, 0.2, 0.1], [1.0, 0.6, 0.2]))
    assert np.array_equal(to_np(a.eval(mi.BSDFContext(), si, wo)),
                          to_np(b.eval(mi.BSDFContext(), si, wo)))


def test_scalar_variant_samples_and_edits_with_films():
    """scalar_spectral: the lobe choice reduces the spectrum to one number (it used to
    compare a 4-wide spectrum with the sample and fail), and an edit rebuilds the
    hemispherical spectra (a scalar mi.Float cannot hold them)."""
    mi.set_variant("scalar_spectral")
    try:
        bsdf = mi.load_dict({"type": "thinfilm_diffuse", "layers": "1.5 200; SiO2 50"})
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wavelengths = mi.Spectrum(450.0, 520.0, 610.0, 700.0)
        si.wi = mi.Vector3f(0.3, 0.0, 0.95)
        for s1 in (0.01, 0.99):
            bs, w = bsdf.sample(mi.BSDFContext(), si, s1, mi.Point2f(0.4, 0.5))
            assert all(math.isfinite(float(v)) and float(v) > 0 for v in w)
        before = [float(v) for v in bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0.1, 0.2, 0.97))]
        params = mi.traverse(bsdf)
        params["layers.0.eta.value"] = 1.7
        params.update()
        after = [float(v) for v in bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0.1, 0.2, 0.97))]
        assert after != before and all(math.isfinite(v) for v in after)
    finally:
        mi.set_variant("llvm_ad_spectral")
