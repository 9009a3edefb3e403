"""thinfilm_mi.render.layered.top: Snell's maps, and the smooth top's ``R`` and ``T`` from
both sides against ``tmm`` (float64; the stack evaluated exactly, float32: 2e-5)."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import LOSSLESS, WLS, coating, interaction, tmm_rt  # noqa: E402
from thinfilm_mi.render.layered.top import RoughTop, SmoothTop, Top, inward, outward  # noqa: E402


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


def test_rough_top_lobes_are_thinfilm_roughdielectrics():
    """:class:`RoughTop`'s four lobes (reflection and transmission, lit from outside and
    from the coat medium) are ``thinfilm_roughdielectric``'s ``eval`` of the same stack
    and roughness (``T`` read from outside at the outer direction's microfacet angle: the
    same as the reversed stack's from inside, float32 ~1e-6), and its samples' weights are
    that plugin's with the lobe fixed (the same microfacet sampled: 1e-5 relative)."""
    props = {"int_ior": 1.5, "alpha": 0.4, "distribution": "ggx", "layers": LOSSLESS,
             "tabulate": False}
    ref = mi.load_dict({"type": "thinfilm_roughdielectric", **props})
    top = coating(**props, ext_ior=1.000277).coating.top
    assert isinstance(top, RoughTop) and not top.smooth
    rng = np.random.default_rng(6)
    n = 512

    def directions(sign):
        mu, phi = rng.uniform(0.05, 1.0, n), rng.uniform(0, 2 * np.pi, n)
        s = np.sqrt(1 - mu ** 2)
        return mi.Vector3f(mi.Float(s * np.cos(phi)), mi.Float(s * np.sin(phi)), mi.Float(sign * mu))

    for sa, sb in ((1, 1), (-1, -1), (1, -1), (-1, 1)):
        a, b = directions(sa), directions(sb)
        si = interaction(1.0, n)
        si.wi = a
        reflect = sa == sb
        want = np.array(ref.eval(mi.BSDFContext(), si, b))
        got = np.array(top.lobe(si, a, b, mi.Bool(True), reflect=reflect, inside=sa < 0)[0])
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6 * np.abs(want).max())
        ctx = mi.BSDFContext()
        ctx.component = 0 if reflect else 1
        s2 = mi.Point2f(mi.Float(rng.random(n, dtype=np.float32)), mi.Float(rng.random(n, dtype=np.float32)))
        bs, w_ref = ref.sample(ctx, si, mi.Float(0.5), s2)
        wo, w, _, ok = top.sample(si, a, s2, mi.Bool(True), reflect, sa < 0)
        ok = np.array(ok) & (np.array(bs.pdf) > 0)
        assert ok.mean() > 0.25   # (from inside, beyond the critical angle: no transmission)
        np.testing.assert_allclose(np.array(wo)[:, ok], np.array(bs.wo)[:, ok], atol=1e-5)
        np.testing.assert_allclose(np.array(w)[:, ok], np.array(w_ref)[:, ok], rtol=1e-4, atol=1e-6)
