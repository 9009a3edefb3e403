"""thinfilm_mi.render.layered.series: ``thinfilm_diffuse``'s estimator over a diffuse bottom,
the exact model (``model="exact"``), the ``thickness`` texture, a rough bottom.

References: tmm's coherent stack (``tmm.coh_tmm``) integrated here with its own
Gauss-Legendre rule, and a path-traced ``thinfilm_dielectric`` interface over a
``diffuse`` plane. Monte Carlo estimates use fixed seeds; tolerances are a number of
standard errors computed from the samples, plus stated float32 allowances.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tmm

mi.set_variant("llvm_ad_spectral")

import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from tests.support.bsdf import WAVELENGTHS as WL
from tests.support.bsdf import direction, make_si, mc_albedo
from thinfilm_mi.errors import ThinFilmError  # noqa: E402
from thinfilm_mi.render.media import SpectralIndex  # noqa: E402

DIFFUSE_ONLY = mi.BSDFContext()
DIFFUSE_ONLY.component = 1


def _tmm_rt(n_list, d_list, cos_in, wl):
    th = np.arccos(np.clip(cos_in, 0.0, 1.0)) + 0j
    R = T = 0.0
    for pol in "sp":
        o = tmm.coh_tmm(pol, n_list, d_list, th, wl)
        R, T = R + 0.5 * o["R"], T + 0.5 * o["T"]
    return float(np.real(R)), float(np.real(T))


def tmm_albedo(layers, n0, nb, rho, theta, wl, nodes=48):
    """``R + T ρ T_hemi / (1 - ρ R_dh)`` from tmm: ``T_hemi`` = (n0/nb)² 2∫T μ0 dμ0 over
    the ambient, ``R_dh`` = 2∫R_up μ dμ over the base (split at the critical angle)."""
    n = [n0] + [SpectralIndex.from_material(m, "x").spectral_values(np.array([wl]))[0]
                for m, _ in layers] + [nb]
    d = [np.inf] + [t for _, t in layers] + [np.inf]
    x, w = np.polynomial.legendre.leggauss(nodes)
    u, w = 0.5 * (x + 1.0), 0.5 * w
    R, T = _tmm_rt(n, d, math.cos(math.radians(theta)), wl)
    t_hemi = (n0 / nb) ** 2 * sum(2 * c * m * _tmm_rt(n, d, m, wl)[1] for m, c in zip(u, w))
    mu_c = math.sqrt(max(0.0, 1.0 - (n0 / nb) ** 2))
    parts = [(mu_c * u, mu_c * w), (mu_c + (1 - mu_c) * u, (1 - mu_c) * w)]
    r_dh = sum(2 * c * m * _tmm_rt(n[::-1], d[::-1], m, wl)[0]
               for mus, ws in parts for m, c in zip(mus, ws))
    return R + T * rho * t_hemi / (1.0 - rho * r_dh)


@pytest.mark.parametrize("theta", [0.0, 30.0, 60.0])
def test_exact_albedo_equals_tmm(theta):
    """The issue's case: SiO2 300; Au 4 in air over reflectance 0.6."""
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                      "ext_ior": 1.0, "reflectance": 0.6, "tabulate": False})
    mean, err = mc_albedo(b, theta, seed=3)
    ref = np.array([tmm_albedo([("SiO2", 300), ("Au", 4)], 1.0, 1.0, 0.6, theta, wl)
                    for wl in WL])
    # 5 standard errors (measured 1.0-1.8e-4 at 2^18 samples) plus 2e-5 for the float32
    # stack in the kernel; the 48-node reference rule is within 1e-7 of 256 nodes.
    assert np.all(np.abs(mean - ref) <= 5 * err + 2e-5), (mean, ref, err)
    # ... and far from the paper's model, which treats the 4 nm of gold as bulk: its
    # diffuse lobe is darker, by more than 20x in the red (measured 0.17 against 0.28
    # at 450 nm, 0.0008 against 0.47 at 680 nm at normal incidence)
    paper = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4",
                          "model": "multiple", "ext_ior": 1.0, "reflectance": 0.6})
    diffuse = mc_albedo(b, theta, ctx=DIFFUSE_ONLY, seed=3)[0]
    paper_diffuse = mc_albedo(paper, theta, ctx=DIFFUSE_ONLY, seed=3)[0]
    assert np.all(paper_diffuse < diffuse) and np.all(paper_diffuse[2:] < 0.05 * diffuse[2:])


