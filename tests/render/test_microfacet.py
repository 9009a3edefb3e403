"""The microfacet model the rough plugins share (thinfilm_mi/render/microfacet.py),
through ``thinfilm_roughconductor`` and ``thinfilm_roughdielectric``: Mitsuba
equivalence with no films, chi2 of the sampling routines, reflection values against a
float64 reference, eval/pdf/sample consistency, energy, components, traversal, the
``thickness`` texture, scalar variants, bad input, a scene render."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
from mitsuba.chi2 import ChiSquareTest, SphericalDomain  # noqa: E402

import thinfilm_mi as tf  # noqa: E402  (registers the plugins)
from tests.support import ROOT
from tests.support.bsdf import context, direction, to_np
from tests.support.rough import (
    COND_FILMS,
    COND_SUB,
    DG_RTOL,
    DIEL_FILMS,
    DIEL_SUB,
    WLS,
    conductor,
    dielectric,
    f32_vec,
    films_tol,
    layers_of,
    make_si,
    random_dirs,
    random_samples,
    ref_D,
    ref_G1,
)

ROOT = ROOT
GLOSSY_R = mi.BSDFFlags.GlossyReflection
GLOSSY_T = mi.BSDFFlags.GlossyTransmission


# ---------------------------------------------------------------------------
# no films = Mitsuba's roughconductor / roughdielectric, image for image
# ---------------------------------------------------------------------------
def _scene(bsdf, size=32):
    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 5},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": T().look_at([0.5, 1.2, 3.5], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "env": {"type": "constant", "radiance": 0.4},
        "light": {"type": "point", "position": [-2.0, 3.0, 2.0], "intensity": 25.0},
        "floor": {"type": "rectangle",
                  "to_world": T().translate([0, -1, 0]) @ T().rotate([1, 0, 0], -90) @ T().scale(4),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard"}}},
        "obj": {"type": "sphere", "bsdf": bsdf},
    })


@pytest.mark.parametrize("kind", ["conductor", "dielectric"])
def test_no_films_renders_like_mitsuba(kind):
    if kind == "conductor":  # anisotropic GGX (the sphere has uv, hence tangents)
        common = {"eta": 0.2, "k": 3.1, "distribution": "ggx", "alpha_u": 0.3, "alpha_v": 0.08}
        ref = {"type": "roughconductor", **common}
        # Mitsuba's eta/k are relative to the exterior: give ext_ior = 1 to match.
        ours = {"type": "thinfilm_roughconductor", "layers": "", "ext_ior": 1.0, **common}
    else:
        common = {"int_ior": 1.5, "alpha": 0.2}
        ref = {"type": "roughdielectric", **common}
        ours = {"type": "thinfilm_roughdielectric", "layers": "", **common}
    a = to_np(mi.render(_scene(ref), seed=3))
    b = to_np(mi.render(_scene(ours), seed=3))
    assert np.all(np.isfinite(b))
    # Same directions from the same random numbers; the film recursion with no
    # films is the single-interface Fresnel up to float32 rounding (~1e-7), and
    # R + T = 1 picks reflection with the same probability F. Rare lanes where
    # sample1 falls within rounding of F could flip a choice, hence not bit equality.
    rel = np.abs(a - b).mean() / np.abs(a).mean()
    assert rel < 1e-4, rel


# ---------------------------------------------------------------------------
# chi2: sample() draws directions with the density pdf() returns
# ---------------------------------------------------------------------------
CHI2_CASES = [
    # (plugin, extra props, theta_i (deg, > 90: from inside), phi_i, context)
    ("conductor", {"distribution": "beckmann", "alpha": 0.3}, 0.0, 0.0, None),
    ("conductor", {"distribution": "ggx", "alpha_u": 0.4, "alpha_v": 0.1}, 45.0, 30.0, None),
    ("conductor", {"distribution": "ggx", "alpha": 0.25}, 85.0, 0.0, None),
    ("conductor", {"distribution": "beckmann", "alpha_u": 0.15, "alpha_v": 0.35,
                   "sample_visible": False}, 60.0, 70.0, None),
    # At normal incidence the refracted lobe is (eta - 1) / eta narrower and sits at
    # the pole, within one row of the chi2 grid: alpha 0.5 keeps the 16x16 cell
    # integration of the pdf accurate (Mitsuba's roughdielectric fails at alpha 0.3 too).
    ("dielectric", {"distribution": "beckmann", "alpha": 0.5}, 0.0, 0.0, None),
    ("dielectric", {"distribution": "ggx", "alpha_u": 0.4, "alpha_v": 0.15}, 50.0, 20.0, None),
    ("dielectric", {"distribution": "beckmann", "alpha_u": 0.2, "alpha_v": 0.4}, 85.0, 60.0, None),
    ("dielectric", {"distribution": "ggx", "alpha": 0.3}, 160.0, 10.0, None),
    # from inside beyond the critical angle (41.8 deg): mostly TIR, T = 0 on those facets
    ("dielectric", {"distribution": "beckmann", "alpha": 0.25, "sample_visible": False},
     130.0, 0.0, None),
    ("dielectric", {"distribution": "ggx", "alpha_u": 0.3, "alpha_v": 0.1}, 150.0, 45.0, 1),
    ("dielectric", {"distribution": "beckmann", "alpha": 0.35}, 70.0, 0.0, 0),
]


@pytest.mark.parametrize("plugin,extra,theta,phi,component", CHI2_CASES)
def test_chi2(plugin, extra, theta, phi, component):
    b = (conductor if plugin == "conductor" else dielectric)(**extra)
    wi = direction(theta, phi)
    ctx = context(component)

    def sample_func(sample):
        n = dr.width(sample)
        bs, w = b.sample(ctx, make_si(n, wi), sample[0], mi.Point2f(sample[1], sample[2]))
        return bs.wo, dr.select(dr.any(w != 0), 1.0, 0.0)

    def pdf_func(wo):
        return b.pdf(ctx, make_si(dr.width(wo), wi), wo)

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=200_000, res=24, ires=16)
    assert test.run(0.01), test.messages
    mass = float(test.histogram_sum[0])
    assert mass > 0.2  # the test saw a real lobe


@pytest.mark.parametrize("dist,au,av", [("beckmann", 0.2, 0.2), ("ggx", 0.35, 0.12)])
@pytest.mark.parametrize("kind", ["conductor", "dielectric_out", "dielectric_in"])
def test_reflection_matches_float64_reference(dist, au, av, kind):
    rng = np.random.default_rng(17)
    n = 512
    inside = kind == "dielectric_in"
    wi = random_dirs(rng, n, lower=inside)
    wo = random_dirs(rng, n, lower=inside)
    aniso = {"alpha": au} if au == av else {"alpha_u": au, "alpha_v": av}
    b = conductor(distribution=dist, **aniso) if kind == "conductor" else \
        dielectric(distribution=dist, **aniso)
    ours = to_np(b.eval(mi.BSDFContext(), make_si(n, f32_vec(wi)), f32_vec(wo))).T  # (n, 4)
    m = wi + wo
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    m *= np.sign(m[:, 2:3])
    cos_m = np.abs(np.sum(wi * m, axis=1))
    if kind == "conductor":
        stack = tf.Stack(COND_FILMS, substrate=COND_SUB, ambient=1.0)
    else:
        stack = tf.Stack(DIEL_FILMS, substrate=DIEL_SUB, ambient=1.0)
        if inside:
            stack = stack.reversed()
    F = stack.rt(np.array(WLS)[None, :], np.arccos(np.clip(cos_m, 0, 1))[:, None]).R
    k = (ref_D(m, au, av, dist) * ref_G1(wi, m, au, av, dist) * ref_G1(wo, m, au, av, dist)
         / (4 * np.abs(wi[:, 2]) * np.abs(wo[:, 2])))[:, None]
    ref = F * k
    got = ours / np.abs(wo[:, 2:3])  # eval() includes cos(theta_o)
    tol = k * (films_tol(b) + DG_RTOL * F)
    ok = np.isfinite(ref)
    assert np.all(np.abs(got - ref)[ok] <= tol[ok]), np.max(np.abs(got - ref)[ok] / tol[ok])
    assert ok.mean() > 0.95 and np.count_nonzero(ref > 1e-3) > n // 4  # a real test, not zeros against zeros


# ---------------------------------------------------------------------------
# sample() weights are eval / pdf; pdf(), eval_pdf() and bs.pdf agree
# ---------------------------------------------------------------------------
CONSISTENCY = [
    ("conductor", {"distribution": "ggx", "alpha_u": 0.3, "alpha_v": 0.1}, None, None),
    ("conductor", {"distribution": "beckmann", "alpha": 0.2, "sample_visible": False}, None, None),
    ("dielectric", {"distribution": "ggx", "alpha": 0.2}, None, None),
    ("dielectric", {"distribution": "beckmann", "alpha_u": 0.3, "alpha_v": 0.15,
                    "sample_visible": False}, None, None),
    ("dielectric", {"distribution": "beckmann", "alpha": 0.2}, 0, None),
    ("dielectric", {"distribution": "ggx", "alpha": 0.2}, 1, mi.TransportMode.Importance),
    ("dielectric", {"distribution": "beckmann", "alpha": 0.2}, None, mi.TransportMode.Importance),
]


@pytest.mark.parametrize("plugin,extra,component,mode", CONSISTENCY)
def test_sample_eval_pdf_consistent(plugin, extra, component, mode):
    b = (conductor if plugin == "conductor" else dielectric)(**extra)
    ctx = context(component, mode=mode)
    n = 4096
    rng = np.random.default_rng(5)
    wi_np = random_dirs(rng, n, lower=False)
    if plugin == "dielectric":  # half the rays from inside
        wi_np[::2, 2] *= -1
    wi = f32_vec(wi_np)
    s1, s2 = random_samples(n, 9)
    si = make_si(n, wi)
    bs, w = b.sample(ctx, si, s1, s2)
    f, p = b.eval_pdf(ctx, si, bs.wo)
    f_only, p_only = to_np(b.eval(ctx, si, bs.wo)), to_np(b.pdf(ctx, si, bs.wo))
    w, f, p, bs_pdf = to_np(w), to_np(f), to_np(p), to_np(bs.pdf)
    np.testing.assert_array_equal(f, f_only)
    np.testing.assert_array_equal(p, p_only)
    valid = np.any(w > 0, axis=0)
    assert valid.mean() > 0.5
    # The sampler builds m directly, eval/pdf rebuild it from wo (float32 rounding of
    # order 1e-7 in m, amplified by D's exponent and the Jacobians): 1e-3 relative.
    np.testing.assert_allclose(p[valid], bs_pdf[valid], rtol=1e-3)
    np.testing.assert_allclose(w[:, valid], f[:, valid] / p[valid], rtol=2e-3, atol=1e-6)
    # Zero weights: facets that send the sample to the wrong side (G1(wo) = 0, as
    # in Mitsuba; the direction may still be reached by the other lobe), or total
    # internal reflection on a facet when only transmission is asked for (T = 0).
    lost = ~valid & (bs_pdf > 0)
    wrong_side = (to_np(bs.wo)[2] * wi_np[:, 2] > 0) != (to_np(bs.sampled_type) == int(GLOSSY_R))
    tir = (component == 1) & (wi_np[:, 2] < 0)
    assert np.all((wrong_side | tir)[lost])
    if component is not None:  # only the requested lobe is ever sampled
        types = to_np(bs.sampled_type)[valid]
        want = GLOSSY_R if component == 0 else GLOSSY_T
        assert np.all(types == int(want))
        same_side = (to_np(bs.wo)[2] * wi_np[:, 2] > 0)[valid]
        assert np.all(same_side == (component == 0))


# ---------------------------------------------------------------------------
# energy
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("plugin,layers", [
    ("conductor", "1.46 300; 2.3 60"), ("conductor", "0.42+2.47j 15; 1.46 200"),
    ("dielectric", "1.46 300; 0.42+2.47j 10"), ("dielectric", "2.3 80; 1.38 120"),
])


def test_albedo_at_most_one(plugin, layers):
    b = (conductor if plugin == "conductor" else dielectric)(layers=layers, alpha=0.4,
                                                             distribution="ggx")
    # Importance transport: no (eta_i/eta_t)^2 radiance factor, so the mean weight
    # is the fraction of energy the surface scatters.
    ctx = context(mode=mi.TransportMode.Importance)
    n = 1 << 17
    thetas = (0.0, 45.0, 80.0, 89.0) + ((120.0, 170.0) if plugin == "dielectric" else ())
    for theta in thetas:
        s1, s2 = random_samples(n, 2)
        _, w = b.sample(ctx, make_si(n, direction(theta, 25.0)), s1, s2)
        w = to_np(w)
        mean, err = w.mean(axis=1), w.std(axis=1) / math.sqrt(n)
        # 5 standard errors of the estimate plus 1e-5 for float32 sums.
        assert np.all(mean <= 1.0 + 5.0 * err + 1e-5), (theta, mean, err)
        assert np.all(mean > 0.05) and np.all(w >= 0)


# ---------------------------------------------------------------------------
# contexts, flags, traversal
# ---------------------------------------------------------------------------
def test_disabled_components_return_zero():
    n = 64
    s1, s2 = random_samples(n, 3)
    wo = direction(140.0, 10.0)
    for b, mask in ((conductor(), mi.BSDFFlags.DeltaReflection | GLOSSY_T),
                    (dielectric(), mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.DeltaTransmission)):
        ctx = context(type_mask=mask)
        si = make_si(n, direction(30.0))
        _, w = b.sample(ctx, si, s1, s2)
        assert np.all(to_np(w) == 0)
        f, p = b.eval_pdf(ctx, si, direction(40.0, 180.0))
        assert np.all(to_np(f) == 0) and np.all(to_np(p) == 0)
    # the conductor has no back side and no transmission
    b = conductor()
    si = make_si(n, direction(130.0))
    _, w = b.sample(mi.BSDFContext(), si, s1, s2)
    assert np.all(to_np(w) == 0)
    assert np.all(to_np(b.eval(mi.BSDFContext(), make_si(1, direction(30.0)), wo)) == 0)


def test_flags_and_traverse():
    iso, aniso = conductor(alpha=0.2), dielectric(alpha_u=0.2, alpha_v=0.1)
    assert not mi.has_flag(iso.flags(), mi.BSDFFlags.Anisotropic)
    assert mi.has_flag(aniso.flags(), mi.BSDFFlags.Anisotropic)
    assert mi.has_flag(aniso.flags(), GLOSSY_T) and mi.has_flag(aniso.flags(), GLOSSY_R)
    assert iso.component_count() == 1 and aniso.component_count() == 2
    p_iso, p_aniso = mi.traverse(iso), mi.traverse(aniso)
    assert "alpha.value" in p_iso.keys() and "alpha_u.value" not in p_iso.keys()
    assert {"alpha_u.value", "alpha_v.value"} <= set(p_aniso.keys())
    assert "layers.0.thickness" in p_iso.keys() and "layers.1.eta.value" in p_aniso.keys()
    # an edit of alpha takes effect (narrower lobe: more energy at the mirror direction)
    si = make_si(1, direction(30.0))
    wo = direction(30.0, 180.0)
    before = to_np(iso.eval(mi.BSDFContext(), si, wo))
    p_iso["alpha.value"] = 0.05
    p_iso.update()
    after = to_np(iso.eval(mi.BSDFContext(), si, wo))
    assert np.all(after > 10 * before)
    assert "ThinFilmRoughConductor" in str(iso) and "ggx" not in str(iso)
    assert "alpha_u" in str(aniso) and "int_ior = 1.5" in str(aniso)


def test_thickness_texture_scales_the_films():
    # thickness = 0.5 on 300/60 nm films is the same as thickness = 1 on 150/30 nm.
    films_half = [(n, d * 0.5) for n, d in COND_FILMS]
    a = conductor(thickness=0.5)
    b = mi.load_dict({"type": "thinfilm_roughconductor", "layers": layers_of(films_half),
                      "eta": COND_SUB.real, "k": COND_SUB.imag, "ext_ior": 1.0,
                      "thickness": 1.0})
    si, wo = make_si(1, direction(25.0)), direction(35.0, 170.0)
    fa, fb = to_np(a.eval(mi.BSDFContext(), si, wo)), to_np(b.eval(mi.BSDFContext(), si, wo))
    np.testing.assert_allclose(fa, fb, rtol=1e-6)
    assert np.abs(fa - to_np(conductor().eval(mi.BSDFContext(), si, wo))).max() > 1e-3


def test_scalar_variant_matches_llvm():
    # Smoke test of the Python (scalar) path: the same numbers as the LLVM kernel.
    props = [("thinfilm_roughconductor", {"eta": 0.35, "k": 2.9, "alpha_u": 0.2, "alpha_v": 0.1,
                                          "distribution": "ggx"}),
             ("thinfilm_roughdielectric", {"int_ior": 1.5, "alpha": 0.25})]
    wi_w = [(direction(30.0, 10.0), direction(40.0, 200.0)),
            (direction(160.0, 10.0), direction(20.0, 190.0))]
    results = {}
    for variant in ("llvm_ad_spectral", "scalar_spectral"):
        mi.set_variant(variant)
        try:
            out = []
            for (name, extra), (wi, wo) in zip(props, wi_w):
                b = mi.load_dict({"type": name, "layers": "0.42+2.47j 12", **extra})
                si = dr.zeros(mi.SurfaceInteraction3f)
                si.wavelengths = mi.Spectrum(WLS)
                si.wi = mi.Vector3f(*[float(x[0]) for x in (wi.x, wi.y, wi.z)])
                wo_ = mi.Vector3f(*[float(x[0]) for x in (wo.x, wo.y, wo.z)])
                bs, w = b.sample(mi.BSDFContext(), si, 0.4, mi.Point2f(0.3, 0.7))
                f, p = b.eval_pdf(mi.BSDFContext(), si, wo_)
                out.append(np.concatenate([to_np(w).ravel(), to_np(bs.wo).ravel(),
                                           to_np(f).ravel(), [float(to_np(p).ravel()[0])]]))
            results[variant] = np.concatenate(out)
        finally:
            mi.set_variant("llvm_ad_spectral")
    assert np.all(np.isfinite(results["scalar_spectral"]))
    assert np.count_nonzero(results["scalar_spectral"]) > 10
    np.testing.assert_allclose(results["scalar_spectral"], results["llvm_ad_spectral"],
                               rtol=1e-4, atol=1e-6)


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------
BAD = [
    ({"distribution": "phong"}, r"distribution.*'phong'"),
    ({"alpha": -0.1}, r"alpha.*-0\.1"),
    ({"alpha": float("nan")}, r"alpha.*nan"),
    ({"alpha": 0.0}, r"alpha.*0\.0"),
    ({"alpha": 0.2, "alpha_u": 0.1, "alpha_v": 0.1}, r"alpha.*alpha_u=0\.1"),
    ({"alpha_u": 0.1}, r"alpha_v.*missing.*0\.1"),
    ({"alpha_u": 0.1, "alpha_v": -2.0}, r"alpha_v.*-2\.0"),
    ({"sample_visible": "yes"}, r"sample_visible.*'yes'"),
    ({"alpah": 0.1}, "alpah"),
    ({"layers": "1.46 -5"}, "thickness"),
]


@pytest.mark.parametrize("plugin", ["thinfilm_roughconductor", "thinfilm_roughdielectric"])
@pytest.mark.parametrize("extra,needle", BAD)
def test_bad_input_names_parameter_and_value(plugin, extra, needle):
    with pytest.raises(Exception, match=needle):
        mi.load_dict({"type": plugin, **extra})


# ---------------------------------------------------------------------------
# the example scene
# ---------------------------------------------------------------------------
def test_rough_films_scene_renders():
    scene = mi.load_file(str(ROOT / "scenes" / "rough_films.xml"), resx=24, resy=16, spp=2)
    kinds = {type(s.bsdf()).__name__ for s in scene.shapes()}
    assert {"ThinFilmRoughConductor", "ThinFilmRoughDielectric", "ThinFilmDielectric"} <= kinds
    img = to_np(mi.render(scene, seed=0))
    assert np.all(np.isfinite(img)) and img.mean() > 0.01
