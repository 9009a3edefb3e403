"""The ``thinfilm_coating`` plugin: the nested BSDF exactly where the top is invisible
(check 1), Mitsuba's chi2 test of ``sample`` against ``pdf`` (check 5), gradients against
finite differences (check 6), the RGB product approximation's ΔE2000, traversal and
validation at load and on edits. The model's closed-form checks (2, 3, 5) are in
``tests/render/layered/`` (``test_walk.py``, ``test_forms.py``, ``test_delta.py``).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.kernels import assert_edits_render_from_cache  # noqa: E402
from thinfilm_mi.colour.cie import colour_differences, normalised_weights  # noqa: E402
from thinfilm_mi.errors import ThinFilmError  # noqa: E402

WLS = [450.0, 520.0, 610.0, 700.0]
BASES = {
    "diffuse": {"type": "diffuse", "reflectance": 0.6},
    "roughconductor": {"type": "roughconductor", "alpha": 0.3},
    "principled": {"type": "principled", "roughness": 0.4, "metallic": 0.2,
                   "base_color": {"type": "rgb", "value": [0.7, 0.3, 0.2]}},
    # a delta reflection over a Lambertian (its exterior is the coat medium)
    "plastic": {"type": "plastic", "ext_ior": 1.5, "int_ior": 2.5, "nonlinear": True,
                "diffuse_reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.7]}},
}
#: bases with delta lobes only: the coating is then a pure delta BSDF (one component)
PURE_DELTA = {"conductor": {"type": "conductor", "material": "Au"}}
FILMS = "TiO2 120; SiO2 200"


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


def coating(base, **extra):
    return mi.load_dict({"type": "thinfilm_coating", "bsdf": {**BASES, **PURE_DELTA}[base],
                         **extra})


def directions(rng, n):
    mu = rng.uniform(0.02, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - mu ** 2)
    return mi.Vector3f(mi.Float(s * np.cos(phi)), mi.Float(s * np.sin(phi)), mi.Float(mu))


def interaction(wi, n):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wavelengths = mi.Spectrum(*WLS)
    si.wi = wi
    return si


@pytest.mark.parametrize("base", list(BASES))
def test_invisible_top_is_the_nested_bsdf(base):
    """Check 1: no films, ``int_ior`` = ``ext_ior``, no absorption: eval, pdf, eval_pdf
    and sample (weights and directions) are the nested BSDF's, bit for bit."""
    b = coating(base, int_ior=1.000277)
    ref = mi.load_dict(BASES[base])
    rng = np.random.default_rng(2)
    n = 4096
    si = interaction(directions(rng, n), n)
    wo = directions(rng, n)
    ctx = mi.BSDFContext()
    for name in ("eval", "pdf"):
        np.testing.assert_array_equal(np.array(getattr(b, name)(ctx, si, wo)),
                                      np.array(getattr(ref, name)(ctx, si, wo)))
    for x, y in zip(b.eval_pdf(ctx, si, wo), ref.eval_pdf(ctx, si, wo)):
        np.testing.assert_array_equal(np.array(x), np.array(y))
    s1 = mi.Float(rng.random(n, dtype=np.float32))
    s2 = mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32))
    (bs, w), (bs_ref, w_ref) = b.sample(ctx, si, s1, s2), ref.sample(ctx, si, s1, s2)
    np.testing.assert_array_equal(np.array(w), np.array(w_ref))
    np.testing.assert_array_equal(np.array(bs.wo), np.array(bs_ref.wo))
    np.testing.assert_array_equal(np.array(bs.pdf), np.array(bs_ref.pdf))


