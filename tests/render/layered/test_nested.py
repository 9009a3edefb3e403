"""thinfilm_mi.render.layered.nested: the registry of the sum's estimators (a closed form
where the base has one that applies, else the walk), and the sampling mixture's share,
0 where the top is invisible (the nested BSDF itself)."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import coating, interaction  # noqa: E402
from thinfilm_mi.render.layered.forms import Lambertian  # noqa: E402
from thinfilm_mi.render.layered.nested import MIXTURE  # noqa: E402
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
    """No films between equal indices: no mixture, and ``sample`` is the nested BSDF's."""
    ours, ref = coating(int_ior=1.0), mi.load_dict({"type": "diffuse", "reflectance": 0.5})
    assert scalar(ours.coating.mix) == 0.0 and scalar(coating().coating.mix) == MIXTURE
    si = interaction(0.6)
    bs, w = ours.sample(mi.BSDFContext(), si, 0.3, mi.Point2f(0.2, 0.7))
    bs_r, w_r = ref.sample(mi.BSDFContext(), si, 0.3, mi.Point2f(0.2, 0.7))
    np.testing.assert_array_equal(np.array(bs.wo), np.array(bs_r.wo))
    np.testing.assert_array_equal(np.array(w), np.array(w_r))
