"""RGB and mono variants: colour tables of the spectral quantities (issue 19).

* a stack's ``R``/``T`` colour in ``llvm_ad_rgb`` against the spectral integral
  computed here with colour-science's CIE 1931 2° observer, D65 and sRGB matrix
  on a 0.01 nm grid of the float64 ``Stack`` (ΔE2000 <= 0.1), both sides, at
  angles up to grazing and across a critical angle;
* mono against the luminance of the same integral;
* ``eta``/``k`` as ``rgb`` with no films: Mitsuba's own ``conductor``, value for value
  and pixel for pixel;
* ``thinfilm_diffuse``: the product ``t(θ_i) t(θ_o) k_d S`` integrated as a product;
* gradients of thickness and index in ``llvm_ad_rgb`` (forward and reverse)
  against central differences of the reference integral;
* ``scalar_rgb`` agrees with ``llvm_ad_rgb``; refused inputs name the parameter.

The module fixture restores the suite's default variant (``llvm_ad_spectral``).
"""
from __future__ import annotations

import colour
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf

DEFAULT = "llvm_ad_spectral"
RGB = "llvm_ad_rgb"
MONO = "llvm_ad_mono"

# The reference integral: colour-science's tables (not the project's CSV), linearly
# interpolated to 0.01 nm, trapezoid rule; 0.01 nm resolves the ~0.1 nm resonances
# of a 30-film metal cavity (halving it changes Y by < 1e-6 here).
LAM = np.arange(360.0, 830.0 + 1e-9, 0.01)
_CMF = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
_D65 = colour.SDS_ILLUMINANTS["D65"]
XYZ_BAR = np.stack([np.interp(LAM, _CMF.wavelengths, _CMF.values[:, i]) for i in range(3)])
D65 = np.interp(LAM, _D65.wavelengths, _D65.values)
XYZ_TO_SRGB = colour.models.RGB_COLOURSPACE_sRGB.matrix_XYZ_to_RGB
W_RGB = (XYZ_TO_SRGB @ XYZ_BAR) * D65
W_RGB /= W_RGB.sum(axis=1, keepdims=True)       # a perfect reflector gives (1, 1, 1)
W_Y = (XYZ_BAR[1] * D65)[None, :]
W_Y /= W_Y.sum()

THIRTY = "; ".join(["2.3 60; 1.46 90"] * 15)
# (name, layers, conductor substrate): 1, 2, 3 and 30 films, and a 2 µm film whose
# fringes alias at three "RGB wavelengths"
CONDUCTOR_STACKS = [
    ("sio2_500_au", "SiO2 500", "Au"),
    ("two_films_al", "1.46 300; 2.3 80", "Al"),
    ("sio2_au_al_on_si", "SiO2 500; Au 20; Al 10", "Si"),
    ("thirty_al", THIRTY, "Al"),
    ("thick_2um_au", "1.46 2000", "Au"),
]
ANGLES = [0.0, 30.0, 60.0, 75.0, 85.0, 89.0]
# The issue's bound for a plugin's direct reflection colour.
DE_MAX = 0.1


@pytest.fixture(scope="module", autouse=True)
def rgb_variant():
    mi.set_variant(RGB)
    yield
    mi.set_variant(DEFAULT)


def lab(rgb):
    """CIELAB of linear sRGB colours relative to the perfect reflector (1, 1, 1)."""
    rgb = np.atleast_2d(rgb)
    white = colour.models.RGB_COLOURSPACE_sRGB.matrix_RGB_to_XYZ @ np.ones(3)
    xyz = rgb @ colour.models.RGB_COLOURSPACE_sRGB.matrix_RGB_to_XYZ.T
    return colour.XYZ_to_Lab(xyz / white[1], colour.XYZ_to_xy(white))


def delta_e(a, b) -> np.ndarray:
    return colour.delta_E(lab(a), lab(b), method="CIE 2000")


def reference(stack: tf.Stack, theta_deg: float, weights=W_RGB, what="R") -> np.ndarray:
    res = stack.rt(wavelength=LAM, theta=np.radians(theta_deg))
    return weights @ getattr(res, what).ravel()


