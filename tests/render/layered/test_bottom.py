"""thinfilm_mi.render.layered.bottom: what each bottom declares (its reflection lobes, its
delta reflection), the diffuse bottom's value alone, and the nested BSDF's and the
albedo's refusals."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import interaction  # noqa: E402
from thinfilm_mi.render.layered.bottom import NestedBottom  # noqa: E402


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


@pytest.mark.parametrize("base, has_delta, lobes", [
    ({"type": "conductor"}, True, ()),
    ({"type": "plastic"}, True, ("DiffuseReflection",)),
    ({"type": "roughconductor"}, False, ("GlossyReflection",)),
    ({"type": "diffuse"}, False, ("DiffuseReflection",)),
])
def test_a_nested_bottom_declares_its_lobes(base, has_delta, lobes):
    """The delta reflection (the delta-base chain's) and the non-delta reflection lobes
    (component 1) of Mitsuba's BSDFs, and the context of the non-delta lobes alone."""
    bottom = NestedBottom(mi.load_dict(base))
    assert bottom.has_delta == has_delta
    assert bottom.lobes == tuple(getattr(mi.BSDFFlags, name) for name in lobes)
    ctx = bottom.smooth_context(mi.TransportMode.Radiance)
    assert ctx.is_enabled(mi.BSDFFlags.DeltaReflection) == (not has_delta)


def test_a_diffuse_bottom_alone_is_mitsubas_diffuse():
    """Without films the diffuse bottom's value is Mitsuba's ``diffuse``'s, bit for bit;
    its lobe is the diffuse reflection; it exposes ``reflectance`` and ``roughness``."""
    ours = mi.load_dict({"type": "thinfilm_diffuse", "reflectance": 0.3})
    ref = mi.load_dict({"type": "diffuse", "reflectance": 0.3})
    bottom = ours.layered.bottom
    assert bottom.lobes == (mi.BSDFFlags.DiffuseReflection,) and not bottom.rough
    si, wo = interaction(0.6), mi.Vector3f(-0.6, 0.0, 0.8)
    np.testing.assert_array_equal(np.array(bottom.bare_value(si, wo, True)) * 0.8 / np.pi,
                                  np.array(ref.eval(mi.BSDFContext(), si, wo)))
    assert [k for k in mi.traverse(ours).keys()] == ["reflectance.value", "roughness.value"]


@pytest.mark.parametrize("bsdf, match", [
    ({}, r"thinfilm_coating: needs exactly one nested BSDF \(the base under the coat\), got 0"),
    ({"a": {"type": "diffuse"}, "b": {"type": "diffuse"}},
     r"thinfilm_coating: needs exactly one nested BSDF \(the base under the coat\), got 2"),
])
def test_the_nested_bsdf_is_one(bsdf, match):
    with pytest.raises(Exception, match=match):
        mi.load_dict({"type": "thinfilm_coating", **bsdf})


def test_an_albedo_above_one_is_refused():
    with pytest.raises(Exception, match=r"thinfilm_diffuse: 'reflectance' must be in \[0, 1\] "
                                        r"\(an albedo\), got 1.5"):
        mi.load_dict({"type": "thinfilm_diffuse", "reflectance": 1.5})
