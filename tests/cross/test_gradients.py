"""Per-wavelength gradients of every plugin's sample weight and eval, with respect to a
film thickness and a numeric film index, against central finite differences of the
float64 optics (:class:`thinfilm_mi.Stack`).

Forward-mode AD gives d(value)/d(parameter) at each of the four wavelengths of a
lane separately, so errors that cancel in the mean over wavelengths (a selection
probability left attached to the graph) show here. Where a plugin divides its weight
by a lobe-selection probability p, that probability is a detached sampling decision:
d(R / p) = dR / p, so the weight's relative gradient is dR / R.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi as tf  # noqa: E402
from tests.support.bsdf import unit_vector

WLS = [450.0, 520.0, 610.0, 700.0]
EXT = 1.0
# An absorbing film (so that R + T < 1 and the selection probability moves with
# the parameter) over a dielectric film; the swept parameter is film 0's.
FILMS = [(1.46, 310.0), (0.42 + 2.47j, 8.0)]
DIEL_SUB = 1.5
COND_SUB = 0.35 + 2.9j
PARAMS = {"layers.0.thickness": ("d", 1e-3), "layers.0.eta.value": ("n", 1e-6)}


def layers_of(films):
    return "; ".join(f"{complex(n).real}{complex(n).imag:+}j {d}" for n, d in films)


def perturbed(what, h):
    (n, d), rest = FILMS[0], FILMS[1:]
    return [((n + h, d) if what == "n" else (n, d + h))] + rest


def stack_rt(films, sub, cos, inside=False, ambient=EXT):
    """Float64 R, T of the stack at the test wavelengths (reversed when lit from inside)."""
    theta = np.arccos(np.clip(cos, 0.0, 1.0))
    if inside:
        st = tf.Stack([(n, d) for n, d in films[::-1]], substrate=ambient, ambient=sub)
    else:
        st = tf.Stack(films, substrate=sub, ambient=ambient)
    res = st.rt(np.array(WLS), theta)
    return res.R, res.T


def fd(fn, what, h):
    """Central difference of ``fn(films)`` (float64) with respect to film 0's ``what``."""
    return (fn(perturbed(what, h)) - fn(perturbed(what, -h))) / (2 * h)


def forward_grad(bsdf, key, fn):
    """(value, d value / d params[key]) per wavelength, by forward-mode AD through ``fn()``."""
    params = mi.traverse(bsdf)
    x = params[key]
    dr.enable_grad(x)
    params.update()
    x = params[key]
    dr.set_grad(x, 1.0)
    out = fn()
    dr.forward_to(out)
    value = np.array(dr.detach(out), dtype=np.float64).ravel()
    grad = np.array(dr.grad(out), dtype=np.float64).ravel()
    dr.disable_grad(x)
    return value, grad