@pytest.mark.parametrize("base", [1.5, 0.8])
def test_exact_albedo_with_a_base_medium(base):
    """A base medium that differs from the ambient: the radiance factor (n0/nb)² and the
    base's total internal reflection (frustrated by the gold)."""
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                      "ext_ior": 1.0, "base_ior": base, "reflectance": 0.6, "tabulate": False})
    mean, err = mc_albedo(b, 30.0, seed=3)
    ref = np.array([tmm_albedo([("SiO2", 300), ("Au", 4)], 1.0, base, 0.6, 30.0, wl)
                    for wl in WL])
    # as above; the split reference rule is within 2e-6 of a 4001-point one at nb = 1.5
    assert np.all(np.abs(mean - ref) <= 5 * err + 2e-5), (mean, ref, err)


def test_exact_matches_path_traced_two_surfaces():
    """An independent reference without any series: a thinfilm_dielectric interface
    (the same films, int_ior = ext_ior) 1e-3 above a diffuse plane, path traced under
    a constant environment of radiance 1: the radiance seen from θ is the albedo."""
    rho, layers, theta = 0.6, "SiO2 300; Au 4", 30.0
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 200, "rr_depth": 200},
        "env": {"type": "constant", "radiance": {"type": "uniform", "value": 1.0}},
        "film": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, 1e-3])
                 @ mi.ScalarTransform4f().scale(1e4),
                 "bsdf": {"type": "thinfilm_dielectric", "layers": layers, "int_ior": 1.0,
                          "ext_ior": 1.0, "tabulate": False}},
        "base": {"type": "rectangle", "to_world": mi.ScalarTransform4f().scale(1e4),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": rho}}},
    })
    n = 1 << 17
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(5, n)
    d = -direction(theta)
    ray = mi.Ray3f(mi.Point3f(0.0, 0.0, 1.0), d)
    ray.wavelengths = mi.Spectrum(*WL)
    integrator = scene.integrator()
    spec, _, _ = integrator.sample(scene, sampler, mi.RayDifferential3f(ray), None, True)
    L = np.array(spec, np.float64)
    mean, err = L.mean(axis=1), L.std(axis=1) / math.sqrt(n)
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": layers, "model": "exact",
                      "ext_ior": 1.0, "reflectance": rho, "tabulate": False})
    ours, err_o = mc_albedo(b, theta, n=1 << 18, seed=3)
    # two independent estimates: 5 combined standard errors (measured 3e-4 and 1.5e-4)
    # plus 1e-4 for the light that escapes between the 2e4-wide planes
    assert np.all(np.abs(mean - ours) <= 5 * np.hypot(err, err_o) + 1e-4), (mean, ours)


@pytest.mark.parametrize("layers, base", [("SiO2 500; Au 2", None), ("Si 50; SiO2 100; Cu 5", 1.5),
                                          ("Au 20", 2.0), ("1.46 500; 2.35 80", 1.33)])
def test_exact_energy_and_reciprocity(layers, base):
    extra = {} if base is None else {"base_ior": base}
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": layers, "model": "exact",
                      "reflectance": 1.0, "tabulate": False, **extra})
    for theta in (0.0, 50.0, 85.0):
        mean, err = mc_albedo(b, theta, n=1 << 16, seed=3)
        # 5 standard errors plus 1e-5 (float32)
        assert np.all(mean <= 1.0 + 5 * err + 1e-5), (layers, theta, mean)
    n = 2048
    rng = mi.PCG32(size=n, initstate=11)
    wi = mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    wo = mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    f = np.array(b.eval(mi.BSDFContext(), make_si(n, wi), wo))
    f_rev = np.array(b.eval(mi.BSDFContext(), make_si(n, wo), wi))
    cos_i, cos_o = np.array(wi)[2], np.array(wo)[2]
    ok = (cos_i > 1e-3) & (cos_o > 1e-3)
    # the same float32 factors in the other order: a few ulps
    np.testing.assert_allclose((f / cos_o)[:, ok], (f_rev / cos_i)[:, ok], rtol=1e-5)


def test_lossless_white_exact_is_one_with_base():
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "1.46 500; 2.35 80", "model": "exact",
                      "base_ior": 1.5, "reflectance": 1.0, "tabulate": False})
    mean, err = mc_albedo(b, 40.0, n=1 << 18, seed=7)
    # R + T T_hemi/(1 - R_dh) with T_hemi + R_dh = 1 (same nodes): 1 up to float32 and
    # 5 standard errors
    assert np.all(np.abs(mean - 1.0) <= 5 * err + 2e-5), (mean, err)


# ---------------------------------------------------------------------------
# the thickness texture
# ---------------------------------------------------------------------------
def _scene(bsdf, variant_spp=1):
    return mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 24, "height": 24,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": variant_spp}},
        "env": {"type": "constant"},
        "sphere": {"type": "sphere", "bsdf": bsdf},
    })


