"""``thinfilm_diffuse`` in RGB and mono variants under a ``thickness`` texture that varies
over the surface (``ScaledColourDiffuse`` in ``thinfilm_mi/tabulate/diffuse.py``).

Reference: the same BSDF with a constant thickness scale ``s``, whose diffuse table is
the 2-D one of ``tabulate/diffuse.py`` built at ``s`` (itself checked against the
spectral integral in ``tests/render/test_colour_variants.py``). At a texel of scale ``s`` the table over
the scale must give the same value within its tolerances (see each test). The module
fixture restores the suite's default variant (``llvm_ad_spectral``).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")

import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from thinfilm_mi.errors import ThinFilmError  # noqa: E402
from thinfilm_mi.tabulate import diffuse as diffuse_tables  # noqa: E402
from thinfilm_mi.tabulate.diffuse import (  # noqa: E402
    LEVEL_ABS,
    LINEAR_ABS,
    SCALE_ABS,
    cubic_midpoints,
    cubic_stencil,
)

LAYERS = "SiO2 120; Au 3"


@pytest.fixture(scope="module", autouse=True)
def rgb_variant():
    mi.set_variant("llvm_ad_rgb")
    yield
    mi.set_variant("llvm_ad_spectral")
#: texel values of the thickness bitmap (2 x 2, nearest filtering): scales between the
#: table's nodes as well as at its ends
TEXELS = np.array([[0.6, 0.75], [1.0, 0.87]], np.float32)
#: the texels compared (the ends are table nodes; these lie between nodes)
INTERIOR = (float(TEXELS[0, 1]), float(TEXELS[1, 1]))


def bitmap():
    return {"type": "bitmap", "bitmap": mi.Bitmap(TEXELS[:, :, None]), "raw": True,
            "filter_type": "nearest"}


def directions(n=12, seed=5):
    rng = np.random.default_rng(seed)
    def hemi():
        u = rng.uniform(0.02, 0.98, (2, n))
        return mi.warp.square_to_cosine_hemisphere(mi.Point2f(u[0], u[1]))
    return hemi(), hemi()


def eval_at(bsdf, uv, wi, wo):
    si = dr.zeros(mi.SurfaceInteraction3f, dr.width(wi))
    si.wi = wi
    si.uv = mi.Point2f(uv[0], uv[1])
    ctx = mi.BSDFContext()
    ctx.component = 1      # the diffuse lobe
    return np.array(bsdf.eval(ctx, si, wo)), si


@pytest.mark.parametrize("variant, model, reflectance, extra", [
    ("llvm_ad_rgb", "single", {"type": "checkerboard", "color0": 0.3, "color1": 0.9}, {}),
    ("llvm_ad_rgb", "multiple", 0.7, {}),
    ("llvm_ad_rgb", "exact", 0.8, {"roughness": 0.5}),
    ("llvm_ad_mono", "multiple", 0.7, {}),
])
def test_bitmap_equals_constant_scale(variant, model, reflectance, extra):
    mi.set_variant(variant)
    try:
        base = {"type": "thinfilm_diffuse", "model": model, "layers": LAYERS,
                "reflectance": reflectance, **extra}
        textured = mi.load_dict({**base, "thickness": bitmap()})
        assert textured.colour.scaled
        assert textured.colour.report["angle_error"] <= LINEAR_ABS     # (the tolerance below)
        wi, wo = directions()
        n = dr.width(wi)
        worst = 0.0
        for u in (0.25, 0.75):
            for v in (0.25, 0.75):
                got, si = eval_at(textured, (np.full(n, u), np.full(n, v)), wi, wo)
                s = float(textured.coating.thickness_scale_at(si)[0])
                assert s in TEXELS
                if s not in INTERIOR:
                    continue
                const = mi.load_dict({**base, "thickness": s})
                assert not const.colour.scaled
                want, _ = eval_at(const, (np.full(n, u), np.full(n, v)), wi, wo)
                # π f may differ by the scale axis' interpolation (SCALE_ABS, checked at
                # every midpoint of its nodes) plus each table's own angle and wavelength
                # errors (LINEAR_ABS + LEVEL_ABS each); eval is π f cos θ_o / π (times
                # k_d <= 0.9 and, for the rough base, its albedo terms <= 1).
                cos_o = np.array(mi.Frame3f.cos_theta(wo))
                tol = (SCALE_ABS + 2 * (LINEAR_ABS + LEVEL_ABS)) * cos_o / math.pi
                assert np.all(np.isfinite(got))
                assert np.all(np.abs(got - want) <= tol + 1e-6), (s, np.max(np.abs(got - want) / tol))
                worst = max(worst, float(np.max(np.abs(got - want) / cos_o * math.pi)))
        assert worst > 0.0    # the two tables are distinct builds
    finally:
        mi.set_variant("llvm_ad_rgb")


@pytest.mark.parametrize("variant", ["llvm_ad_rgb", "llvm_ad_mono"])
def test_bitmap_scale_renders_finite(variant):
    mi.set_variant(variant)
    try:
        bsdf = {"type": "thinfilm_diffuse", "model": "multiple", "layers": LAYERS, "reflectance": 0.7,
                "thickness": bitmap()}
        scene = mi.load_dict({
            "type": "scene", "integrator": {"type": "path", "max_depth": 3},
            "sensor": {"type": "perspective", "fov": 40,
                       "to_world": mi.ScalarTransform4f().look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 24, "height": 24}},
            "env": {"type": "constant"}, "sphere": {"type": "sphere", "bsdf": bsdf}})
        img = np.array(mi.render(scene, spp=4, seed=1))
        assert np.all(np.isfinite(img)) and img.mean() > 0.05
    finally:
        mi.set_variant("llvm_ad_rgb")


def test_albedo_table_equals_constant_scale():
    """The lobe-selection albedo over (θ_i, s) against the constant-scale table's."""
    base = {"type": "thinfilm_diffuse", "model": "multiple", "layers": LAYERS, "reflectance": 0.7}
    textured = mi.load_dict({**base, "thickness": bitmap()})
    cos_i = mi.Float(np.linspace(0.05, 1.0, 16))
    kd = mi.Color3f(0.7)
    for s in INTERIOR:
        const = mi.load_dict({**base, "thickness": s})
        got = np.array(textured.colour.albedo(cos_i, kd, True, mi.Float(s)))
        want = np.array(const.colour.albedo(cos_i, kd, True))
        # the albedo table follows the same tolerances as π f (see above)
        assert np.all(np.abs(got - want) <= SCALE_ABS + 2 * (LINEAR_ABS + LEVEL_ABS)), (s, got - want)


