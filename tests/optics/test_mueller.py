"""Mueller components (thinfilm_mi/optics/mueller.py) against tmm, unrolled and as a loop."""
from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest
import tmm
from drjit.llvm import Float64, UInt32

import thinfilm_mi  # noqa: F401  (registers the plugins in every variant)
from tests.support.mueller import channels
from tests.support.polarized import polarized_variant, pytestmark  # noqa: F401  (the skip mark, variant fixture)
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.optics.mueller import mueller_rt, mueller_rt_loop


def tmm_channels(n_list, d_list, cos, wl):
    """The 8 channels (optics.mueller) from tmm's amplitudes, per point."""
    out = []
    for c, w in zip(cos, wl):
        s, p = (tmm.coh_tmm(pol, n_list, d_list, math.acos(c), w) for pol in "sp")
        cr = s["r"] * np.conj(p["r"])
        z = s["t"] * np.conj(p["t"])
        ct = math.sqrt(s["T"] * p["T"]) * (z / abs(z) if abs(z) > 0 else 0.0)
        out.append([(s["R"] + p["R"]) / 2, (s["T"] + p["T"]) / 2, (s["R"] - p["R"]) / 2,
                    cr.real, cr.imag, (s["T"] - p["T"]) / 2, ct.real, ct.imag])
    return np.array(out)


# ---------------------------------------------------------------------------
# float64 components
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("inside", [False, True])
def test_components_match_tmm_unrolled_and_as_a_loop(inside):
    """R, B, C of reflection and transmission against tmm's amplitudes (conjugated
    products in our convention: C = r_s conj(r_p), sign of C_im as jones_shape's,
    which tests/cross/test_polarized.py maps onto Mitsuba's), an absorbing film included,
    lit from glass through its critical angle (TIR: T = 0, |C| = R = 1). Both
    evaluators are float64 runs of the same recursion as tmm: agreement to ~1e-14
    (measured 4e-14); 1e-11 leaves room for other platforms' rounding."""
    films = [(2.3, 140.0), (1.46, 60.0), (0.42 + 2.47j, 8.0), (2.1, 95.0)]
    n0, n_exit = 1.0, 1.52
    if inside:
        films, n0, n_exit = films[::-1], 1.52, 1.0
    rng = np.random.default_rng(3)
    cos, wl = rng.uniform(0.02, 1.0, 40), rng.uniform(360.0, 830.0, 40)
    n_list = [n0] + [n for n, _ in films] + [n_exit]
    ref = tmm_channels(n_list, [np.inf] + [d for _, d in films] + [np.inf], cos, wl)
    cx = [(Cx(float(np.real(n)), float(np.imag(n))), d) for n, d in films]
    ours = channels(mueller_rt(n0, Float64(cos), cx, Cx(n_exit, 0.0), Float64(wl)), cos.size)
    re, im, th = (Float64(np.r_[x, 0.0]) for x in (np.real([n for n, _ in films]),
                                                     np.imag([n for n, _ in films]),
                                                     [d for _, d in films]))

    def film(j):
        return Cx(dr.gather(Float64, re, j), dr.gather(Float64, im, j)), dr.gather(Float64, th, j)

    loop = channels(mueller_rt_loop(n0, Float64(cos), UInt32(len(films)), film, Cx(n_exit, 0.0),
                                    Float64(wl), n0_max=n0), cos.size)
    assert np.abs(ours - ref).max() < 1e-11
    assert np.abs(loop - ref).max() < 1e-11
    assert np.abs(ref[:, 3:5]).max() > 0.3     # the cross terms are really compared
    if inside:
        tir = cos < math.sqrt(1.0 - (1.0 / 1.52) ** 2)
        assert tir.any() and np.allclose(ours[tir, 1], 0.0, atol=1e-12)