def interaction(wi):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.Spectrum(WLS)
    si.wi = mi.Vector3f(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    return si


def direction(theta_deg, phi_deg=0.0, below=False):
    v = unit_vector(theta_deg, phi_deg)
    return -v if below else v


def check(grad, ref):
    # float32 kernel against float64 central differences (truncation ~h^2 R''' ~ 1e-12):
    # the phase 4 pi n d / lambda ~ 10 rad carries float32 rounding ~1e-6 relative, so
    # the gradients agree to ~1e-4 of their scale; 2e-3 of the largest |gradient| is
    # far below the errors of an attached selection probability (~10x the gradient).
    scale = np.max(np.abs(ref))
    assert scale > 0
    np.testing.assert_allclose(grad, ref, atol=2e-3 * scale, rtol=2e-3)


def load(kind, **extra):
    base = {"layers": layers_of(FILMS), "ext_ior": EXT, "tabulate": False}
    if kind in ("thinfilm_conductor", "thinfilm_roughconductor"):
        base.update(eta=COND_SUB.real, k=COND_SUB.imag)
    elif kind in ("thinfilm_dielectric", "thinfilm_roughdielectric"):
        base["int_ior"] = DIEL_SUB
    if kind.startswith("thinfilm_rough"):
        base.update(alpha=0.3, distribution="ggx")
    return mi.load_dict({"type": kind, **base, **extra})


@pytest.mark.parametrize("key", PARAMS)
def test_conductor_sample_weight_gradient_per_wavelength(key):
    bsdf = load("thinfilm_conductor")
    cos = 0.8
    si = interaction(direction(np.degrees(np.arccos(cos))))
    w, g = forward_grad(bsdf, key, lambda: bsdf.sample(mi.BSDFContext(), si, 0.5,
                                                       mi.Point2f(0.5, 0.5))[1])
    what, h = PARAMS[key]
    np.testing.assert_allclose(w, stack_rt(FILMS, COND_SUB, cos)[0], atol=3e-5)
    check(g, fd(lambda f: stack_rt(f, COND_SUB, cos)[0], what, h))


@pytest.mark.parametrize("key", PARAMS)
@pytest.mark.parametrize("inside", [False, True])
@pytest.mark.parametrize("lobe", ["R", "T"])
def test_dielectric_sample_weight_gradient_per_wavelength(key, inside, lobe):
    """Reflection lanes weigh R / p, transmission lanes T / (1 - p) (times eta^2 for
    radiance): the gradient is dR / p, resp. dT / (1 - p), at each wavelength."""
    bsdf = load("thinfilm_dielectric")
    cos = 0.75
    si = interaction(direction(np.degrees(np.arccos(cos)), below=inside))
    sample1 = 0.0 if lobe == "R" else 1.0
    w, g = forward_grad(bsdf, key, lambda: bsdf.sample(mi.BSDFContext(), si, sample1,
                                                       mi.Point2f(0.5, 0.5))[1])
    what, h = PARAMS[key]
    idx = 0 if lobe == "R" else 1
    R, T = stack_rt(FILMS, DIEL_SUB, cos, inside)
    p = R.mean() / (R.mean() + T.mean())
    share = p if lobe == "R" else 1.0 - p
    scale = w / ((R, T)[idx] / share)        # eta^2 radiance factor of T lanes, else 1
    check(g, scale * fd(lambda f: stack_rt(f, DIEL_SUB, cos, inside)[idx], what, h) / share)


@pytest.mark.parametrize("key", PARAMS)
def test_roughconductor_eval_and_sample_gradients_per_wavelength(key):
    """eval = R(wi.m) D G / (4 cos_i) and the sample weight R(wi.m) G1: both have the
    relative gradient dR / R of the films at the microfacet angle."""
    bsdf = load("thinfilm_roughconductor")
    wi, wo = direction(40.0, 10.0), direction(25.0, 200.0)
    si = interaction(wi)
    what, h = PARAMS[key]
    m = (wi + wo) / np.linalg.norm(wi + wo)
    cos_m = float(wi @ m)
    R = stack_rt(FILMS, COND_SUB, cos_m)[0]
    dR = fd(lambda f: stack_rt(f, COND_SUB, cos_m)[0], what, h)
    v, g = forward_grad(bsdf, key, lambda: bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo)))
    check(g, v * dR / R)
    bs_wo = []

    def sample():
        bs, w = bsdf.sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.3, 0.6))
        bs_wo.append(np.array(bs.wo, dtype=np.float64).ravel())
        return w
    w, g = forward_grad(bsdf, key, sample)
    wo_s = bs_wo[0]
    m = (wi + wo_s) / np.linalg.norm(wi + wo_s)
    cos_m = float(wi @ m)
    R = stack_rt(FILMS, COND_SUB, cos_m)[0]
    check(g, w * fd(lambda f: stack_rt(f, COND_SUB, cos_m)[0], what, h) / R)