def interaction(theta_deg: float, n: int = 1, rng=None):
    th = np.radians(theta_deg)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    if rng is not None:
        si.p = mi.Point3f(*[mi.Float(rng.random(n).astype(np.float32)) for _ in range(3)])
    si.wi = mi.Vector3f(float(np.sin(th)), 0.0, float(np.cos(th)))
    return si


def colour_of(stack_like, theta_deg: float, *, inside=False, transmission=False):
    """``KernelStack.colour`` at one angle, as numpy (``(R, T)`` with ``transmission``)."""
    si = interaction(theta_deg)
    cos = mi.Float(float(np.cos(np.radians(theta_deg))))
    out = stack_like.colour(si, cos, inside=inside, transmission=transmission)
    if transmission:
        return tuple(np.array(x, np.float64).ravel() for x in out)
    return np.array(out, np.float64).ravel()


# ---------------------------------------------------------------------------
# Colours of stacks against the spectral integral
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name,layers,substrate", CONDUCTOR_STACKS, ids=[c[0] for c in CONDUCTOR_STACKS])
def test_conductor_colour_matches_spectral_integral(name, layers, substrate):
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": substrate,
                         "ext_ior": 1.0})
    stack = tf.Stack(layers=layers, substrate=substrate, ambient=1.0)
    for theta in ANGLES:
        si = interaction(theta)
        _, weight = bsdf.sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.5, 0.5))
        got = np.array(weight, np.float64).ravel()
        ref = reference(stack, theta)
        de = float(delta_e(got, ref)[0])
        assert de <= DE_MAX, (name, theta, got, ref, de)


def test_three_rgb_wavelengths_would_alias():
    """The control: the 2 µm film at three 'RGB wavelengths' is a different colour,
    so the check above can tell an integral from a point sample."""
    stack = tf.Stack(layers="1.46 2000", substrate="Au", ambient=1.0)
    point = stack.rt(wavelength=np.array([610.0, 550.0, 465.0]), theta=0.0).R.ravel()
    assert float(delta_e(point, reference(stack, 0.0))[0]) > 5.0


DIELECTRIC_STACKS = [("sio2_500", "SiO2 500"), ("sio2_au_al", "SiO2 500; Au 20; Al 10"),
                     ("thirty", THIRTY)]


@pytest.mark.parametrize("name,layers", DIELECTRIC_STACKS, ids=[c[0] for c in DIELECTRIC_STACKS])
def test_dielectric_colours_both_sides(name, layers):
    """R and T from outside and from inside the glass, through a critical angle
    (41.8° inside glass of 1.5 for transparent stacks)."""
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers, "int_ior": 1.5,
                         "ext_ior": 1.0})
    outside = tf.Stack(layers=layers, substrate=1.5, ambient=1.0)
    inside = outside.reversed()
    for stack, flag, angles in ((outside, False, ANGLES),
                                (inside, True, [0.0, 30.0, 40.0, 41.5, 42.0, 45.0, 70.0, 89.0])):
        for theta in angles:
            R, T = colour_of(bsdf.stack, theta, inside=flag, transmission=True)
            for got, what in ((R, "R"), (T, "T")):
                ref = reference(stack, theta, what=what)
                de = float(delta_e(got, ref)[0])
                assert de <= DE_MAX, (name, flag, theta, what, got, ref, de)


def test_mono_is_the_luminance():
    """llvm_ad_mono returns Y of the same integral (V(λ) = ȳ under D65)."""
    mi.set_variant(MONO)
    try:
        for name, layers, substrate in CONDUCTOR_STACKS:
            bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers,
                                 "material": substrate, "ext_ior": 1.0})
            stack = tf.Stack(layers=layers, substrate=substrate, ambient=1.0)
            for theta in (0.0, 60.0, 85.0):
                _, w = bsdf.sample(mi.BSDFContext(), interaction(theta), 0.5,
                                   mi.Point2f(0.5, 0.5))
                ref = float(reference(stack, theta, W_Y)[0])
                # the issue allows 2 % for renders; the table itself is ~1e-4
                assert abs(float(np.ravel(w)[0]) - ref) <= 1e-3 * max(ref, 0.1), (name, theta)
    finally:
        mi.set_variant(RGB)


