"""``thinfilm_conductor``: weights against the float64 core and tmm, components,
edits without recompiling, substrate errors, named materials against the numpy
datasets, bad input."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.bsdf import context
from tests.support.kernels import assert_edits_render_from_cache
from tests.support.specular import F32_TOL, WLS, interaction, lit_floor_scene, tmm_R, weight

RNG_STACKS = [
    [(1.46, 500.0)],
    [(1.46, 500.0), (0.42 + 2.47j, 20.0)],
    [(2.3, 80.0), (1.38, 120.0), (0.15 + 3.5j, 10.0)],
]


@pytest.mark.parametrize("films", RNG_STACKS)
@pytest.mark.parametrize("cos_theta", [1.0, 0.7, 0.2, 0.01])
def test_conductor_weight_is_stack_reflectance(variant, films, cos_theta):
    layers = "; ".join(f"{complex(n).real}{complex(n).imag:+}j {d}" for n, d in films)
    sub = 4.08 + 0.03j
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "tabulate": False,
                         "eta": sub.real, "k": sub.imag, "ext_ior": 1.0})
    bs, w = weight(bsdf, cos_theta)
    theta = float(np.arccos(cos_theta))
    ref = tf.Stack(films, substrate=sub).rt(np.array(WLS), theta).R
    np.testing.assert_allclose(w, ref, atol=F32_TOL)
    n_list = [1.0] + [n for n, _ in films] + [sub]
    d_list = [np.inf] + [d for _, d in films] + [np.inf]
    ref_tmm = [tmm_R(n_list, d_list, theta, wl) for wl in WLS]
    np.testing.assert_allclose(w, ref_tmm, atol=F32_TOL)
    sampled = bs.sampled_type
    if dr.is_array_v(sampled) and dr.width(sampled):
        sampled = sampled[0]
    assert int(sampled) == int(mi.BSDFFlags.DeltaReflection)


def test_conductor_rejects_back_side_and_disabled_component(variant):
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 300", "material": "1.5+3j"})
    _, w = weight(bsdf, -0.5)
    assert np.all(w == 0)
    ctx = mi.BSDFContext()
    ctx.type_mask = mi.BSDFFlags.DeltaTransmission
    _, w2 = bsdf.sample(ctx, interaction(0.5), 0.3, mi.Point2f(0.5, 0.5))
    assert np.all(np.array(w2) == 0)


def test_thickness_edit_does_not_recompile():
    mi.set_variant("llvm_ad_spectral")
    # Exact mode: the kernel reads the thickness as an opaque input. (A table is
    # rebuilt on an edit; tests/tabulate/test_exact.py covers that mode.)
    scene = lit_floor_scene({"type": "thinfilm_conductor", "layers": "1.46 300; 0.42+2.47j 15",
                    "eta": 4.0, "k": 0.05, "tabulate": False}, size=16)
    params = mi.traverse(scene)
    assert "obj.bsdf.layers.0.thickness" in params.keys()
    assert "obj.bsdf.layers.1.eta.value" in params.keys()
    assert_edits_render_from_cache(scene, params, {"obj.bsdf.layers.0.thickness": 420.0,
                                                   "obj.bsdf.layers.1.eta.value": 0.5})


BAD = [
    ({"layers": "1.46 -5"}, "thickness"),
    ({"layers": "1.46 nan"}, "nan"),
    ({"layers": "1.46"}, "missing thickness"),
    ({"layers": "1.46 100 7"}, "tokens"),
    ({"layers": "1.46 100,, 2 5"}, "tokens"),
    ({"layers": "1.5-0.2j 100"}, "k must be >= 0"),
    ({"layers": "unobtainium 100"}, "unobtainium"),
    ({"ext_ior": "1.2+0.1j"}, "ext_ior"),
    ({"ext_ior": -1.0}, "ext_ior"),
    ({"thin_film_ior": 1.4}, "thin_film_thickness"),
    ({"layers": "1.4 10", "thin_film_ior": 1.4, "thin_film_thickness": 5.0}, "not both"),
    ({"layrs": "1.4 10"}, "layrs"),
]


@pytest.mark.parametrize("extra,needle", BAD)
def test_bad_input_names_parameter_and_value(extra, needle):
    mi.set_variant("llvm_ad_spectral")
    with pytest.raises(Exception, match=needle):
        mi.load_dict({"type": "thinfilm_conductor", "material": "2+3j", **extra})
    # the process stays usable
    ok = mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 100", "material": "2+3j"})
    assert "ThinFilmConductor" in str(ok)


@pytest.mark.parametrize("props,needle", [
    ({"material": "2+3j", "eta": 1.0, "k": 2.0}, "not both"),
    ({"eta": 1.0}, "together"),
])


def test_conductor_substrate_errors(props, needle):
    mi.set_variant("llvm_ad_spectral")
    with pytest.raises(Exception, match=needle):
        mi.load_dict({"type": "thinfilm_conductor", **props})


@pytest.mark.parametrize("substrate,layers", [("Cu", "SiO2 500; Au 20"), ("Si", "SiO2 500"),
                                              ("Al", "TiO2 60; MgF2 95")])


def test_named_materials_in_kernel_match_numpy_datasets(variant, substrate, layers):
    # Wavelengths between the datasets' knots and off the 1 nm grid: the kernel's
    # spectra must reproduce the datasets' own linear interpolation, so the only
    # difference left is float32 rounding.
    wls = [401.3, 487.77, 612.5, 777.7]
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "material": substrate, "layers": layers, "tabulate": False,
                         "ext_ior": 1.0})
    si = interaction(0.8, wls)
    _, w = bsdf.sample(context(), si, 0.5, mi.Point2f(0.5, 0.5))
    ref = tf.Stack(layers, substrate=substrate).rt(np.array(wls), float(np.arccos(0.8))).R
    np.testing.assert_allclose(np.array(w, dtype=np.float64).ravel(), ref, atol=F32_TOL)
