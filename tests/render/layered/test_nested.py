"""thinfilm_mi.render.layered.nested: the registry of the sum's estimators (a closed form
where the base has one that applies, else the walk), the sampling mixture's share from the
probe, the fold into the escape cone, and the nested BSDF alone where the top is
invisible."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import coating, interaction  # noqa: E402
from thinfilm_mi.render.layered.forms import Lambertian  # noqa: E402
from thinfilm_mi.render.layered.nested import MIXTURE_BOUNDS, fold, unfold  # noqa: E402
from thinfilm_mi.render.layered.walk import RandomWalk  # noqa: E402
from thinfilm_mi.render.textures import scalar  # noqa: E402


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


@pytest.mark.parametrize("extra, estimator", [
    ({}, Lambertian),
    ({"coat_sigma_a": 0.2}, RandomWalk),           # absorption: no closed form
    ({"bsdf": {"type": "roughconductor"}}, RandomWalk),
])
def test_the_sum_is_a_closed_form_where_one_applies(extra, estimator):
    c = coating(**extra).coating
    assert type(c.sum) is estimator
    assert (c.form is None) == (estimator is RandomWalk)


def test_rgb_variants_walk_over_diffuse():
    mi.set_variant("llvm_ad_rgb")
    assert type(coating().coating.sum) is RandomWalk


def test_an_invisible_top_samples_the_nested_bsdf_alone():
    """No films between equal indices: ``sample`` is the nested BSDF's, bit for bit."""
    ours, ref = coating(int_ior=1.0), mi.load_dict({"type": "diffuse", "reflectance": 0.5})
    si = interaction(0.6)
    bs, w = ours.sample(mi.BSDFContext(), si, 0.3, mi.Point2f(0.2, 0.7))
    bs_r, w_r = ref.sample(mi.BSDFContext(), si, 0.3, mi.Point2f(0.2, 0.7))
    np.testing.assert_array_equal(np.array(bs.wo), np.array(bs_r.wo))
    np.testing.assert_array_equal(np.array(w), np.array(w_r))


@pytest.mark.parametrize("base, share", [
    ({"type": "diffuse", "reflectance": 0.5}, MIXTURE_BOUNDS[1]),   # ν = 1: the top bound
    ({"type": "roughconductor", "alpha": 0.3}, (0.55, 0.75)),       # ν ≈ 2
    ({"type": "roughconductor", "alpha": 0.02}, MIXTURE_BOUNDS[0]),  # ν in the hundreds
])
def test_the_cosine_share_falls_with_the_lobes_peak(base, share):
    """The probe's share ``c = clip(0.8 - 0.15 ln ν)``: the top bound over a Lambertian
    (``ν = p π / cos = 1`` exactly), the bottom one over a near mirror, between them over
    α 0.3 (its two probe samples at normal incidence have ``ν`` near 2: ``c`` 0.69)."""
    c = coating(bsdf=base).coating
    _, got = c.probe(mi.TransportMode.Radiance, interaction(1.0), True)
    got = scalar(got)
    if isinstance(share, tuple):
        assert share[0] < got < share[1]
    else:
        assert abs(got - share) < 1e-6


def test_fold_maps_the_trapped_directions_onto_the_cone_and_back():
    """``fold`` sends ``(0, μ_c)`` onto ``(μ_c, 1)`` (rim to rim, grazing to the normal) at
    the same azimuth, and ``unfold`` inverts it (float32: 1e-6)."""
    mu_c = float(np.sqrt(1 - 1 / 1.5 ** 2))
    mu = np.array([1e-3, 0.2, 0.5, mu_c - 1e-4])
    phi = np.array([0.3, 2.0, 4.0, 5.5])
    s = np.sqrt(1 - mu ** 2)
    w = mi.Vector3f(mi.Float(s * np.cos(phi)), mi.Float(s * np.sin(phi)), mi.Float(mu))
    f = fold(w, mi.Float(mu_c))
    got = np.array(f.z)
    np.testing.assert_allclose(got, mu_c + (mu_c - mu) * (1 - mu_c) / mu_c, atol=1e-6)
    np.testing.assert_allclose(np.arctan2(np.array(f.y), np.array(f.x)) % (2 * np.pi), phi, atol=1e-5)
    np.testing.assert_allclose(np.array(dr_norm(f)), 1.0, atol=1e-6)
    back = unfold(f, mi.Float(mu_c))
    np.testing.assert_allclose(np.array(back), np.array(w), atol=1e-5)


def dr_norm(v):
    return np.sqrt(np.array(v.x) ** 2 + np.array(v.y) ** 2 + np.array(v.z) ** 2)
