"""``thinfilm_dielectric``: reflection and transmission against the float64 core from both
sides, energy and total internal reflection, refraction like Mitsuba's dielectric,
dispersive media, bad input."""
import mitsuba as mi
import numpy as np
import pytest
import tmm

import thinfilm_mi as tf
from tests.support.specular import F32_TOL, WLS, tmm_R, weight


def tmm_T(n_list, d_list, theta, wl):
    return 0.5 * sum(tmm.coh_tmm(p, n_list, d_list, theta, wl)["T"] for p in "sp")


FILMS_ABSORBING = [(1.46, 500.0), (0.42 + 2.47j, 20.0), (1.2 + 7.0j, 10.0)]


@pytest.mark.parametrize("cos_theta", [0.9, 0.5, 0.1, -0.95, -0.8, -0.3])
def test_dielectric_components_match_core_from_both_sides(variant, cos_theta):
    layers = "1.46 500; 0.42+2.47j 20; 1.2+7j 10"
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers, "int_ior": 1.6, "tabulate": False,
                         "ext_ior": 1.0})
    stack = tf.Stack(FILMS_ABSORBING, substrate=1.6, ambient=1.0)
    if cos_theta < 0:
        stack = stack.reversed()
    res = stack.rt(np.array(WLS), float(np.arccos(abs(cos_theta))))
    bs_r, w_r = weight(bsdf, cos_theta, component=0)
    bs_t, w_t = weight(bsdf, cos_theta, component=1)
    np.testing.assert_allclose(w_r, res.R, atol=F32_TOL)
    # Radiance transport scales transmitted radiance by (eta_i / eta_t)^2.
    eta_ti = 1.0 / 1.6 if cos_theta > 0 else 1.6
    np.testing.assert_allclose(w_t / eta_ti ** 2, res.T, atol=F32_TOL)
    # Independent reference: tmm on the same stack and side.
    n_list = [1.0] + [n for n, _ in FILMS_ABSORBING] + [1.6]
    d_list = [np.inf] + [d for _, d in FILMS_ABSORBING] + [np.inf]
    if cos_theta < 0:
        n_list, d_list = n_list[::-1], d_list[::-1]
    theta = float(np.arccos(abs(cos_theta)))
    if n_list[0] * np.sin(theta) < n_list[-1].real:  # tmm needs a propagating exit angle
        np.testing.assert_allclose(w_t / eta_ti ** 2, [tmm_T(n_list, d_list, theta, wl) for wl in WLS],
                                   atol=F32_TOL)
    np.testing.assert_allclose(w_r, [tmm_R(n_list, d_list, theta, wl) for wl in WLS], atol=F32_TOL)
    # The two sides differ with absorbing films (so the reversal really matters).
    other = tf.Stack(FILMS_ABSORBING, substrate=1.6, ambient=1.0)
    if cos_theta > 0:
        other = other.reversed()
    assert np.max(np.abs(other.rt(np.array(WLS), 0.0).R - stack.rt(np.array(WLS), 0.0).R)) > 0.05


@pytest.mark.parametrize("cos_theta", [1.0, 0.6, 0.05, -1.0, -0.9, -0.7, -0.3, -0.01])
def test_dielectric_energy_and_tir(variant, cos_theta):
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": "2.1 130; 0.05+3.2j 8", "tabulate": False,
                         "int_ior": 1.5})
    bs_r, w_r = weight(bsdf, cos_theta, component=0)
    bs_t, w_t = weight(bsdf, cos_theta, component=1)
    eta = 1.5 / 1.000277
    eta_ti = 1.0 / eta if cos_theta > 0 else eta
    R, T = w_r, w_t / eta_ti ** 2
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(T))
    assert np.all(R >= 0) and np.all(T >= 0)
    assert np.all(R + T <= 1 + 1e-5)
    sin_t = eta * np.sqrt(1 - cos_theta ** 2)
    if cos_theta < 0 and sin_t > 1:  # beyond the critical angle seen from inside
        assert np.all(T == 0)
    # Both components enabled: the sampled weight is R / P(R) or T / P(T) with
    # P(R) = mean R / (mean R + mean T).
    p_r = R.mean() / (R.mean() + T.mean())
    bs, w = weight(bsdf, cos_theta, sample1=0.5 * p_r)  # picks reflection
    np.testing.assert_allclose(float(np.array(bs.pdf).ravel()[0]), p_r, rtol=1e-4)
    np.testing.assert_allclose(w, R / p_r, rtol=1e-4, atol=1e-7)
    if p_r < 0.999:
        bs, w = weight(bsdf, cos_theta, sample1=p_r + 0.5 * (1 - p_r))  # picks transmission
        np.testing.assert_allclose(float(np.array(bs.pdf).ravel()[0]), 1 - p_r, rtol=1e-4)
        np.testing.assert_allclose(w, T * eta_ti ** 2 / (1 - p_r), rtol=1e-4, atol=1e-7)
        assert float(np.array(bs.eta).ravel()[0]) == pytest.approx(1 / eta_ti, rel=1e-5)


def test_dielectric_refraction_matches_mitsuba_dielectric(variant):
    ours = mi.load_dict({"type": "thinfilm_dielectric", "layers": "", "int_ior": 1.33})
    ref = mi.load_dict({"type": "dielectric", "int_ior": 1.33})
    for cos_theta in (0.9, 0.4, -0.9, -0.7):
        for u in (0.01, 0.99):
            a, wa = weight(ours, cos_theta, sample1=u)
            b, wb = weight(ref, cos_theta, sample1=u)
            np.testing.assert_allclose(np.array(a.wo).ravel(), np.array(b.wo).ravel(), atol=1e-6)
            np.testing.assert_allclose(np.array(a.eta).ravel(), np.array(b.eta).ravel(), rtol=1e-6)
            np.testing.assert_allclose(wa, np.array(wb).ravel(), rtol=1e-5)


def test_dielectric_int_ior_must_be_real():
    mi.set_variant("llvm_ad_spectral")
    with pytest.raises(Exception, match="int_ior"):
        mi.load_dict({"type": "thinfilm_dielectric", "int_ior": "1.5+0.01j"})


def test_dispersive_glass_and_air_media_are_accepted():
    mi.set_variant("llvm_ad_spectral")
    # BK7 (k ~ 1e-8) and Ciddor air are non-absorbing for our purposes.
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "int_ior": "BK7", "ext_ior": "air", "tabulate": False,
                         "layers": "SiO2 500; Au 20"})
    assert "BK7" in str(bsdf)
    _, w = weight(bsdf, -0.9, component=0)
    ref = tf.Stack("SiO2 500; Au 20", substrate="BK7", ambient="air").reversed().rt(
        np.array(WLS), float(np.arccos(0.9))).R
    np.testing.assert_allclose(w, ref, atol=F32_TOL)