def test_cubic_stencil_reproduces_cubics():
    x = np.linspace(0.0, 6.0, 7)
    f = 0.3 * x ** 3 - x ** 2 + 2 * x - 1
    mid = 0.5 * (x[:-1] + x[1:])
    np.testing.assert_allclose(cubic_midpoints(f), 0.3 * mid ** 3 - mid ** 2 + 2 * mid - 1, atol=1e-12)
    b, w = cubic_stencil(np.array([0.0, 2.5, 6.0]), 7)
    np.testing.assert_allclose(np.sum(w, axis=0), 1.0, atol=1e-12)
    assert list(b) == [0.0, 1.0, 3.0]


def test_over_budget_is_refused(monkeypatch):
    monkeypatch.setattr(diffuse_tables, "MAX_SCALED_FLOATS", 1000)
    # (Mitsuba's loader passes the ThinFilmError on as a RuntimeError with its text)
    with pytest.raises((ThinFilmError, RuntimeError), match=r"'thickness': a texture reaching 1 needs"):
        mi.load_dict({"type": "thinfilm_diffuse", "layers": LAYERS, "reflectance": 0.7,
                      "thickness": bitmap()})


def test_gradient_wrt_the_bitmap():
    """The derivative of the RGB value with respect to a texel (through the table's cubic
    interpolation over the scale) against central differences of the rebuilt table."""
    b = mi.load_dict({"type": "thinfilm_diffuse", "model": "multiple", "layers": LAYERS,
                      "reflectance": 0.7, "thickness": bitmap()})
    params = mi.traverse(b)
    key = "thickness.data"
    wi, wo = directions(32, seed=9)
    n = dr.width(wi)
    uv = (np.full(n, 0.75), np.full(n, 0.25))      # the texel of scale 0.75 (TEXELS[0, 1])

    def total():
        return dr.sum(eval_at_ad(b, uv, wi, wo), axis=None)
    x = mi.TensorXf(params[key])
    dr.enable_grad(x)
    params[key] = x
    params.update()
    dr.backward(total())
    grad = np.array(dr.grad(x)).ravel()
    base = np.array(params[key]).ravel()
    assert base[1] == TEXELS[0, 1]

    def at(d):
        v = base.copy()
        v[1] += d
        params[key] = mi.TensorXf(v.reshape(TEXELS.shape + (1,)))
        params.update()
        return float(np.array(total()).ravel()[0])
    fd = (at(0.005) - at(-0.005)) / 0.01
    # both differentiate the same interpolant (the range, hence the nodes, is unchanged):
    # the central difference's truncation over a step of 1/5 of the node spacing and
    # float32 sums (~1e-6 of ~1 over 0.01) leave 2 % (measured 0.1 %)
    assert grad[1] == pytest.approx(fd, rel=2e-2), (grad, fd)
    assert grad[0] == 0.0 and grad[2] == 0.0 and grad[3] == 0.0    # texels not hit


def eval_at_ad(bsdf, uv, wi, wo):
    """The diffuse lobe's eval as a Dr.Jit value (for gradients)."""
    si = dr.zeros(mi.SurfaceInteraction3f, dr.width(wi))
    si.wi, si.uv = wi, mi.Point2f(uv[0], uv[1])
    ctx = mi.BSDFContext()
    ctx.component = 1
    return bsdf.eval(ctx, si, wo)