# ---------------------------------------------------------------------------
# Colours given per channel: Mitsuba's own conductor
# ---------------------------------------------------------------------------
RGB_ETA = {"type": "rgb", "value": [0.2, 0.9, 1.1]}
RGB_K = {"type": "rgb", "value": [3.9, 2.4, 1.9]}


def test_rgb_eta_k_without_films_is_mitsubas_conductor():
    ours = mi.load_dict({"type": "thinfilm_conductor", "eta": RGB_ETA, "k": RGB_K})
    theirs = mi.load_dict({"type": "conductor", "eta": RGB_ETA, "k": RGB_K})
    rng = np.random.default_rng(3)
    n = 256
    th, ph = rng.uniform(0, np.pi / 2, n), rng.uniform(0, 2 * np.pi, n)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(mi.Float(np.sin(th) * np.cos(ph)), mi.Float(np.sin(th) * np.sin(ph)),
                        mi.Float(np.cos(th)))
    a = ours.sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.5, 0.5))
    b = theirs.sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.5, 0.5))
    # the same Fresnel equation per channel in two float32 forms (our amplitude
    # recursion, Mitsuba's fresnel_conductor): measured max difference 7e-5 at
    # k ~ 4; tests/plugins/test_thinfilm_conductor.py holds the spectral pair to 1e-4 likewise
    np.testing.assert_allclose(np.array(a[1]), np.array(b[1]), atol=1e-4)
    np.testing.assert_allclose(np.array(a[0].wo), np.array(b[0].wo), atol=1e-6)


def _sphere_scene(bsdf: dict) -> dict:
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
            "sensor": {"type": "perspective", "fov": 30,
                       "to_world": mi.ScalarTransform4f().look_at([0, 0, 4], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 24, "height": 24,
                                "pixel_format": "rgb"},
                       "sampler": {"type": "independent", "sample_count": 4}},
            "emitter": {"type": "constant", "radiance": {"type": "rgb", "value": [0.8, 0.9, 1.0]}},
            "light": {"type": "point", "position": [2, 3, 4],
                      "intensity": {"type": "rgb", "value": [20, 18, 15]}},
            "sphere": {"type": "sphere", "bsdf": bsdf}}


def test_rgb_eta_k_image_equals_conductor():
    ours = mi.render(mi.load_dict(_sphere_scene(
        {"type": "thinfilm_conductor", "eta": RGB_ETA, "k": RGB_K})), seed=7)
    theirs = mi.render(mi.load_dict(_sphere_scene(
        {"type": "conductor", "eta": RGB_ETA, "k": RGB_K})), seed=7)
    # the same samples and the same per-channel Fresnel up to float32 rounding (see
    # above): the spectral test of the same pair's bound, mean relative 1e-4
    a, b = np.array(ours), np.array(theirs)
    assert np.abs(a - b).mean() / np.abs(b).mean() < 1e-4
    assert np.abs(a - b).max() < 1e-3


def test_films_over_rgb_eta_integrate_per_channel():
    """Films over an index given per channel: each channel integrates the stack over
    that channel's constant index (a substrate of index 1.5 + 0j in every channel is
    the dielectric substrate of the reference)."""
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 400",
                         "eta": {"type": "rgb", "value": [1.5, 1.5, 1.5]},
                         "k": {"type": "rgb", "value": [0.0, 0.0, 0.0]}, "ext_ior": 1.0})
    stack = tf.Stack(layers="1.46 400", substrate=1.5, ambient=1.0)
    for theta in (0.0, 50.0):
        got = colour_of(bsdf.stack, theta)
        assert float(delta_e(got, reference(stack, theta))[0]) <= DE_MAX


