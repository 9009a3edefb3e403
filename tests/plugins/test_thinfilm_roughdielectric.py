"""``thinfilm_roughdielectric``: transmission against a float64 reference, the radiance
scaling of transmission, the smooth limit at small roughness, and its two media."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")

import thinfilm_mi as tf  # noqa: E402  (registers the plugins)
from tests.support.bsdf import context, direction, to_np
from tests.support.rough import (
    ALPHA0,
    DG_RTOL,
    DIEL_FILMS,
    DIEL_SUB,
    WLS,
    check_near_smooth,
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


@pytest.mark.parametrize("dist,au,av,inside,mode", [
    ("beckmann", 0.25, 0.25, False, mi.TransportMode.Radiance),
    ("ggx", 0.1, 0.3, True, mi.TransportMode.Radiance),
    ("beckmann", 0.25, 0.25, True, mi.TransportMode.Importance),
    ("ggx", 0.1, 0.3, False, mi.TransportMode.Importance),
])


def test_transmission_matches_float64_reference(dist, au, av, inside, mode):
    rng = np.random.default_rng(23)
    n = 512
    wi = random_dirs(rng, n, lower=inside)
    wo = random_dirs(rng, n, lower=not inside)
    aniso = {"alpha": au} if au == av else {"alpha_u": au, "alpha_v": av}
    b = dielectric(distribution=dist, **aniso)
    ours = to_np(b.eval(context(mode=mode), make_si(n, f32_vec(wi)), f32_vec(wo))).T
    eta = DIEL_SUB if not inside else 1.0 / DIEL_SUB  # eta_t / eta_i
    m = wi + eta * wo
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    m *= np.sign(m[:, 2:3])
    dim, dom = np.sum(wi * m, axis=1), np.sum(wo * m, axis=1)
    ok = (dim * wi[:, 2] > 0) & (dom * wo[:, 2] > 0)  # the microfacet faces both directions
    stack = tf.Stack(DIEL_FILMS, substrate=DIEL_SUB, ambient=1.0)
    if inside:
        stack = stack.reversed()
    T = stack.rt(np.array(WLS)[None, :], np.arccos(np.clip(np.abs(dim), 0, 1))[:, None]).T
    scale = 1.0 / eta ** 2 if mode == mi.TransportMode.Radiance else 1.0
    k = np.where(ok, ref_D(m, au, av, dist) * ref_G1(wi, m, au, av, dist)
                 * ref_G1(wo, m, au, av, dist) * scale * eta ** 2 * np.abs(dim * dom)
                 / (np.abs(wi[:, 2]) * np.abs(wo[:, 2]) * (dim + eta * dom) ** 2), 0.0)[:, None]
    ref = T * k
    got = ours / np.abs(wo[:, 2:3])
    tol = k * (films_tol(b) + DG_RTOL * T)
    ok = np.isfinite(ref)
    assert np.all(np.abs(got - ref)[ok] <= tol[ok]), np.max(np.abs(got - ref)[ok] / tol[ok])
    assert ok.mean() > 0.95 and np.count_nonzero(ref > 1e-3) > n // 8


def test_radiance_scaling_of_transmission():
    b = dielectric(distribution="ggx", alpha=0.2)
    n = 2048
    for lower, eta_ti in ((False, 1.0 / DIEL_SUB), (True, DIEL_SUB)):
        wi_np = random_dirs(np.random.default_rng(3), n, lower=lower)
        si = make_si(n, f32_vec(wi_np))
        s1, s2 = random_samples(n, 4)
        out = {}
        for mode in (mi.TransportMode.Radiance, mi.TransportMode.Importance):
            bs, w = b.sample(context(1, mode=mode), si, s1, s2)
            out[mode] = (to_np(w), to_np(b.eval(context(1, mode=mode), si, bs.wo)), to_np(bs.pdf))
        (wr, fr, pr), (wi_, fi, pi) = out[mi.TransportMode.Radiance], out[mi.TransportMode.Importance]
        np.testing.assert_array_equal(pr, pi)
        np.testing.assert_allclose(wr, wi_ * eta_ti ** 2, rtol=1e-6)
        np.testing.assert_allclose(fr, fi * eta_ti ** 2, rtol=1e-6)
        assert np.count_nonzero(wr) > n


@pytest.mark.parametrize("theta", [0.0, 40.0, 150.0, 170.0])
def test_small_alpha_is_smooth_dielectric(theta):
    rough = dielectric(alpha=ALPHA0)
    smooth = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers_of(DIEL_FILMS),
                           "int_ior": DIEL_SUB, "ext_ior": 1.0})
    stack = tf.Stack(DIEL_FILMS, substrate=DIEL_SUB, ambient=1.0)
    if theta > 90:
        stack = stack.reversed()
    for component, which in ((0, "R"), (1, "T")):
        # Refraction turns a facet tilt of 8 alpha by at most ~3x here (away from the
        # critical angle): allow 2 * 8 alpha * 3.
        check_near_smooth(rough, smooth, stack, direction(theta, 15.0),
                           min(theta, 180.0 - theta), which,
                           context(component, mode=mi.TransportMode.Importance),
                           48 * ALPHA0, seed=6)


def test_rough_dielectric_needs_two_media():
    with pytest.raises(Exception, match=r"int_ior.*ext_ior.*must differ"):
        mi.load_dict({"type": "thinfilm_roughdielectric", "int_ior": 1.33, "ext_ior": 1.33})
    with pytest.raises(Exception, match="int_ior"):
        mi.load_dict({"type": "thinfilm_roughdielectric", "int_ior": "1.5+0.1j"})