@pytest.mark.parametrize("base", list(BASES))
@pytest.mark.parametrize("theta", [20.0, 70.0])
def test_chi2_sample_against_pdf(base, theta):
    """Check 5: the directions ``sample`` draws (component 1, the light through the coat)
    have the density ``pdf`` returns: Mitsuba's chi2 test at significance 0.01 on a 24 x 48
    grid, 16 x 16 points per cell to integrate the pdf. A sample is counted where it is
    valid (a base direction beyond the critical angle is a failed sample, which ``pdf``
    leaves out alike)."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    b = coating(base, layers=FILMS, int_ior=1.5)
    t = np.radians(theta)
    wi = mi.Vector3f(float(np.sin(t) * np.cos(0.4)), float(np.sin(t) * np.sin(0.4)), float(np.cos(t)))
    ctx = mi.BSDFContext()
    ctx.component = 1

    def sample_func(sample):
        n = dr.width(sample)
        bs, w = b.sample(ctx, interaction(wi, n), sample[0], mi.Point2f(sample[1], sample[2]))
        return bs.wo, dr.select(bs.pdf > 0, 1.0, 0.0)

    def pdf_func(wo):
        return b.pdf(ctx, interaction(wi, dr.width(wo)), wo)

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=100_000, res=24, ires=16)
    assert test.run(0.01), test.messages
    assert float(test.histogram_sum[0]) > 0.4   # most samples are valid


@pytest.mark.parametrize("base", list(BASES))
def test_sample_pdf_is_pdf_and_weight_estimates_eval(base):
    """MIS needs ``bs.pdf`` to be the ``pdf`` of the direction (both components on: the
    delta choice's ``1 - P_R`` included; float32, 1e-5), and the sample weight times it
    to estimate ``eval``: both are walks from the same first vertex, so over 4096 samples
    their means agree within 4σ of the difference."""
    b = coating(base, layers=FILMS, int_ior=1.5)
    rng = np.random.default_rng(21)
    n = 4096
    si = interaction(mi.Vector3f(0.4, 0.3, float(np.sqrt(0.75))), n)
    ctx = mi.BSDFContext()
    bs, w = b.sample(ctx, si, mi.Float(rng.random(n, dtype=np.float32)),
                     mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32)))
    through = (np.array(bs.sampled_component) == 1) & (np.array(bs.pdf) > 0)
    assert through.sum() > n // 4
    pdf = np.array(b.pdf(ctx, si, bs.wo))
    np.testing.assert_allclose(np.array(bs.pdf)[through], pdf[through], rtol=1e-5)
    est = (np.array(w, np.float64) * np.array(bs.pdf, np.float64))[:, through]
    ev = np.array(b.eval(ctx, si, bs.wo), np.float64)[:, through]
    diff = est - ev
    assert np.all(np.abs(diff.mean(axis=1)) <= 4 * diff.std(axis=1) / np.sqrt(diff.shape[1]) + 1e-7)


def test_delta_reflection_is_the_stack():
    """Component 0 alone: the mirror direction with weight ``R`` of the stack, the same
    ``R`` as ``thinfilm_dielectric``'s reflection over the coat medium (same machinery);
    float32 rounding of two evaluations: 1e-6."""
    b = coating("diffuse", layers=FILMS, int_ior=1.5)
    d = mi.load_dict({"type": "thinfilm_dielectric", "layers": FILMS, "int_ior": 1.5})
    ctx = mi.BSDFContext()
    ctx.component = 0
    wi = mi.Vector3f(0.6, 0.0, 0.8)
    bs, w = b.sample(ctx, interaction(wi, 1), 0.5, mi.Point2f(0.5, 0.5))
    _, w_ref = d.sample(ctx, interaction(wi, 1), 0.5, mi.Point2f(0.5, 0.5))
    np.testing.assert_allclose(np.array(w), np.array(w_ref), atol=1e-6)
    np.testing.assert_allclose(np.array(bs.wo)[:, 0], [-0.6, 0.0, 0.8], atol=1e-7)
    assert int(np.array(bs.sampled_type)[0]) == int(mi.BSDFFlags.DeltaReflection)


def finite_differences(b, key, h, n, seed):
    """Central differences of ``b``'s ``eval`` in the parameter ``key`` (step ``h``) at ``n``
    random direction pairs (float64 of the float32 values), then the parameter restored
    with its gradient enabled: ``(fd, parameter, evaluate, rng)``, ``evaluate()`` the
    ``eval`` at the same directions, ``rng`` the generator that drew them."""
    params = mi.traverse(b)
    x0 = float(np.array(params[key]).ravel()[0])
    rng = np.random.default_rng(seed)
    si = interaction(directions(rng, n), n)
    wo = directions(rng, n)
    ctx = mi.BSDFContext()

    def value(x):
        params[key] = type(params[key])(x)
        params.update()
        return np.array(b.eval(ctx, si, wo), np.float64)

    fd = (value(x0 + h) - value(x0 - h)) / (2 * h)
    params[key] = type(params[key])(x0)
    params.update()
    theta = params[key]
    dr.enable_grad(theta)
    params.update()
    return fd, theta, lambda: b.eval(ctx, si, wo), rng


#: a base whose delta lobe is chosen with a fixed probability (its eta moves no sampling
#: decision): the walk's delta vertices and its exit tail carry the conductor's gradient
BLEND = {"type": "blendbsdf", "weight": 0.5, "bsdf_0": {"type": "conductor", "eta": 2.0, "k": 3.0},
         "bsdf_1": {"type": "diffuse", "reflectance": 0.6}}


@pytest.mark.parametrize("key,bounces,base", [("layers.0.thickness", 3, BASES["diffuse"]),
                                              ("coat_sigma_a.value", 3, BASES["diffuse"]),
                                              ("bsdf.roughness.value", 1, BASES["principled"]),
                                              ("bsdf.bsdf_0.eta.value", 3, BLEND)],
                         ids=["thickness", "sigma_a", "roughness", "delta-eta"])
def test_gradient_matches_finite_differences(key, bounces, base):
    """Check 6: reverse-mode (and, for the thickness, forward-mode) derivatives of
    ``eval`` (``max_bounces`` 3, no Russian roulette: a smooth function of the parameters
    for its fixed seed) against
    central differences in float64 of the float32 values at step h: 1e-3 relative. The
    truncation error is h²/6 f'''/f': for the thickness (h = 1 nm) ~(4π n h/λ)²/6 < 2e-4,
    for σ_a (h = 0.004) (h L)²/6 < 1e-4 with L <= ~10 the path's length in the coat
    (it was 3e-3 at h = 0.02); the float32 rounding of the values divided by 2h stays
    below 1e-6 absolute. The nested BSDF's own parameter (``principled``'s roughness)
    keeps its gradient: with one bounce (the walk's later directions are sampled from
    the base, so their finite differences are not those of the detached-sampling
    estimate) its ``eval`` is a smooth function, h = 0.004 as for σ_a. A conductor's
    ``eta`` inside a ``blendbsdf`` (its delta vertices in the walk, whose ``eval`` is 0,
    and the delta round trips of the exit): 3 bounces, h = 0.004 (the Fresnel factor is
    smooth in eta; (h/eta)² < 1e-5)."""
    # tabulate false: the finite differences of a table (within table_error) are not
    # the derivative the exact recursion has
    # (constant film indices and a diffuse base where the base is not differentiated:
    # smaller kernels to compile)
    b = mi.load_dict({"type": "thinfilm_coating", "bsdf": base, "layers": "2.3 120; 1.46 200",
                      "int_ior": 1.5, "coat_sigma_a": 0.2, "max_bounces": bounces,
                      "tabulate": False})
    h = 1.0 if "thickness" in key else 0.004
    fd, theta, evaluate, rng = finite_differences(b, key, h, 64, 4)
    if key == "layers.0.thickness":   # forward mode: every lane and wavelength
        out = evaluate()
        dr.set_grad(theta, 1.0)
        grad_fwd = np.array(dr.forward_to(out), np.float64)
        np.testing.assert_allclose(grad_fwd, fd, rtol=1e-3, atol=1e-3 * np.abs(fd).max())
    # reverse mode (what an optimisation runs): of a random combination of every lane and
    # wavelength, so that each enters
    weights = rng.uniform(0.5, 1.5, fd.shape)
    out = evaluate()
    dr.backward_from(dr.sum(sum(out[i] * mi.Float(weights[i]) for i in range(4))))
    grad_bwd = float(np.array(dr.grad(theta)).ravel()[0])
    scale = np.sum(np.abs(weights * fd))   # the terms' size (the sum may cancel)
    np.testing.assert_allclose(grad_bwd, np.sum(weights * fd), atol=1e-3 * scale)


@pytest.mark.parametrize("key,h", [("layers.0.thickness", 1.0), ("bsdf.reflectance.value", 0.004)])
def test_closed_form_gradient_is_unbiased(key, h):
    """Over ``diffuse`` without coat absorption (the closed form): forward-mode derivatives
    of ``eval`` against central differences lane by lane (h as above: truncation < 2e-4
    relative). The value is deterministic; a film's derivative reaches ``R_dh`` through one
    cosine-distributed direction (``thinfilm_mi/render/layered/forms.py``), an unbiased
    estimate, so over 4096 lanes the mean difference is within 4σ of the lanes' spread
    plus 2e-4 of the mean |FD|; the albedo's derivative has no estimate in it and matches
    lane by lane (1e-3)."""
    b = mi.load_dict({"type": "thinfilm_coating", "bsdf": BASES["diffuse"], "int_ior": 1.5,
                      "layers": "2.3 120; 1.46 200", "tabulate": False})
    assert b.coating.form is not None
    n = 4096
    fd, theta, evaluate, _ = finite_differences(b, key, h, n, 8)
    out = evaluate()
    dr.set_grad(theta, 1.0)
    grad = np.array(dr.forward_to(out), np.float64)
    if key.startswith("bsdf."):
        np.testing.assert_allclose(grad, fd, rtol=1e-3, atol=1e-3 * np.abs(fd).max())
        return
    diff = grad - fd
    assert np.abs(diff).max() > 1e-3 * np.abs(fd).max()   # the estimate is in it
    assert np.all(np.abs(diff.mean(axis=1)) <= 4 * diff.std(axis=1) / np.sqrt(n)
                  + 2e-4 * np.abs(fd).mean(axis=1)), (diff.mean(axis=1), diff.std(axis=1))


def test_traverse_shows_the_nested_bsdf_and_edits_reach_it():
    scene = mi.load_dict({"type": "scene", "obj": {
        "type": "rectangle", "bsdf": {"type": "thinfilm_coating", "layers": FILMS,
                                      "coat_sigma_a": 0.1, "bsdf": BASES["diffuse"]}}})
    params = mi.traverse(scene)
    keys = set(params.keys())
    assert {"obj.bsdf.layers.0.thickness", "obj.bsdf.coat_sigma_a.value",
            "obj.bsdf.coat_thickness", "obj.bsdf.bsdf.reflectance.value"} <= keys
    bsdf = scene.shapes()[0].bsdf()
    si = interaction(mi.Vector3f(0, 0, 1), 1)
    wo = mi.Vector3f(0.0, 0.6, 0.8)
    ctx = mi.BSDFContext()
    before = np.array(bsdf.eval(ctx, si, wo))
    params["obj.bsdf.bsdf.reflectance.value"] = 0.3
    params.update()
    after = np.array(bsdf.eval(ctx, si, wo))
    assert np.all(after < 0.75 * before)   # 0.3 against 0.6: about half, less interreflection


@pytest.mark.parametrize("extra,edits", [
    ({"coat_sigma_a": 0.1}, {"obj.bsdf.layers.0.thickness": 150.0,
                             "obj.bsdf.coat_sigma_a.value": 0.4, "obj.bsdf.coat_thickness": 2.0,
                             "obj.bsdf.bsdf.reflectance.value": 0.3}),
    ({}, {"obj.bsdf.layers.0.thickness": 150.0, "obj.bsdf.bsdf.reflectance.value": 0.3}),
    ({"alpha": 0.2}, {"obj.bsdf.alpha.value": 0.35, "obj.bsdf.layers.0.thickness": 150.0}),
], ids=["walk", "closed", "rough"])
def test_edits_do_not_recompile(extra, edits):
    """The kernel reads every edited value as an opaque input: an edit of a film's
    thickness, the coat's absorption and thickness, and the nested BSDF's albedo renders
    from the cached kernel (exact stack: a table is rebuilt on an edit, which
    tests/tabulate/test_exact.py covers for every plugin); without absorption (the closed
    form over ``diffuse``) a film's edit updates ``R_dh`` in place."""
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 16, "height": 16},
                   "sampler": {"type": "independent", "sample_count": 4}},
        "light": {"type": "constant"},
        "obj": {"type": "sphere", "bsdf": {"type": "thinfilm_coating", "layers": FILMS,
                                           "tabulate": False, "bsdf": BASES["diffuse"],
                                           **extra}}})
    assert_edits_render_from_cache(scene, mi.traverse(scene), edits)


#: The form of every plugin's refused edit (``render.params.check_value``): the plugin, the
#: key, what the value is, the range, the value, and that the edit was undone.
REFUSED_EDIT = (r"^thinfilm_coating: '{key}' \((?P<what>.+)\) must be finite and >= 0, "
                r"got (a texture holding )?{value}; the edit was undone and the BSDF keeps its "
                r"last valid parameters$")


@pytest.mark.parametrize("key,value,what", [
    ("coat_thickness", -1.0, "the coat medium's thickness"),
    ("coat_thickness", float("nan"), "the coat medium's thickness"),
    ("coat_sigma_a.value", -1.0, "an absorption coefficient per unit of 'coat_thickness'"),
    ("coat_sigma_a.value", float("nan"), "an absorption coefficient per unit of 'coat_thickness'"),
    ("coat_sigma_a.value", float("inf"), "an absorption coefficient per unit of 'coat_thickness'"),
    ("layers.0.thickness", -3.0, "a film thickness (nm)"),
])
def test_bad_edits_are_refused_and_undone(key, value, what):
    """A refused scene edit says what every plugin's does (the plugin, the key, what the
    parameter is, the range, the value, and that the edit was undone), and is undone."""
    import re
    scene = mi.load_dict({"type": "scene", "obj": {
        "type": "rectangle", "bsdf": {"type": "thinfilm_coating", "layers": FILMS,
                                      "coat_sigma_a": 0.1, "bsdf": BASES["diffuse"]}}})
    params = mi.traverse(scene)
    full = f"obj.bsdf.{key}"
    old = np.array(params[full]).copy()
    params[full] = type(params[full])(value)
    with pytest.raises(ThinFilmError) as err:
        params.update()
    text = str(err.value)
    form = re.match(REFUSED_EDIT.format(key=re.escape(key), value=re.escape(f"{value:.7g}")), text)
    assert form and form["what"] == what, text
    np.testing.assert_array_equal(np.array(mi.traverse(scene)[full]), old)


@pytest.mark.parametrize("extra,message", [
    ({"coat_sigma_a": -0.1}, "coat_sigma_a"),
    ({"coat_thickness": float("nan")}, "coat_thickness"),
    ({"coat_thickness": "thick"}, "coat_thickness"),
    ({"max_bounces": 0}, "max_bounces"),
    ({"int_ior": -1.5}, "int_ior"),
    ({"bsdf": 1.0}, "nested BSDF"),
    ({"bsdf_misspelt": 1.0}, "bsdf_misspelt"),
])
def test_bad_input_at_load_names_the_parameter(extra, message):
    props = {"type": "thinfilm_coating", "bsdf": BASES["diffuse"], **extra}
    with pytest.raises(Exception, match=message):
        mi.load_dict(props)


def test_needs_one_nested_bsdf():
    with pytest.raises(Exception, match="exactly one nested BSDF"):
        mi.load_dict({"type": "thinfilm_coating"})
    # unnamed (XML-style) children are found by type
    b = mi.load_dict({"type": "thinfilm_coating", "base": BASES["diffuse"]})
    assert "bsdf = SmoothDiffuse" in str(b)


@pytest.fixture
def polarized():
    mi.set_variant("llvm_ad_spectral_polarized")
    yield
    mi.set_variant("llvm_ad_spectral")


def _pol_interaction(wi, n):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wavelengths = mi.UnpolarizedSpectrum(*WLS)
    si.wi = wi
    return si


def _mueller(x):
    """A Mueller matrix value as numpy (row, column, wavelength, lane)."""
    return np.array(x, np.float64)


def test_polarized_single_bounce_is_the_chain_of_the_plugins_matrices(polarized):
    """Polarized, one bounce over a polarizing base (``roughconductor``): the Mueller
    matrix is ``thinfilm_dielectric``'s transmission out, the base's matrix, and
    ``thinfilm_dielectric``'s transmission in (their own frames: the rotations chain),
    without their radiance factors ``η²`` and times the coating's ``(η_e/η_c)² cos θ_o /
    cos θ_o'``. Exact amplitudes on both sides (``tabulate`` false); float32: 1e-5 of the
    largest entry."""
    films, eta = FILMS, 1.5
    b = mi.load_dict({"type": "thinfilm_coating", "layers": films, "int_ior": eta, "ext_ior": 1.0,
                      "bsdf": BASES["roughconductor"], "max_bounces": 1, "tabulate": False})
    d = mi.load_dict({"type": "thinfilm_dielectric", "layers": films, "int_ior": eta,
                      "ext_ior": 1.0, "tabulate": False})
    base = mi.load_dict(BASES["roughconductor"])
    ctx = mi.BSDFContext()
    ctx.component = 1                     # the dielectric's transmission
    wi = mi.Vector3f(0.5, 0.2, float(np.sqrt(0.71)))
    wo = mi.Vector3f(-0.3, 0.4, float(np.sqrt(0.75)))
    wi_in = mi.Vector3f(wi.x / eta, wi.y / eta, dr.sqrt(1 - (wi.x ** 2 + wi.y ** 2) / eta ** 2))
    wo_in = mi.Vector3f(wo.x / eta, wo.y / eta, dr.sqrt(1 - (wo.x ** 2 + wo.y ** 2) / eta ** 2))
    got = _mueller(b.eval(mi.BSDFContext(), _pol_interaction(wi, 1), wo))
    bs, leave = d.sample(ctx, _pol_interaction(wi, 1), 0.5, mi.Point2f(0.5, 0.5))
    np.testing.assert_allclose(np.array(bs.wo)[:, 0], -np.array(wi_in)[:, 0], atol=1e-6)
    bs, enter = d.sample(ctx, _pol_interaction(-wo_in, 1), 0.5, mi.Point2f(0.5, 0.5))
    np.testing.assert_allclose(np.array(bs.wo)[:, 0], np.array(wo)[:, 0], atol=1e-6)
    middle = base.eval(mi.BSDFContext(), _pol_interaction(wi_in, 1), wo_in)
    # the dielectric's radiance factors: (1/η)² entering, η² leaving; they cancel
    want = _mueller(leave * middle * enter) / eta ** 2 * float(wo.z[0]) / float(wo_in.z[0])
    np.testing.assert_allclose(got, want, atol=1e-5 * np.abs(want).max())
    assert np.abs(want[0, 1]).max() > 1e-3 * np.abs(want[0, 0]).max()   # it does polarize


def test_polarized_delta_chain_is_the_chain_of_the_plugins_matrices(polarized):
    """Polarized, over a smooth ``conductor``: the delta lobe (component 0) is
    ``thinfilm_dielectric``'s reflection plus the all-delta chain ``leave · B · (I -
    U B)^-1 · enter``, each factor a Mueller matrix of a plugin in its own frames:
    ``thinfilm_dielectric``'s transmission out and in (their radiance factors η² and
    1/η² cancel), its reflection from inside (``U``) and the conductor's (``B``), the
    round trips summed by the matrix inverse (computed here in float64 by numpy). At
    normal incidence ``M00`` is the spectral variant's scalar chain (no frame rotates).
    Exact amplitudes (``tabulate`` false); float32: 1e-5 of the largest entry."""
    eta = 1.5
    props = {"type": "thinfilm_coating", "layers": FILMS, "int_ior": eta, "ext_ior": 1.0,
             "bsdf": PURE_DELTA["conductor"], "tabulate": False}
    b = mi.load_dict(props)
    d = mi.load_dict({"type": "thinfilm_dielectric", "layers": FILMS, "int_ior": eta,
                      "ext_ior": 1.0, "tabulate": False})
    base = mi.load_dict(PURE_DELTA["conductor"])
    reflect, through = mi.BSDFContext(), mi.BSDFContext()
    reflect.component, through.component = 0, 1

    def sample(bsdf, ctx, w):
        return bsdf.sample(ctx, _pol_interaction(w, 1), 0.5, mi.Point2f(0.5, 0.5))

    def m(x):
        return _mueller(x)[..., 0].transpose(2, 0, 1)   # (wavelength, row, column)

    for cos in (1.0, 0.6):
        wi = mi.Vector3f(float(np.sqrt(1 - cos * cos) * 0.8), float(np.sqrt(1 - cos * cos) * 0.6),
                         cos)
        wi_in = mi.Vector3f(wi.x / eta, wi.y / eta, dr.sqrt(1 - (wi.x ** 2 + wi.y ** 2) / eta ** 2))
        wo_in = mi.Vector3f(-wi_in.x, -wi_in.y, wi_in.z)
        wo = mi.reflect(wi)
        bs, got = sample(b, reflect, wi)
        assert int(np.array(bs.sampled_type)[0]) == int(mi.BSDFFlags.DeltaReflection)
        np.testing.assert_allclose(np.array(bs.wo)[:, 0], np.array(wo)[:, 0], atol=1e-7)
        _, top = sample(d, reflect, wi)
        _, leave = sample(d, through, wi)                 # along wi_in up, out along wi
        _, enter = sample(d, through, -wo_in)             # in along -wo, on along -wo_in
        bs, under = sample(d, reflect, -wo_in)            # up along wi_in, down along -wo_in
        np.testing.assert_allclose(np.array(bs.wo)[:, 0], -np.array(wi_in)[:, 0], atol=1e-6)
        bs, mirror = sample(base, mi.BSDFContext(), wi_in)  # down along -wo_in, up along wi_in
        np.testing.assert_allclose(np.array(bs.wo)[:, 0], np.array(wo_in)[:, 0], atol=1e-6)
        B, U = m(mirror), m(under)
        D = np.linalg.inv(np.eye(4) - U @ B)
        want = m(top) + m(leave) @ B @ D @ m(enter)
        np.testing.assert_allclose(m(got), want, atol=1e-5 * np.abs(want).max())
        if cos == 1.0:
            scalar = want[:, 0, 0]
    assert np.abs(want[:, 0, 1]).max() > 1e-3 * np.abs(want[:, 0, 0]).max()  # it polarizes
    mi.set_variant("llvm_ad_spectral")
    _, w = mi.load_dict(props).sample(reflect, interaction(mi.Vector3f(0, 0, 1), 1), 0.5,
                                      mi.Point2f(0.5, 0.5))
    np.testing.assert_allclose(np.array(w, np.float64)[:, 0], scalar, rtol=1e-5)


#: a Lambertian base the closed form does not know (a blend of two ``diffuse``): the walk
WALKED_DIFFUSE = {"type": "blendbsdf", "weight": 0.5, "bsdf_0": BASES["diffuse"],
                  "bsdf_1": BASES["diffuse"]}


@pytest.mark.parametrize("base", [BASES["diffuse"], WALKED_DIFFUSE], ids=["closed", "walk"])
def test_polarized_intensity_over_a_depolarizing_base_is_the_unpolarized_walk(polarized, base):
    """Over a Lambertian base (a depolarizer at every vertex) the ``M00`` of the closed
    form (``diffuse``) and of the walk (a blend of two) is the unpolarised value for the
    same seeds: ``eval`` and ``sample`` of the polarized variant against
    ``llvm_ad_spectral``. Exact amplitudes against the unpolarised recursion
    (``tabulate`` false): float32, 1e-5 of the largest value, except lanes whose Russian
    roulette falls within that rounding of its threshold (none in these 1024)."""
    props = {"type": "thinfilm_coating", "layers": FILMS, "bsdf": base, "tabulate": False}
    rng = np.random.default_rng(12)
    n = 1024
    dirs = [np.array(directions(rng, n)) for _ in range(2)]
    s1 = rng.random(n, dtype=np.float32)
    s2 = rng.random((2, n), dtype=np.float32)

    def run(make_si):
        b = mi.load_dict(props)
        si = make_si(mi.Vector3f(dirs[0]), n)
        ev = b.eval(mi.BSDFContext(), si, mi.Vector3f(dirs[1]))
        _, w = b.sample(mi.BSDFContext(), si, mi.Float(s1), mi.Point2f(s2[0], s2[1]))
        return ev, w
    ev, w = run(_pol_interaction)
    pol = [_mueller(ev)[0, 0], _mueller(w)[0, 0]]
    mi.set_variant("llvm_ad_spectral")
    ref = [np.array(x, np.float64) for x in run(interaction)]
    for a, b in zip(pol, ref):
        np.testing.assert_allclose(a, b, atol=1e-5 * np.abs(b).max())


@pytest.mark.parametrize("base", list(BASES) + list(PURE_DELTA))
def test_polarized_outputs_are_physical(polarized, base):
    """Stokes vectors of degree of polarization <= 1 stay physical through ``eval`` and
    ``sample`` over every base (products of Jones-Mueller matrices, depolarizers and the
    base's; over a delta base the inverse ``(I - M)^-1`` of its round trips): S0 >= 0 and
    |S1..3| <= S0 (1e-5 relative, float32)."""
    b = coating(base, layers=FILMS)
    rng = np.random.default_rng(13)
    n = 512
    si = _pol_interaction(directions(rng, n), n)
    ev = b.eval(mi.BSDFContext(), si, directions(rng, n))
    _, w = b.sample(mi.BSDFContext(), si, mi.Float(rng.random(n, dtype=np.float32)),
                    mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32)))
    stokes = rng.normal(size=(3, n))
    stokes *= rng.uniform(0, 1, n) / np.linalg.norm(stokes, axis=0)
    s_in = np.concatenate([np.ones((1, n)), stokes])
    for M in (_mueller(ev), _mueller(w)):
        out = np.einsum("ijwn,jn->iwn", M, s_in)
        assert np.all(np.isfinite(out)) and out[0].min() >= -1e-6
        assert np.all(np.linalg.norm(out[1:], axis=0) <= out[0] * (1 + 1e-5) + 1e-6)


@pytest.mark.parametrize("base", ["principled", "conductor"])
def test_polarized_render(polarized, base):
    """A render (the walk recorded inside Mitsuba's symbolic call) over ``principled``:
    the walk's Mueller state, if started from literals, fills in one entry per product and
    Dr.Jit refuses to record the loop ("presumed to be constant, but it changed"); over a
    smooth ``conductor`` (the delta chain's inverse Mueller matrix in the kernel). The
    image is finite and positive (a white constant light on a red paint, on gold)."""
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 6, "height": 6}},
        "light": {"type": "constant"},
        "obj": {"type": "sphere", "bsdf": {"type": "thinfilm_coating", "layers": FILMS,
                                           "bsdf": {**BASES, **PURE_DELTA}[base]}}})
    img = np.array(mi.render(scene, spp=2))
    assert np.all(np.isfinite(img)) and img[..., :3].mean() > 0.05


@pytest.mark.parametrize("base,key,h", [
    ({"type": "conductor", "eta": 2.0, "k": 3.0}, "layers.0.thickness", 1.0),
    ({"type": "conductor", "eta": 2.0, "k": 3.0}, "bsdf.eta.value", 0.004),
    (BASES["diffuse"], "bsdf.reflectance.value", 0.004),
], ids=["delta-thickness", "delta-eta", "closed-albedo"])
def test_polarized_gradients_where_no_walk_runs(polarized, base, key, h):
    """Polarized gradients (every Mueller entry, forward mode) against central differences
    lane by lane, where no walk runs: the delta lobe over a smooth ``conductor`` (its
    closed-form chain, the inverse of ``I - U B``) in a film's thickness and the conductor's
    ``eta``, and ``eval`` over ``diffuse`` (the closed form) in its albedo; h and the
    tolerance as in the unpolarised test (1e-3 of the largest entry)."""
    b = mi.load_dict({"type": "thinfilm_coating", "layers": "2.3 120; 1.46 200", "int_ior": 1.5,
                      "bsdf": base, "tabulate": False})
    ctx = mi.BSDFContext()
    ctx.component = 0 if base["type"] == "conductor" else 1
    params = mi.traverse(b)
    x0 = float(np.array(params[key]).ravel()[0])
    rng = np.random.default_rng(3)
    n = 256
    si, wo = _pol_interaction(directions(rng, n), n), directions(rng, n)

    def value():
        if ctx.component == 0:
            return b.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5))[1]
        return b.eval(ctx, si, wo)

    def at(x):
        params[key] = type(params[key])(x)
        params.update()
        return _mueller(value())

    fd = (at(x0 + h) - at(x0 - h)) / (2 * h)
    params[key] = type(params[key])(x0)
    theta = params[key]
    dr.enable_grad(theta)
    params.update()
    out = value()
    dr.set_grad(theta, 1.0)
    grad = np.array(dr.forward_to(out), np.float64)
    np.testing.assert_allclose(grad, fd, rtol=1e-3, atol=1e-3 * np.abs(fd).max())


def test_polarized_gradients_over_a_walked_base_are_refused(polarized):
    """The walk's replay has no Mueller form: a gradient over a walked base is refused,
    naming the base."""
    walked = mi.load_dict({"type": "thinfilm_coating", "layers": FILMS,
                           "bsdf": BASES["roughconductor"]})
    params = mi.traverse(walked)
    dr.enable_grad(params["layers.0.thickness"])
    params.update()
    with pytest.raises(ThinFilmError, match="RoughConductor"):
        walked.eval(mi.BSDFContext(), _pol_interaction(mi.Vector3f(0, 0, 1), 1),
                    mi.Vector3f(0, 0, 1))


def test_scalar_variant_single_bounce_equals_the_vector_variant():
    """scalar_spectral runs the same code (a Python loop): one bounce is deterministic,
    so its eval equals the LLVM variant's to float32 rounding (1e-6 relative). Both evaluate
    the stack exactly (scalar variants build no tables; the LLVM variant might, as ``auto``
    decides)."""
    props = {"type": "thinfilm_coating", "layers": FILMS, "bsdf": BASES["principled"],
             "max_bounces": 1, "coat_sigma_a": 0.1, "tabulate": False}
    wi, wo = [0.3, 0.2, float(np.sqrt(0.87))], [-0.5, 0.1, float(np.sqrt(0.74))]
    vec = np.array(mi.load_dict(props).eval(mi.BSDFContext(), interaction(mi.Vector3f(*wi), 1),
                                            mi.Vector3f(*wo)))[:, 0]
    try:
        mi.set_variant("scalar_spectral")
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wavelengths = mi.Spectrum(WLS)
        si.wi = mi.Vector3f(wi)
        sca = np.array(mi.load_dict(props).eval(mi.BSDFContext(), si, mi.Vector3f(wo)))
    finally:
        mi.set_variant("llvm_ad_spectral")
    np.testing.assert_allclose(sca, vec, rtol=1e-5)


def test_rgb_product_approximation_delta_e():
    """RGB: the stack's integrated ``R`` and ``T`` per channel times the base's RGB, where
    the physical colour integrates the product. Measured on the albedo at 30° of a
    two-film coat over a coloured ``diffuse``: spectral (sample means at 48 wavelengths,
    integrated against the same colour weights) against ``llvm_ad_rgb``; Monte Carlo noise
    of both < 0.1 ΔE2000 (2^19 samples)."""
    props = {"type": "thinfilm_coating", "layers": FILMS, "int_ior": 1.5,
             "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.7, 0.35, 0.15]}}}
    cos = float(np.cos(np.radians(30)))
    wi = mi.Vector3f(float(np.sqrt(1 - cos * cos)), 0.0, cos)
    rng = np.random.default_rng(9)
    wl = np.arange(360.0, 831.0, 10.0)
    per = 1 << 13
    n = per * len(wl)
    lanes = np.repeat(wl, per)
    b = mi.load_dict(props)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wavelengths = mi.Spectrum(*([mi.Float(lanes)] * 4))
    si.wi = wi
    _, w = b.sample(mi.BSDFContext(), si, mi.Float(rng.random(n, dtype=np.float32)),
                    mi.Point2f(rng.random(n, dtype=np.float32), rng.random(n, dtype=np.float32)))
    spectrum = np.array(w, np.float64)[0].reshape(len(wl), per).mean(axis=1)
    grid = np.arange(360.0, 831.0)
    weights = normalised_weights("rgb")
    spectral_rgb = weights @ np.interp(grid, wl, spectrum)
    try:
        mi.set_variant("llvm_ad_rgb")
        b = mi.load_dict(props)
        m = 1 << 19
        si = dr.zeros(mi.SurfaceInteraction3f, m)
        si.wi = mi.Vector3f(wi)
        _, w = b.sample(mi.BSDFContext(), si, mi.Float(rng.random(m, dtype=np.float32)),
                        mi.Point2f(rng.random(m, dtype=np.float32), rng.random(m, dtype=np.float32)))
        rgb = np.array(w, np.float64).mean(axis=1)
    finally:
        mi.set_variant("llvm_ad_spectral")
    de = float(colour_differences(spectral_rgb, rgb, 3)[0])
    print(f"RGB product approximation: spectral {spectral_rgb}, rgb {rgb}, ΔE2000 {de:.3f}")
    assert de < 3.0


# -- the rough top (the estimator's checks: tests/render/layered/test_rough.py) ----------

ROUGH = {"type": "thinfilm_coating", "layers": FILMS, "alpha": 0.2, "distribution": "ggx",
         "bsdf": BASES["roughconductor"]}


@pytest.mark.parametrize("extra,message", [
    ({"alpha": float("nan")}, r"'alpha' must be a finite number >= 0 and <= 100 or a texture, got nan"),
    ({"alpha": -0.1}, r"'alpha' must be a finite number >= 0 and <= 100 or a texture, got -0.1"),
    ({"alpha": float("inf")}, r"'alpha' must be a finite number >= 0 and <= 100 or a texture, got inf"),
    ({"alpha": "rough"}, r"'alpha' must be a number > 0 or a texture, got 'rough'"),
    ({"alpha_u": 0.1}, r"'alpha_v' is missing \('alpha_u' = 0.1"),
    ({"alpha": 0.1, "alpha_u": 0.1, "alpha_v": 0.2}, "give either 'alpha' or 'alpha_u'"),
    ({"distribution": "phong"}, r"'distribution'.*'phong'"),
    ({"alpha": 0.1, "int_ior": 1.000277, "layers": ""}, r"a rough top \(alpha=0.1\) needs 'int_ior'"),
])
def test_bad_roughness_at_load_names_the_parameter(extra, message):
    """The top's roughness and distribution, checked at load (the smooth top's too:
    ``distribution`` is checked where ``alpha`` is 0 or absent)."""
    props = {"type": "thinfilm_coating", "bsdf": BASES["diffuse"], **extra}
    with pytest.raises(Exception, match="thinfilm_coating: " + message):
        mi.load_dict(props)


@pytest.mark.parametrize("value", [float("nan"), -0.2, float("inf"), 0.0])
def test_bad_roughness_edits_are_refused_and_undone(value):
    """A scene edit of ``alpha`` to a value not > 0 (0 would need the smooth top's other
    code) or not finite is refused, naming the key and the value, and undone."""
    import re
    scene = mi.load_dict({"type": "scene", "obj": {"type": "rectangle", "bsdf": ROUGH}})
    params = mi.traverse(scene)
    key = "obj.bsdf.alpha.value"
    params[key] = type(params[key])(value)
    with pytest.raises(ThinFilmError) as err:
        params.update()
    text = str(err.value)
    assert re.match(rf"^thinfilm_coating: 'alpha\.value' \(a roughness\) must be finite and > 0 "
                    rf"and <= 100, got (a texture holding )?{re.escape(f'{value:.7g}')}; the edit "
                    "was undone", text), text
    np.testing.assert_array_equal(np.array(mi.traverse(scene)[key]), np.float32([0.2]))


@pytest.mark.parametrize("variant", ["llvm_ad_rgb", "llvm_ad_mono", "llvm_ad_spectral_polarized"])
def test_rough_top_renders_in_every_variant(variant):
    """A sphere under a constant white environment (8 x 8, 16 spp): finite, positive, and
    a white furnace's bound (a lossless film over a metal). 2-7 s each (compilation)."""
    mi.set_variant(variant)
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 25,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 16}},
        "emitter": {"type": "constant"},
        "ball": {"type": "sphere", "bsdf": {**ROUGH, "layers": "SiO2 200"}}})
    image = np.array(mi.render(scene, seed=1))
    assert np.all(np.isfinite(image)) and image.min() > 0
    # the mean of the 64 pixels (~2/3 on the sphere; a pixel's 16 samples may still hold a
    # rare heavy weight): at most 1 plus its noise
    assert 0.5 < image.mean() < 1.05, image


def test_polarized_gradients_under_a_rough_top_are_refused(polarized):
    """The rough walk's replay has no Mueller form either: refused, saying why."""
    b = mi.load_dict({**ROUGH, "layers": FILMS})
    params = mi.traverse(b)
    dr.enable_grad(params["alpha.value"])
    params.update()
    with pytest.raises(ThinFilmError, match="gradients in polarized variants under a rough top"):
        b.eval(mi.BSDFContext(), _pol_interaction(mi.Vector3f(0, 0, 1), 1), mi.Vector3f(0, 0, 1))