@pytest.mark.parametrize("variant", ["llvm_ad_spectral", "llvm_ad_rgb"])
@pytest.mark.parametrize("model", ["exact", "multiple"])
def test_constant_scale_equals_scaled_thicknesses(variant, model):
    mi.set_variant(variant)
    try:
        base = {"type": "thinfilm_diffuse", "model": model, "reflectance": 0.7}
        a = mi.render(_scene({**base, "layers": "SiO2 300; Au 4", "thickness": 1.3}), spp=16, seed=2)
        b = mi.render(_scene({**base, "layers": "SiO2 390; Au 5.2"}), spp=16, seed=2)
        a, b = np.array(a), np.array(b)
        # same seed, same paths: differences come from float32 rounding of d*s against
        # d' (measured mean rel diff ~1e-6) and, in spectral variants, the scale
        # table's interpolation at its last node (float32 coordinate): <= 2e-3 (issue)
        rel = np.mean(np.abs(a - b)) / np.mean(np.abs(b))
        assert rel <= 2e-3, rel
        assert np.all(np.isfinite(a)) and np.mean(b) > 0
    finally:
        mi.set_variant("llvm_ad_spectral")


@pytest.mark.parametrize("variant", ["llvm_ad_spectral", "llvm_ad_spectral_polarized"])
@pytest.mark.parametrize("model", ["exact", "single"])
def test_bitmap_scale_renders_finite(variant, model):
    mi.set_variant(variant)
    try:
        img = mi.render(_scene({"type": "thinfilm_diffuse", "model": model,
                                "layers": "SiO2 300; Au 4",
                                "thickness": {"type": "bitmap", "raw": True,
                                              "filename": "scenes/textures/soap_film.exr"}}),
                        spp=4, seed=1)
        img = np.array(img)
        assert np.all(np.isfinite(img)) and img.mean() > 0
    finally:
        mi.set_variant("llvm_ad_spectral")


# ---------------------------------------------------------------------------
# gradients
# ---------------------------------------------------------------------------
def _eval_sum(b, n=256):
    rng = mi.PCG32(size=n, initstate=21)
    wi = mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    wo = mi.warp.square_to_cosine_hemisphere(mi.Point2f(rng.next_float32(), rng.next_float32()))
    return dr.sum(b.eval(mi.BSDFContext(), make_si(n, wi), wo), axis=None)


def _gradient_and_difference(b, key, value, step):
    """``∂/∂x`` of :func:`_eval_sum` at the parameter ``key`` = ``value`` by AD, and the
    central difference over ``value ± step``."""
    params = mi.traverse(b)
    assert key in params
    x = mi.Float(value)
    dr.enable_grad(x)
    params[key] = x
    params.update()
    dr.backward(_eval_sum(b))
    grad = float(dr.grad(x)[0])

    def at(v):
        params[key] = mi.Float(v)
        params.update()
        return float(_eval_sum(b)[0])
    return grad, (at(value + step) - at(value - step)) / (2 * step)


@pytest.mark.parametrize("key, value, step", [("layers.0.thickness", 300.0, 0.5),
                                              ("layers.1.thickness", 4.0, 0.05)])
def test_exact_gradient_wrt_layer_thickness(key, value, step):
    # tabulate false: the finite differences must see the exact stack, not a 1e-3 table
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                      "reflectance": 0.8, "tabulate": False})
    grad, fd = _gradient_and_difference(b, key, value, step)
    # central difference in float32 (sum of 1024 values ~1e2, rounding ~1e-5 / step)
    # against an exact derivative: 2 % (measured < 0.5 %)
    assert grad == pytest.approx(fd, rel=2e-2), (grad, fd)


def test_gradient_wrt_thickness_texture():
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                      "reflectance": 0.8,
                      "thickness": {"type": "checkerboard", "color0": 0.5, "color1": 1.5}})
    grad, fd = _gradient_and_difference(b, "thickness.color0.value", 0.9, 0.01)
    # the kernel's T(θ) is differentiated exactly, R_dh through the table's ∂R_dh/∂s
    # (second-order differences of nodes ~0.003 apart): 3 % (measured < 1 %)
    assert grad == pytest.approx(fd, rel=3e-2), (grad, fd)


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("extra, pattern", [
    ({"model": "exakt"}, r"model.*'exakt'"),
    ({"model": "multiple", "base_ior": 1.5}, r"base_ior.*'multiple'"),
    ({"model": "exact", "base_ior": -1.0}, r"base_ior"),
    ({"model": "exact", "base_ior": float("nan")}, r"base_ior"),
    ({"model": "exact", "base_ior": "Au"}, r"base_ior"),
    ({"model": "exact", "thickness": -0.5}, r"thickness.*-0\.5"),
    ({"model": "exact", "thickness": {"type": "uniform", "value": float("inf")}}, r"thickness"),
])
def test_bad_input(extra, pattern):
    with pytest.raises(Exception, match=pattern):
        mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", **extra})


