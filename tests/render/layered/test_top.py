"""thinfilm_mi.render.layered.top: Snell's maps, and the smooth top's ``R`` and ``T`` from
both sides against ``tmm`` (float64; the stack evaluated exactly, float32: 2e-5)."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import LOSSLESS, WLS, coating, interaction, tmm_rt  # noqa: E402
from thinfilm_mi.render.layered.top import SmoothTop, Top, inward, outward  # noqa: E402


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


def test_snell_maps_are_inverse_and_conserve_the_tangent_momentum():
    rng = np.random.default_rng(3)
    mu = rng.uniform(0.01, 1, 64)
    phi = rng.uniform(0, 2 * np.pi, 64)
    s = np.sqrt(1 - mu ** 2)
    w = mi.Vector3f(mi.Float(s * np.cos(phi)), mi.Float(s * np.sin(phi)), mi.Float(mu))
    w_in, ok = inward(w, 1.5)
    back, leaves = outward(w_in, 1.5)
    assert np.all(np.array(ok)) and np.all(np.array(leaves))
    # z = sqrt(1 - x² - y²) in float32 loses ~6e-8/μ near grazing (μ >= 0.01 here)
    np.testing.assert_allclose(np.array(back), np.array(w), atol=1e-5)
    # 1.0 sin θ = 1.5 sin θ' and unit length
    np.testing.assert_allclose(1.5 * np.hypot(*np.array(w_in)[:2]), s, rtol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(np.array(w_in), axis=0), 1.0, rtol=1e-6)
    # beyond the critical angle an inner direction does not leave
    _, leaves = outward(mi.Vector3f(0.8, 0.0, 0.6), 1.5)
    assert not bool(leaves[0])


@pytest.mark.parametrize("cos", [1.0, 0.5, 0.17])
def test_smooth_top_is_the_stack_from_both_sides(cos):
    """``R``, ``T`` lit from outside at θ and ``R`` lit from the coat medium at θ' (Snell's
    law at the mean indices) are ``tmm``'s of the stack and of the reversed stack."""
    top = coating(layers=LOSSLESS, tabulate=False).coating.top
    assert isinstance(top, Top) and isinstance(top, SmoothTop) and top.smooth
    n, d = [1.0, 1.46, 2.3, 1.5], [300.0, 80.0]
    out = top.unpolarized(interaction(cos), mi.Float(cos), True, inside=False, transmission=True)
    cos_in = float(np.sqrt(1 - (1 - cos * cos) / 1.5 ** 2))
    np.testing.assert_allclose(float(top.inward(interaction(cos).wi)[0].z[0]), cos_in, rtol=1e-6)
    back = top.unpolarized(interaction(cos), mi.Float(cos_in), True, inside=True, transmission=False)
    want = np.array([tmm_rt(n, d, cos, wl) for wl in WLS])
    want_in = np.array([tmm_rt(n[::-1], d[::-1], cos_in, wl)[0] for wl in WLS])
    np.testing.assert_allclose(np.array(out.R, np.float64)[:, 0], want[:, 0], atol=2e-5)
    np.testing.assert_allclose(np.array(out.T, np.float64)[:, 0], want[:, 1], atol=2e-5)
    np.testing.assert_allclose(np.array(back.R, np.float64)[:, 0], want_in, atol=2e-5)


def test_a_top_without_films_between_equal_indices_is_invisible():
    """No films between equal indices: invisible (the engine returns the bottom itself);
    films, or a coat medium of another index: not."""
    assert coating(int_ior=1.0).coating.top.invisible
    assert not coating(int_ior=1.0, layers=LOSSLESS).coating.top.invisible
    assert not coating().coating.top.invisible


def test_a_top_must_implement_the_interface():
    """:class:`Top` is abstract: a top that leaves out a method cannot be made."""
    class Partial(Top):
        def response(self, si, cos, active, inside=False, transmission=False):
            return None
    with pytest.raises(TypeError, match="abstract"):
        Partial()
