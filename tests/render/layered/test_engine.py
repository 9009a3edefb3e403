"""thinfilm_mi.render.layered.engine: the components a top names over a bottom, the
registry of estimators, the lobes a context enables, the order of the parameters (the
top's, the estimator's, the bottom's), and an edit through the engine, which must give the
BSDF freshly loaded with the new value, bit for bit."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import LOSSLESS, coating, interaction  # noqa: E402
from thinfilm_mi.errors import ThinFilmError  # noqa: E402
from thinfilm_mi.render.layered.engine import layered  # noqa: E402


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


@pytest.mark.parametrize("base, second", [
    ({"type": "conductor"}, None),
    ({"type": "diffuse"}, mi.BSDFFlags.DiffuseReflection),
    ({"type": "roughconductor"}, mi.BSDFFlags.GlossyReflection),
])
def test_components_follow_the_bottom(base, second):
    """Component 0 the delta reflection; component 1 the bottom's lobes, absent over a
    pure-delta bottom."""
    b = coating(bsdf=base)
    front = mi.BSDFFlags.FrontSide
    want = [mi.BSDFFlags.DeltaReflection | front] + ([] if second is None else [second | front])
    assert b.layered.components() == want and b.component_count() == len(want)


@pytest.mark.parametrize("base, second", [
    ({"type": "conductor"}, mi.BSDFFlags.GlossyReflection),
    ({"type": "diffuse"}, mi.BSDFFlags.DiffuseReflection),
    ({"type": "plastic"}, mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection),
])
def test_a_rough_top_names_glossy_components(base, second):
    """Under a rough top component 0 is the top's glossy reflection and component 1 is
    always there: a delta bottom's light leaves it glossy."""
    b = coating(bsdf=base, alpha=0.2)
    front = mi.BSDFFlags.FrontSide
    assert b.layered.components() == [mi.BSDFFlags.GlossyReflection | front, second | front]
    ctx = mi.BSDFContext()
    ctx.component = 1
    assert b.layered.enabled(ctx) == (False, True)


def test_the_registry_refuses_a_pair_it_has_no_estimator_for():
    """A rough top over a diffuse bottom has no estimator: named, not guessed."""
    rough = coating(alpha=0.2).layered.top
    bottom = mi.load_dict({"type": "thinfilm_diffuse"}).layered.bottom
    with pytest.raises(ThinFilmError, match="no estimator sums a RoughTop over a DiffuseBottom"):
        layered(rough, bottom, None, rough.mode, "test")


@pytest.mark.parametrize("component, enabled", [(None, (True, True)), (0, (True, False)),
                                                (1, (False, True))])
def test_a_context_enables_the_components_it_names(component, enabled):
    ctx = mi.BSDFContext()
    if component is not None:
        ctx.component = component
    assert coating().layered.enabled(ctx) == enabled
    assert mi.load_dict({"type": "thinfilm_diffuse"}).layered.enabled(ctx) == enabled


def test_parameters_are_the_tops_the_estimators_the_bottoms():
    keys = list(mi.traverse(coating(layers="1.46 300", coat_sigma_a=0.2)).keys())
    assert keys[0] == "layers.0.thickness" and keys[-1] == "bsdf.reflectance.value"
    assert keys.index("coat_sigma_a.value") < keys.index("coat_thickness") < keys.index(
        "bsdf.reflectance.value")
    keys = list(mi.traverse(mi.load_dict({"type": "thinfilm_diffuse",
                                          "layers": "SiO2 300; Au 4", "model": "single"})).keys())
    assert keys.index("layers.0.thickness") < keys.index("layers.1.thickness") \
        < keys.index("reflectance.value") < keys.index("roughness.value")


@pytest.mark.parametrize("plugin", ["thinfilm_coating", "thinfilm_diffuse"])
def test_an_edit_refreshes_the_top_and_the_estimator(plugin):
    """``layers.0.thickness`` 300 -> 200 nm: ``eval`` is that of the BSDF loaded at 200 nm."""
    extra = {"int_ior": 1.5, "bsdf": {"type": "diffuse"}} if plugin == "thinfilm_coating" else {}
    edited = mi.load_dict({"type": plugin, "layers": LOSSLESS, **extra})
    params = mi.traverse(edited)
    params["layers.0.thickness"] = 200.0
    params.update()
    fresh = mi.load_dict({"type": plugin, "layers": LOSSLESS.replace("300", "200"), **extra})
    si, wo = interaction(0.7), mi.Vector3f(-0.6, 0.0, 0.8)
    values = [np.array(b.eval(mi.BSDFContext(), si, wo)) for b in (edited, fresh)]
    before = np.array(mi.load_dict({"type": plugin, "layers": LOSSLESS, **extra}).eval(
        mi.BSDFContext(), si, wo))
    np.testing.assert_array_equal(values[0], values[1])
    assert np.any(values[0] != before)