def test_bad_texture_edit_through_the_scene():
    scene = _scene({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                    "thickness": {"type": "checkerboard", "color0": 0.5, "color1": 1.5}})
    params = mi.traverse(scene)
    key = [k for k in params.keys() if k.endswith("thickness.color0.value")][0]
    params[key] = -2.0
    with pytest.raises(ThinFilmError, match="thickness"):
        params.update()
    # the last valid value is back and the BSDF renders
    assert float(params[key][0]) == 0.5
    assert np.all(np.isfinite(np.array(mi.render(scene, spp=1))))


@pytest.mark.parametrize("roughness_model", ["qualitative", "eon"])
def test_exact_with_a_rough_base_and_a_texture(roughness_model):
    """The rough base (render/orennayar.py) under the exact model and a thickness
    texture: the albedo stays at most 1, and σ = 0 is the Lambertian exact model."""
    tex = {"type": "checkerboard", "color0": 0.6, "color1": 1.2}
    rough = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                          "reflectance": 1.0, "roughness": 0.8, "roughness_model": roughness_model,
                          "thickness": tex})
    for theta in (0.0, 60.0):
        mean, err = mc_albedo(rough, theta, n=1 << 16, seed=3)
        # 5 standard errors plus 1e-5 (float32)
        assert np.all(mean <= 1.0 + 5 * err + 1e-5) and np.all(mean > 0.2), (theta, mean)
    smooth = [mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                            "reflectance": 0.7, "thickness": tex, **extra})
              for extra in ({}, {"roughness": 0.0, "roughness_model": roughness_model})]
    si = make_si(64, direction(35.0))
    wo = mi.warp.square_to_cosine_hemisphere(mi.Point2f(np.linspace(0.01, 0.99, 64),
                                                        np.linspace(0.99, 0.01, 64)))
    a, b = (np.array(s.eval(mi.BSDFContext(), si, wo)) for s in smooth)
    assert np.array_equal(a, b)


def quadrature_albedo(b, theta, nodes=64):
    """The albedo for light from ``theta`` without noise: the delta part from a sample
    with component 0 alone (weight ``R``), the diffuse part ``2π ∫ eval dμ_o`` (the lobe
    of a Lambertian base does not depend on φ) by a ``nodes``-point Gauss-Legendre rule."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    mu, w = 0.5 * (x + 1.0), 0.5 * w
    wo = mi.Vector3f(np.sqrt(1.0 - mu ** 2), np.zeros(nodes), mu)
    diffuse = 2.0 * math.pi * np.array(b.eval(mi.BSDFContext(), make_si(nodes, direction(theta)), wo)) @ w
    ctx = mi.BSDFContext()
    ctx.component = 0
    _, spec = b.sample(ctx, make_si(1, direction(theta)), mi.Float(0.5), mi.Point2f(0.5, 0.5))
    return np.array(spec, np.float64).ravel() + diffuse


@pytest.mark.parametrize("tabulate", [False, True])
@pytest.mark.parametrize("theta", [0.0, 45.0, 75.0])
def test_no_films_over_a_base_medium_is_an_interface(theta, tabulate):
    """Issue 42, check 3: no films over a base medium unlike the ambient is still the
    interface between them (it was Mitsuba's diffuse, albedo 0.5): continuous in the
    film thickness, and Mitsuba's own plastic (nonlinear=true, same int_ior)."""
    def load(layers):
        return mi.load_dict({"type": "thinfilm_diffuse", "layers": layers, "base_ior": 1.5,
                             "ext_ior": 1.0, "reflectance": 0.5, "tabulate": tabulate})
    bare, film = load(""), load("SiO2 1e-4")
    plastic = mi.load_dict({"type": "plastic", "int_ior": 1.5, "ext_ior": 1.0, "nonlinear": True,
                            "diffuse_reflectance": {"type": "uniform", "value": 0.5}})
    a, b, p = (quadrature_albedo(x, theta) for x in (bare, film, plastic))
    # the film-free diffuse (0.5 at every angle, the defect) is far outside the tolerances
    assert np.all(np.abs(p - 0.5) > 0.03), p
    # 1e-4 nm of SiO2 shifts the phase by 2π n d/λ ~ 2e-6 rad, R by less than 1e-7; the
    # rest is float32 rounding of the kernel, of R_dh, T_hemi and of the film's table
    # (measured 5e-9 to 7.6e-7)
    assert np.all(np.abs(a - b) <= 2e-6), (a, b)
    # plastic's internal diffuse reflectance is a fit (F_dr,int +4.65e-4 at eta 1.5,
    # tests/cross/test_coating_geometry.py), ours the quadrature of the exact Fresnel
    # term: that shifts the albedo by kd² t_i T ΔF/(1 - kd F)² (measured 7.1e-5 to 9.2e-5
    # here); the albedo is flat over the wavelengths, as plastic's (a non-dispersive
    # base_ior)
    assert np.all(np.abs(a - p) <= 1.5e-4), (a, p)
    assert np.ptp(a) <= 1e-6