# ---------------------------------------------------------------------------
# thinfilm_diffuse: the product integrated as a product
# ---------------------------------------------------------------------------
def test_diffuse_term_integrates_the_product():
    """π f_c(θ_i, θ_o) = ∫ ŵ_c t(θ_i) t(θ_o) k_d dλ ("single"), t the float64 T of the
    films over the base, integrated here on a 0.01 nm grid; and it differs from the
    product of integrated factors, which is what a per-factor table would give."""
    layers, kd = "1.46 1500", np.array([0.8, 0.5, 0.3])
    bsdf = mi.load_dict({"type": "thinfilm_diffuse", "layers": layers, "model": "single",
                         "reflectance": {"type": "rgb", "value": kd.tolist()}})
    base = bsdf.coating.substrate.mean_real()
    stack = tf.Stack(layers=layers, substrate=base, ambient=bsdf.coating.ambient.mean_real())
    for ti, to in ((0.0, 0.0), (30.0, 60.0), (70.0, 20.0)):
        t_i = stack.rt(wavelength=LAM, theta=np.radians(ti)).T.ravel()
        t_o = stack.rt(wavelength=LAM, theta=np.radians(to)).T.ravel()
        ref = kd * (W_RGB @ (t_i * t_o))
        separate = kd * (W_RGB @ t_i) * (W_RGB @ t_o)
        got = np.array(bsdf.colour.value(mi.Float(float(np.cos(np.radians(ti)))),
                                         mi.Float(float(np.cos(np.radians(to)))),
                                         mi.Color3f(*map(float, kd))), np.float64).ravel()
        assert float(delta_e(got, ref)[0]) <= DE_MAX, (ti, to, got, ref)
        assert float(np.max(np.abs(got - ref))) <= 1e-3
        if ti != to:
            assert float(np.max(np.abs(separate - ref))) > 20 * float(np.max(np.abs(got - ref)))


def test_diffuse_albedo_texture_uses_the_series_expansion():
    """A reflectance texture (k_d per hit): the Chebyshev expansion of the series
    in R_dh agrees with the table integrated for the constant k_d."""
    layers = "SiO2 500; Au 5"
    kd = [0.9, 0.6, 0.2]
    const = mi.load_dict({"type": "thinfilm_diffuse", "layers": layers,
                          "reflectance": {"type": "rgb", "value": kd}})
    tex = mi.load_dict({"type": "thinfilm_diffuse", "layers": layers,
                        "reflectance": {"type": "checkerboard",
                                        "color0": {"type": "rgb", "value": kd},
                                        "color1": {"type": "rgb", "value": kd}}})
    assert const.colour.fixed and not tex.colour.fixed
    for ti, to in ((10.0, 20.0), (60.0, 45.0)):
        args = (mi.Float(float(np.cos(np.radians(ti)))), mi.Float(float(np.cos(np.radians(to)))),
                mi.Color3f(*kd))
        a = np.array(const.colour.value(*args)).ravel()
        b = np.array(tex.colour.value(*args)).ravel()
        # the expansion's relative error is <= coated_diffuse.SERIES_TOLERANCE plus
        # the two tables' interpolation (1e-4 each)
        np.testing.assert_allclose(a, b, atol=3e-4)


# ---------------------------------------------------------------------------
# Gradients
# ---------------------------------------------------------------------------
GRAD_CASES = [
    ("thinfilm_conductor", "1.46 300", {"material": "Au"}, "layers.0.thickness", "R"),
    ("thinfilm_conductor", "1.46 300; 2.3 80", {"material": "Al"}, "layers.1.thickness", "R"),
    ("thinfilm_conductor", "1.46 300", {"material": "Au"}, "layers.0.eta.value", "R"),
    ("thinfilm_dielectric", "2.3 120", {"int_ior": 1.5}, "layers.0.thickness", "T"),
]


def _fd_reference(plugin, layers, extra, key, what, theta, h):
    substrate = extra.get("material", extra.get("int_ior"))
    parts = [p.split() for p in layers.split(";")]
    j = int(key.split(".")[1])

    def shifted(delta):
        q = [list(p) for p in parts]
        col = 1 if key.endswith("thickness") else 0
        q[j][col] = repr(float(q[j][col]) + delta)
        stack = tf.Stack(layers="; ".join(" ".join(p) for p in q), substrate=substrate,
                         ambient=1.0)
        return reference(stack, theta, what=what)
    return (shifted(h) - shifted(-h)) / (2 * h)