@pytest.mark.parametrize("key", PARAMS)
@pytest.mark.parametrize("lobe", ["R", "T"])
def test_roughdielectric_eval_and_sample_gradients_per_wavelength(key, lobe):
    bsdf = load("thinfilm_roughdielectric")
    idx = 0 if lobe == "R" else 1
    wi = direction(35.0, 0.0)
    si = interaction(wi)
    what, h = PARAMS[key]
    bs_wo = []

    def sample():
        bs, w = bsdf.sample(mi.BSDFContext(), si, 0.0 if lobe == "R" else 1.0,
                            mi.Point2f(0.3, 0.6))
        bs_wo.append(np.array(bs.wo, dtype=np.float64).ravel())
        return w
    w, g = forward_grad(bsdf, key, sample)
    wo = bs_wo[0]
    assert (wo[2] > 0) == (lobe == "R")
    # the microfacet normal of the sampled pair (generalised half vector)
    eta = DIEL_SUB / EXT
    m = wi + wo * (1.0 if lobe == "R" else eta)
    m = m / np.linalg.norm(m) * np.sign(m[2])
    cos_m = float(wi @ m)
    RT = stack_rt(FILMS, DIEL_SUB, cos_m)
    dRT = fd(lambda f: stack_rt(f, DIEL_SUB, cos_m)[idx], what, h)
    check(g, w * dRT / RT[idx])
    v, g = forward_grad(bsdf, key, lambda: bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo)))
    check(g, v * dRT / RT[idx])


@pytest.mark.parametrize("key", PARAMS)
def test_diffuse_sample_and_eval_gradients_per_wavelength(key):
    """thinfilm_diffuse with a non-absorbing coating (all films over an ambient-matched
    base): the specular lane weighs k_r / p (relative gradient dk_r / k_r), the
    diffuse lane and eval k_d t_i t_o / (1 - p) (relative gradient dt_i/t_i + dt_o/t_o)
    with the "single" model (the "multiple" series' R_dh: tests/plugins/test_thinfilm_diffuse.py)."""
    films = [FILMS[0], (2.3, 60.0)]

    def coating(f, cos):
        return stack_rt(f, EXT, cos)

    def perturbed2(what, hh):
        (n, d) = films[0]
        return [((n + hh, d) if what == "n" else (n, d + hh)), films[1]]

    bsdf = mi.load_dict({"type": "thinfilm_diffuse", "layers": layers_of(films), "ext_ior": EXT,
                         "model": "single", "reflectance": 0.6, "tabulate": False})
    what, h = PARAMS[key]
    cos_i = 0.7
    si = interaction(direction(np.degrees(np.arccos(cos_i))))

    def d_of(fn):
        return (fn(perturbed2(what, h)) - fn(perturbed2(what, -h))) / (2 * h)

    # specular lane
    w, g = forward_grad(bsdf, key, lambda: bsdf.sample(mi.BSDFContext(), si, 0.0,
                                                       mi.Point2f(0.4, 0.7))[1])
    kr = coating(films, cos_i)[0]
    check(g, w * d_of(lambda f: coating(f, cos_i)[0]) / kr)
    # diffuse lane
    bs_wo = []

    def sample():
        bs, w = bsdf.sample(mi.BSDFContext(), si, 0.999999, mi.Point2f(0.4, 0.7))
        bs_wo.append(np.array(bs.wo, dtype=np.float64).ravel())
        return w
    w, g = forward_grad(bsdf, key, sample)
    cos_o = float(bs_wo[0][2])

    def rel(cos):
        return d_of(lambda f: coating(f, cos)[1]) / coating(films, cos)[1]
    check(g, w * (rel(cos_i) + rel(cos_o)))
    v, g = forward_grad(bsdf, key, lambda: bsdf.eval(mi.BSDFContext(), si,
                                                     mi.Vector3f(bs_wo[0])))
    check(g, v * (rel(cos_i) + rel(cos_o)))
