"""thinfilm_conductor and thinfilm_dielectric: weights against the float64 core and
tmm, energy, Mitsuba equivalence with no films, loading, traversal, bad input."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tmm

import thinfilm_mi as tf

WLS = [380.0, 470.0, 590.0, 760.0]
VARIANTS = ["llvm_ad_spectral", "scalar_spectral"]
# Float32 tolerance for a weight against float64: the in-kernel recursion runs in
# float32 (relative rounding 6e-8 per operation); for the <= 3 films and
# thicknesses <= 500 nm used here the phase error is below 1e-5 rad and the
# reflectance error below 1e-5 (see tests/test_optics.py); 3e-5 leaves margin for
# the 1 nm spectral resampling of datasets and the float32 cos(theta).
F32_TOL = 3e-5


@pytest.fixture(params=VARIANTS)
def variant(request):
    mi.set_variant(request.param)
    return request.param


def interaction(cos_theta, wls=WLS):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.Spectrum(wls)
    s = float(np.sqrt(max(0.0, 1.0 - cos_theta ** 2)))
    si.wi = mi.Vector3f(s, 0.0, float(cos_theta))
    return si


def context(component=None):
    ctx = mi.BSDFContext()
    if component is not None:
        ctx.component = component
    return ctx


def weight(bsdf, cos_theta, component=None, sample1=0.3):
    bs, w = bsdf.sample(context(component), interaction(cos_theta), float(sample1),
                        mi.Point2f(0.5, 0.5))
    return bs, np.array(w, dtype=np.float64).ravel()


def tmm_R(n_list, d_list, theta, wl):
    return 0.5 * sum(tmm.coh_tmm(p, n_list, d_list, theta, wl)["R"] for p in "sp")


def tmm_T(n_list, d_list, theta, wl):
    return 0.5 * sum(tmm.coh_tmm(p, n_list, d_list, theta, wl)["T"] for p in "sp")


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


def _scene(bsdf, size=24):
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at([0, 1, 4], [0, 0, 0], [0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": size, "height": size},
                   "sampler": {"type": "independent", "sample_count": 8}},
        "env": {"type": "constant", "radiance": 0.3},
        "light": {"type": "point", "position": [2.0, 3.0, 2.0], "intensity": 20.0},
        "floor": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, -1, 0])
                  @ mi.ScalarTransform4f().rotate([1, 0, 0], -90) @ mi.ScalarTransform4f().scale(3),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "checkerboard"}}},
        "obj": {"type": "sphere", "bsdf": bsdf},
    })


@pytest.mark.parametrize("kind", ["conductor", "dielectric"])
def test_no_films_renders_like_mitsuba(kind):
    mi.set_variant("llvm_ad_spectral")
    if kind == "conductor":
        ref = {"type": "conductor", "eta": 0.2, "k": 3.1}
        ours = {"type": "thinfilm_conductor", "layers": "", "eta": 0.2, "k": 3.1}
    else:
        ref = {"type": "dielectric", "int_ior": 1.5}
        ours = {"type": "thinfilm_dielectric", "layers": "", "int_ior": 1.5}
    a = np.array(mi.render(_scene(ref), seed=7))
    b = np.array(mi.render(_scene(ours), seed=7))
    rel = np.abs(a - b).mean() / np.abs(a).mean()
    assert rel < 1e-4, rel


def test_thickness_edit_does_not_recompile():
    mi.set_variant("llvm_ad_spectral")
    # Exact mode: the kernel reads the thickness as an opaque input. (A table is
    # rebuilt on an edit; tests/test_tables.py covers that mode.)
    scene = _scene({"type": "thinfilm_conductor", "layers": "1.46 300; 0.42+2.47j 15",
                    "eta": 4.0, "k": 0.05, "tabulate": False}, size=16)
    params = mi.traverse(scene)
    assert "obj.bsdf.layers.0.thickness" in params.keys()
    assert "obj.bsdf.layers.1.eta.value" in params.keys()
    first = np.array(mi.render(scene, seed=1))
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()  # clear
        params["obj.bsdf.layers.0.thickness"] = 420.0
        params["obj.bsdf.layers.1.eta.value"] = 0.5
        params.update()
        second = np.array(mi.render(scene, seed=1))
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    jit = [k for k in history if k["type"] == dr.KernelType.JIT]
    assert jit, "no kernel ran"
    assert all(k.get("cache_hit") for k in jit), "a parameter edit recompiled the render kernel"
    assert np.abs(first - second).mean() > 1e-3  # and the edit took effect


def test_load_from_xml_and_to_string(tmp_path):
    mi.set_variant("llvm_ad_spectral")
    xml = tmp_path / "bsdf.xml"
    xml.write_text("""<scene version="3.0.0">
  <bsdf type="thinfilm_dielectric" id="glass">
    <float name="int_ior" value="1.6"/>
    <string name="layers" value="1.46 500; 0.42+2.47j 20; 1.2+7j 10"/>
  </bsdf>
  <bsdf type="thinfilm_conductor" id="si">
    <float name="thin_film_ior" value="1.46"/>
    <float name="thin_film_thickness" value="500"/>
    <spectrum name="eta" value="4.08"/>
    <spectrum name="k" value="0.03"/>
  </bsdf>
</scene>""")
    scene = mi.load_file(str(xml))
    text = str(scene)
    assert "ThinFilmDielectric" in text or "glass" in text
    glass = mi.load_dict({"type": "thinfilm_dielectric", "int_ior": 1.6,
                          "layers": "1.46 500; 0.42+2.47j 20"})
    desc = str(glass)
    assert "1.46 500 nm" in desc and "0.42+2.47j 20 nm" in desc and "1.6" in desc


@pytest.mark.parametrize("variant_name", ["llvm_ad_mono_polarized"])
def test_unsupported_variants_raise_clearly(variant_name):
    mi.set_variant(variant_name)
    try:
        for plugin in ("thinfilm_conductor", "thinfilm_dielectric"):
            with pytest.raises(Exception, match="not supported"):
                mi.load_dict({"type": plugin, "layers": "1.46 100"})
    finally:
        mi.set_variant("llvm_ad_spectral")


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


def test_dielectric_int_ior_must_be_real():
    mi.set_variant("llvm_ad_spectral")
    with pytest.raises(Exception, match="int_ior"):
        mi.load_dict({"type": "thinfilm_dielectric", "int_ior": "1.5+0.01j"})


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