@pytest.mark.parametrize("plugin,layers,extra,key,what", GRAD_CASES,
                         ids=[f"{c[0]}-{c[3]}-{len(c[1].split(';'))}" for c in GRAD_CASES])


def test_gradients_match_finite_differences(plugin, layers, extra, key, what):
    """Forward-mode derivative of the sampled weight, averaged over many hits (the
    estimator is unbiased; its noise is measured), against central differences of
    the reference integral."""
    bsdf = mi.load_dict({"type": plugin, "layers": layers, "ext_ior": 1.0, **extra})
    params = mi.traverse(bsdf)
    theta, n = 40.0, 1 << 17
    si = interaction(theta, n, np.random.default_rng(5))
    x = params[key]
    dr.enable_grad(x)
    dr.set_grad(x, 1.0)
    params.update()
    # R: the specular reflection (sample1 < R); T: transmission (sample1 ~ 1)
    sample1 = 0.0 if what == "R" else 0.999999
    # Importance transport: no 1/eta^2 radiance scale on the transmitted weight
    ctx = mi.BSDFContext(mi.TransportMode.Importance)
    bs, w = bsdf.sample(ctx, si, sample1, mi.Point2f(0.5, 0.5))
    value = w * bs.pdf if what == "T" else w    # the weight is T / P(T): undo the pdf
    dr.forward_to(value)
    g = np.array(dr.grad(value), np.float64).reshape(3, -1)
    mean, se = g.mean(axis=1), g.std(axis=1) / np.sqrt(n)
    h = 0.05 if key.endswith("thickness") else 1e-3
    fd = _fd_reference(plugin, layers, extra, key, what, theta, h)
    # 6 standard errors of the Monte Carlo mean, plus 3 % for float32 evaluation
    # and the 1 nm weight texture (measured: <= 1.7 % on these cases)
    assert np.all(np.abs(mean - fd) <= 6 * se + 0.03 * np.abs(fd) + 1e-6), (mean, se, fd)
    # the value is the table's: no noise in the primal
    v = np.array(value, np.float64).reshape(3, -1)
    assert np.ptp(v, axis=1).max() <= 1e-6


def test_reverse_mode_gradient():
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 300", "material": "Au",
                         "ext_ior": 1.0})
    params = mi.traverse(bsdf)
    key = "layers.0.thickness"
    dr.enable_grad(params[key])
    params.update()
    n = 1 << 17
    _, w = bsdf.sample(mi.BSDFContext(), interaction(40.0, n, np.random.default_rng(9)), 0.0,
                       mi.Point2f(0.5, 0.5))
    loss = dr.sum(w[1]) / n                  # the green channel's mean
    dr.backward(loss)
    g = float(np.ravel(dr.grad(params[key]))[0])
    fd = _fd_reference("thinfilm_conductor", "1.46 300", {"material": "Au"}, key, "R", 40.0,
                       0.05)[1]
    assert abs(g - fd) <= 0.03 * abs(fd) + 2e-5, (g, fd)


def test_no_gradient_work_without_gradients():
    """Without gradients the value is the table's (no estimator is traced: the
    weights of many hits are identical)."""
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 300"})
    assert not bsdf.stack.colour_gradients(interaction(10.0))


