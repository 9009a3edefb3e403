"""Helpers of the rough plugins' tests: the stacks, plugins, interactions and contexts,
the microfacet distribution written out in float64 (D and G1), and the check that a
small roughness gives the smooth plugin."""
from __future__ import annotations

import math
from functools import partial

import mitsuba as mi
import numpy as np

from tests.support import bsdf
from tests.support.bsdf import to_np

mi.set_variant("llvm_ad_spectral")


WLS = (450.0, 520.0, 610.0, 700.0)
#: Interactions at these wavelengths, at uv (0.3, 0.6).
make_si = partial(bsdf.make_si, wavelengths=WLS, uv=(0.3, 0.6))
# A dielectric stack on gold, and an absorbing stack on glass (R + T < 1, and the
# two sides of the glass differ), as float64 reference stacks and as layers strings.
COND_FILMS = [(1.46, 300.0), (2.3, 60.0)]
COND_SUB = 0.35 + 2.9j
DIEL_FILMS = [(1.46, 300.0), (0.42 + 2.47j, 10.0)]
DIEL_SUB = 1.5
# Float32 against float64 for a film reflectance/transmittance (the bound of
# tests/plugins/test_thinfilm_conductor.py: phase error < 1e-5 rad for these stacks).
F32_TOL = 3e-5


def films_tol(bsdf):
    """Error bound of the BSDF's R and T: float32, plus the kernel's documented
    ``table_error`` when the stack reads them from a verified table (the kernel
    may tabulate stacks of several films; that is its choice, not this plugin's)."""
    stack = bsdf.stack
    tabled = getattr(stack, "mode", lambda: "exact")() != "exact"
    return F32_TOL + (float(stack.table_error) if tabled else 0.0)


def layers_of(films):
    return "; ".join(f"{complex(n).real}{complex(n).imag:+}j {d}" for n, d in films)


def conductor(**extra):
    return mi.load_dict({"type": "thinfilm_roughconductor", "layers": layers_of(COND_FILMS),
                         "eta": COND_SUB.real, "k": COND_SUB.imag, "ext_ior": 1.0, **extra})


def dielectric(**extra):
    return mi.load_dict({"type": "thinfilm_roughdielectric", "layers": layers_of(DIEL_FILMS),
                         "int_ior": DIEL_SUB, "ext_ior": 1.0, **extra})


def random_samples(n, seed):
    rng = mi.PCG32(size=n, initstate=seed)
    return rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())


# ---------------------------------------------------------------------------
# values against a float64 reference: D G F / (4 cos_i cos_o), F from Stack.rt
# ---------------------------------------------------------------------------
def ref_D(m, au, av, dist):
    x2 = (m[:, 0] / au) ** 2 + (m[:, 1] / av) ** 2
    c2 = m[:, 2] ** 2
    if dist == "beckmann":
        d = np.exp(-x2 / c2) / (np.pi * au * av * c2 ** 2)
    else:
        d = 1.0 / (np.pi * au * av * (x2 + c2) ** 2)
    # Mitsuba sets D = 0 where D cos(theta_m) <= 1e-20; lanes within a factor 10 of
    # that cut could go either way in float32, so they are marked NaN and skipped.
    dc = d * np.abs(m[:, 2])
    return np.where(dc > 1e-19, d, np.where(dc <= 1e-21, 0.0, np.nan))


def ref_G1(v, m, au, av, dist):
    xy = (au * v[:, 0]) ** 2 + (av * v[:, 1]) ** 2
    t2 = xy / v[:, 2] ** 2
    with np.errstate(divide="ignore"):
        if dist == "beckmann":  # Mitsuba's rational fit of Smith-Beckmann (< 0.35 %)
            a = 1.0 / np.sqrt(t2)
            g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1 + 2.276 * a + 2.577 * a * a))
        else:
            g = 2.0 / (1.0 + np.sqrt(1.0 + t2))
    g = np.where(xy == 0, 1.0, g)
    return np.where(np.sum(v * m, axis=1) * v[:, 2] <= 0, 0.0, g)


def random_dirs(rng, n, lower=False):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.08  # keep away from grazing (the 1/cos factors)
    if lower:
        v[:, 2] = -v[:, 2]
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v.astype(np.float32).astype(np.float64)  # what the float32 kernel sees


def f32_vec(v):
    return mi.Vector3f(*[v[:, i] for i in range(3)])


# Relative tolerance on D*G in float32: the Beckmann exponent x = tan^2/alpha^2
# (< 40 where D is not negligible) has relative rounding ~3e-7, so exp(-x) is good to
# ~1.2e-5; the half vector, 1/cos^4 and the G1 fit add a few 1e-7. 1e-4 leaves margin.
DG_RTOL = 1e-4


# ---------------------------------------------------------------------------
# alpha -> 0: the smooth BSDFs
# ---------------------------------------------------------------------------
ALPHA0 = 1e-3


def window(stack, theta_deg, which):
    """min and max of R or T over the microfacet angles a Beckmann surface with
    alpha = ALPHA0 can produce: tan(theta_m) is Rayleigh with sigma = alpha/sqrt(2),
    so P(theta_m > 8 alpha) = exp(-64); the angle on a facet is theta_i +- theta_m."""
    t = math.radians(theta_deg)
    th = np.clip(np.linspace(t - 8 * ALPHA0, t + 8 * ALPHA0, 201), 0.0, math.pi / 2)
    v = getattr(stack.rt(np.array(WLS)[None, :], th[:, None]), which)
    return v.min(axis=0), v.max(axis=0)


def check_near_smooth(rough, smooth, ref_stack, wi, theta_side, which, ctx, max_turn, seed):
    """Samples of ``rough`` (alpha = ALPHA0) against the smooth BSDF's one sample.

    Every weight is R (or T) at its facet angle times G1 = 1 (Mitsuba's fit is
    exactly 1 for cot(theta)/alpha >= 1.6), so it lies in the window of the float64
    reference (+ float32 or table error), and the mean matches the smooth weight;
    every direction is within ``max_turn`` rad of the smooth one."""
    n = 4096
    s1, s2 = random_samples(n, seed)
    bs, w = rough.sample(ctx, make_si(n, wi), s1, s2)
    bs0, w0 = smooth.sample(ctx, make_si(1, wi), 0.5, mi.Point2f(0.5, 0.5))
    lo, hi = window(ref_stack, theta_side, which)
    w = to_np(w)
    tol = films_tol(rough) + films_tol(smooth)
    assert np.all(w >= lo[:, None] - tol) and np.all(w <= hi[:, None] + tol)
    np.testing.assert_allclose(w.mean(axis=1), to_np(w0).ravel(),
                               atol=float(np.max(hi - lo)) + tol)
    cos_dev = to_np(bs.wo).T @ to_np(bs0.wo).ravel()
    assert np.all(cos_dev >= math.cos(max_turn))
    np.testing.assert_allclose(to_np(bs.eta), to_np(bs0.eta).ravel()[0], rtol=1e-6)