# ---------------------------------------------------------------------------
# scalar_rgb; bad input
# ---------------------------------------------------------------------------
def test_scalar_rgb_agrees_with_llvm_rgb():
    cases = [({"type": "thinfilm_conductor", "layers": "SiO2 500"}, 0.5),
             ({"type": "thinfilm_dielectric", "layers": "SiO2 300"}, 0.99),
             ({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"}, 0.9),
             ({"type": "thinfilm_roughconductor", "layers": "SiO2 500", "alpha": 0.2}, 0.5)]
    vec = {}
    for variant in (RGB, "scalar_rgb"):
        mi.set_variant(variant)
        try:
            out = []
            for desc, s1 in cases:
                bsdf = mi.load_dict(desc)
                si = dr.zeros(mi.SurfaceInteraction3f)
                si.wi = mi.Vector3f(0.6, 0.0, 0.8)
                _, w = bsdf.sample(mi.BSDFContext(), si, s1, mi.Point2f(0.3, 0.6))
                out.append(np.array(w, np.float64).ravel())
            vec[variant] = out
        finally:
            mi.set_variant(RGB)
    for a, b in zip(vec[RGB], vec["scalar_rgb"]):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)


def test_varying_rgb_index_under_films_is_refused():
    """An RGB texture (a bitmap) where the films need a spectrum: the error names
    the parameter."""
    tex = {"type": "checkerboard", "color0": {"type": "rgb", "value": [0.2, 0.9, 0.9]},
           "color1": {"type": "rgb", "value": [0.3, 0.8, 0.95]}}
    with pytest.raises(Exception) as err:
        mi.load_dict({"type": "thinfilm_conductor", "layers": "SiO2 100", "eta": tex,
                      "k": {"type": "rgb", "value": [3.0, 2.0, 1.0]}})
    text = str(err.value)
    assert "'eta'" in text and "thinfilm_conductor" in text and "spectrum" in text, text
    # without films the per-channel Fresnel takes it, as Mitsuba's conductor does
    mi.load_dict({"type": "thinfilm_conductor", "eta": tex,
                  "k": {"type": "rgb", "value": [3.0, 2.0, 1.0]}})


def test_polarized_rgb_variants_are_refused():
    from thinfilm_mi.render.variant import check_variant
    if "llvm_ad_mono_polarized" not in mi.variants():
        pytest.skip("no llvm_ad_mono_polarized")
    mi.set_variant("llvm_ad_mono_polarized")
    try:
        with pytest.raises(Exception, match="not supported"):
            check_variant("thinfilm_conductor")
    finally:
        mi.set_variant(RGB)


def test_diffuse_gradient_matches_finite_differences():
    """thinfilm_diffuse's diffuse term ("single": no R_dh; "multiple" in
    tests/plugins/test_thinfilm_diffuse.py) in llvm_ad_rgb: the forward derivative averaged
    over hits against central differences of the tabulated value itself."""
    def load(d):
        return mi.load_dict({"type": "thinfilm_diffuse", "layers": f"1.46 {d}; 2.3 60",
                             "model": "single",
                             "reflectance": {"type": "rgb", "value": [0.8, 0.6, 0.4]}})
    d, h, n = 300.0, 2.0, 1 << 17
    ctx = mi.BSDFContext()
    ctx.component = 1                      # the diffuse lobe

    def evaluate(bsdf, si):
        wo = mi.Vector3f(-0.5, 0.3, float(np.sqrt(1 - 0.34)))
        return bsdf.eval(ctx, si, wo)
    fd = (np.array(evaluate(load(d + h), interaction(35.0))).ravel()
          - np.array(evaluate(load(d - h), interaction(35.0))).ravel()) / (2 * h)
    bsdf = load(d)
    params = mi.traverse(bsdf)
    key = "layers.0.thickness"
    dr.enable_grad(params[key])
    dr.set_grad(params[key], 1.0)
    params.update()
    value = evaluate(bsdf, interaction(35.0, n, np.random.default_rng(11)))
    dr.forward_to(value)
    g = np.array(dr.grad(value), np.float64).reshape(3, -1)
    mean, se = g.mean(axis=1), g.std(axis=1) / np.sqrt(n)
    # as test_gradients_match_finite_differences, plus the tables' interpolation
    # in the finite difference (<= 1e-4 of pi f, times cos/pi, over 2h)
    slack = 1e-4 * 0.25 / (2 * h) * 4
    assert np.all(np.abs(mean - fd) <= 6 * se + 0.03 * np.abs(fd) + slack), (mean, se, fd)
    assert np.max(np.abs(fd)) > 10 * slack         # a real derivative, not noise


@pytest.mark.parametrize("plugin", ["thinfilm_conductor", "thinfilm_dielectric", "thinfilm_diffuse"])
def test_edited_thickness_rebuilds_the_colour_table(plugin):
    """``mi.traverse`` edits rebuild the tables: the edited BSDF equals a fresh one,
    and a bad value is refused naming the key (the last valid table stays)."""
    def sample(bsdf):
        _, w = bsdf.sample(mi.BSDFContext(), interaction(30.0), 0.3, mi.Point2f(0.4, 0.6))
        return np.array(w, np.float64).ravel()
    bsdf = mi.load_dict({"type": plugin, "layers": "1.46 300"})
    before = sample(bsdf)
    params = mi.traverse(bsdf)
    params["layers.0.thickness"] = 420.0
    params.update()
    after = sample(bsdf)
    np.testing.assert_allclose(after, sample(mi.load_dict({"type": plugin,
                                                           "layers": "1.46 420"})), atol=1e-6)
    assert np.max(np.abs(after - before)) > 1e-3     # the edit changed the colour
    params["layers.0.thickness"] = float("nan")
    with pytest.raises(Exception, match="thickness"):
        params.update()
    np.testing.assert_allclose(sample(bsdf), after, atol=1e-6)


def test_thickness_texture_table_over_angle_and_scale():
    """A ``thickness`` texture that varies over the surface: the colour table is
    2-D over (angle, thickness scale); its lookups at scales and angles between
    the nodes against the reference integral of the scaled stack, within the
    issue's ΔE2000 0.1 (measured 0.01; the 2-D refinement's node tolerance,
    integrated.TOLERANCE_DE_2D, allows 0.2 where the 4-point rule mispredicts)."""
    tex = {"type": "checkerboard", "color0": {"type": "rgb", "value": [0.1, 0.1, 0.1]},
           "color1": {"type": "rgb", "value": [0.9, 0.9, 0.9]}}
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": "1.33 700", "material": "Au",
                         "ext_ior": 1.0, "thickness": tex})
    table = bsdf.stack.plan[False].colour
    assert table.scale_max == pytest.approx(0.9, rel=1e-6) and table.ns > 1
    rng = np.random.default_rng(2)
    worst = 0.0
    for s, theta in zip(rng.uniform(0.0, 0.9, 12), rng.uniform(0.0, 85.0, 12)):
        R, _ = table.lookup(mi.Float(float(np.cos(np.radians(theta)))), mi.Float(float(s)))
        got = np.array(R, np.float64).ravel()
        ref = reference(tf.Stack(layers=f"1.33 {700 * s!r}", substrate="Au", ambient=1.0), theta)
        worst = max(worst, float(delta_e(got, ref)[0]))
    assert worst <= DE_MAX, worst


def test_render_gradient_in_rgb_matches_finite_difference():
    """Through mi.render in llvm_ad_rgb (path, reverse mode): the mean pixel's
    derivative with respect to a film thickness of a coated conductor sphere under a
    constant sky, against a central difference of renders (tables rebuilt by the
    edits; same seed). The smooth conductor's paths do not depend on the thickness,
    so the difference is exact up to the tables' interpolation; the AD side is the
    unbiased per-hit estimate (measured 2.8e-4 against 2.9e-4, 3 %); 10 % + 1e-5 bound."""
    sc = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 25,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0],
                                                             up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 256}},
        "sphere": {"type": "sphere", "bsdf": {"type": "thinfilm_conductor", "material": "Au",
                                              "layers": "1.46 300; 2.3 60"}},
        "light": {"type": "constant"}})
    key = "sphere.bsdf.layers.0.thickness"
    params = mi.traverse(sc)
    d0 = float(params[key][0])
    dr.enable_grad(params[key])
    params.update()
    img = mi.render(sc, params, seed=3)
    dr.backward(dr.mean(img, axis=None))
    ad = float(dr.grad(params[key])[0])
    dr.disable_grad(params[key])
    h, vals = 2.0, []
    for d in (d0 + h, d0 - h):
        params[key] = d
        params.update()
        vals.append(float(np.mean(np.array(mi.render(sc, seed=3)))))
    fd = (vals[0] - vals[1]) / (2 * h)
    assert abs(fd) > 1e-4, fd
    assert abs(ad - fd) <= 0.1 * abs(fd) + 1e-5, (ad, fd)
