"""Polarized variants: Mueller matrices from the stack's complex amplitudes.

* the map between our (tmm's) amplitudes and Mitsuba's, on bare interfaces against
  ``mi.mueller.specular_reflection`` / ``specular_transmission``;
* with no films, the plugins' matrices against Mitsuba's ``conductor``,
  ``dielectric`` and ``roughconductor`` at random directions, in both transport modes;
* with films, against matrices built here from tmm's complex amplitudes;
* physical Stokes outputs, S0 of a polarized render against the unpolarized render,
  chi2 of the rough plugins, and a ``scalar_spectral_polarized`` smoke test.

Every test runs in ``llvm_ad_spectral_polarized`` (vectorised); the module fixture
restores the suite's default variant (``llvm_ad_spectral``) afterwards.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins in every variant)
from tests.support.polarized import (  # noqa: F401  (the skip mark, the variant fixture)
    DEFAULT,
    VARIANT,
    directions,
    interaction,
    mat,
    polarized_variant,
    pytestmark,
    rotated,
    tmm_matrix,
    vec,
)

MODES = ["Radiance", "Importance"]
# float32 against float32: the matrices are products of a few float32 operations on
# entries <= 1 (Fresnel terms, 3 rotations by angles from float32 vectors); 2e-5
# covers their rounding (~1e-6) with room for cos(theta) near 0 and TIR.
F32_TOL = 2e-5
# float32 stack recursion against tmm's float64: phase error < 1e-5 rad and power error
# < 1e-5 for <= 3 films <= 500 nm (tests/plugins/test_thinfilm_conductor.py), plus the rotation.
TMM_TOL = 5e-5


def ctx_of(mode: str, component=None):
    ctx = mi.BSDFContext(getattr(mi.TransportMode, mode))
    if component is not None:
        ctx.component = component
    return ctx


def wavelengths(rng, n):
    return rng.uniform(360.0, 830.0, (n, 4))


# ---------------------------------------------------------------------------
# The amplitude map on bare interfaces
# ---------------------------------------------------------------------------
def test_bare_interface_map_matches_mitsuba_fresnel():
    """conj(our r, t) are Mitsuba's amplitudes: our s/p matrices (amplitudes.jones_shape,
    modes.sp_matrix) equal mueller.specular_reflection/transmission for a conductor
    (complex eta) and a dielectric lit from both sides, TIR included."""
    from thinfilm_mi.optics.core import Cx, stack_amplitudes, transmittance_factor_p, transmittance_factor_s
    from thinfilm_mi.optics.unpolarized import unpolarized_powers
    from thinfilm_mi.render.amplitudes import jones_shape
    from thinfilm_mi.render.modes import sp_matrix

    rng = np.random.default_rng(1)
    c = rng.uniform(0.0, 1.0, 512).astype(np.float32)
    U = mi.UnpolarizedSpectrum
    # (our ambient, our exit, Mitsuba's eta, sign of Mitsuba's cos: - = from inside)
    cases = [(1.0, 0.2 + 3.0j, 0.2 + 3.0j, 1.0),   # a gold-like conductor
             (1.0, 1.5, 1.5, 1.0),                  # air -> glass
             (1.5, 1.0, 1.5, -1.0)]                 # glass -> air (TIR beyond 41.8 deg)
    for n0, n_exit, eta, side in cases:
        a = stack_amplitudes(U(n0), U(mi.Float(c)), [], Cx(U(n_exit.real), U(n_exit.imag)),
                             U(500.0))
        R, T = unpolarized_powers(a, True)
        ours = mat(sp_matrix(R, jones_shape(a.rs, a.rp)))[:, 0]
        ref = np.array(mi.mueller.specular_reflection(
            mi.Float(side * c), mi.Complex2f(eta.real, eta.imag))).transpose(2, 0, 1)
        assert np.abs(ours - ref).max() < F32_TOL, (n0, eta)
        if n_exit.imag:
            continue
        q0 = dr.select(a.grazing, 1.0, a.q0)
        t_shape = jones_shape(a.ts, a.tp, transmittance_factor_s(a.q_exit, q0),
                              transmittance_factor_p(a.n_exit, a.q_exit, q0))
        ours_t = mat(sp_matrix(T, t_shape))[:, 0]
        ref_t = np.array(mi.mueller.specular_transmission(
            mi.Float(side * c), mi.Float(eta.real))).transpose(2, 0, 1)
        assert np.abs(ours_t - ref_t).max() < F32_TOL, (n0, eta)


# ---------------------------------------------------------------------------
# No films: Mitsuba's own polarized plugins
# ---------------------------------------------------------------------------
N = 512


def lanes(x) -> np.ndarray:
    return np.broadcast_to(np.array(x), (N,))


def _compare_samples(ours, ref, si, ctx, rng, u=None, skip=None):
    """sample() of both plugins at the same inputs (sample1 ``u`` or random)."""
    u = rng.uniform(0, 1, N) if u is None else u
    s1 = mi.Float(u.astype(np.float32))
    s2 = mi.Point2f(*(mi.Float(rng.uniform(0, 1, N).astype(np.float32)) for _ in range(2)))
    bs_a, a = ours.sample(ctx, si, s1, s2)
    bs_b, b = ref.sample(ctx, si, s1, s2)
    keep = np.ones(N, bool) if skip is None else ~skip
    A, B = mat(a)[keep], mat(b)[keep]
    valid = np.any(B != 0, axis=(1, 2, 3))   # invalid samples may keep any direction
    assert valid.mean() > 0.5
    assert np.array_equal(lanes(bs_a.sampled_type)[keep][valid],
                          lanes(bs_b.sampled_type)[keep][valid])
    assert np.abs(np.array(bs_a.wo)[:, keep] - np.array(bs_b.wo)[:, keep])[:, valid].max() \
        < F32_TOL
    assert np.abs(A - B).max() < F32_TOL * max(1.0, np.abs(B).max())
    assert np.abs(B[:, :, 2:, 2:]).max() > 0.1   # the phase terms are really compared


@pytest.mark.parametrize("mode", MODES)
def test_no_films_conductor_equals_mitsuba(mode):
    rng = np.random.default_rng(2)
    si = interaction(directions(rng, N), wavelengths(rng, N))
    ours = mi.load_dict({"type": "thinfilm_conductor", "eta": 0.2, "k": 3.0, "ext_ior": 1.0})
    ref = mi.load_dict({"type": "conductor", "eta": 0.2, "k": 3.0})
    _compare_samples(ours, ref, si, ctx_of(mode), rng)


@pytest.mark.parametrize("mode", MODES)
def test_no_films_dielectric_equals_mitsuba(mode):
    """Both lobes, lit from both sides (TIR from inside beyond 41.8 deg), and each
    component alone. Skipped lanes: sample1 within rounding of the Fresnel
    reflectance (the lobe choice may flip), and grazing incidence from outside
    (cos < 0.02), where Mitsuba evaluates the transmission in Radiance mode at the
    refracted cosine, within float32 rounding of the critical angle from inside,
    where T has an infinite slope (there the two differ by up to 5e-5 while both
    are float32 roundings of the same T: we evaluate from the incident side)."""
    rng = np.random.default_rng(3)
    wi = directions(rng, N, 0.0, np.pi)
    si = interaction(wi, wavelengths(rng, N))
    ours = mi.load_dict({"type": "thinfilm_dielectric", "int_ior": 1.5, "ext_ior": 1.0})
    ref = mi.load_dict({"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0})
    F = np.array(mi.fresnel(mi.Float(wi[:, 2].astype(np.float32)), mi.Float(1.5))[0])
    u = rng.uniform(0, 1, N)
    grazing = np.abs(wi[:, 2]) < 0.02
    _compare_samples(ours, ref, si, ctx_of(mode), rng, u, skip=grazing | (np.abs(u - F) < 1e-4))
    for component in (0, 1):
        _compare_samples(ours, ref, si, ctx_of(mode, component), rng, skip=grazing)


@pytest.mark.parametrize("mode", MODES)
def test_no_films_roughconductor_equals_mitsuba(mode):
    rng = np.random.default_rng(4)
    wi, wo = directions(rng, N), directions(rng, N)
    si = interaction(wi, wavelengths(rng, N))
    props = {"eta": 0.2, "k": 3.0, "distribution": "ggx", "alpha_u": 0.3, "alpha_v": 0.15}
    ours = mi.load_dict({"type": "thinfilm_roughconductor", "ext_ior": 1.0, **props})
    ref = mi.load_dict({"type": "roughconductor", **props})
    ctx = ctx_of(mode)
    _compare_samples(ours, ref, si, ctx, rng)
    A, B = mat(ours.eval(ctx, si, vec(wo))), mat(ref.eval(ctx, si, vec(wo)))
    assert np.abs(A - B).max() < F32_TOL * max(1.0, np.abs(B).max())
    assert np.abs(B[:, :, 2:, 2:]).max() > 0.1


# ---------------------------------------------------------------------------
# Films: matrices built here from tmm's complex amplitudes
# ---------------------------------------------------------------------------
NT = 48   # lanes (x 4 wavelengths x 2 polarisations tmm calls each)
FILMS_C = [(1.46, 300.0), (2.3, 60.0)]             # on a conductor 0.2 + 3i
FILMS_D = [(1.46, 300.0), (0.42 + 2.47j, 10.0)]    # on glass 1.5: absorbing, sides differ


def layers(films):
    return "; ".join(f"{complex(n).real}{complex(n).imag:+}j {d}" for n, d in films)


def _films_case(bsdf, films, n_sub, wi, wls, mode, component):
    """Our sample() against tmm for the delta lobe ``component`` (0: R, 1: T)."""
    si = interaction(wi, wls)
    bs, w = bsdf.sample(ctx_of(mode, component), si, mi.Float(0.5), mi.Point2f(0.5, 0.5))
    ours = mat(w)
    wo = np.array(bs.wo).T.astype(np.float64)
    radiance = mode == "Radiance"
    wo_hat, wi_hat = (wo, wi) if radiance else (wi, wo)
    ref = np.zeros((len(wi), 4, 4, 4))
    for i in range(len(wi)):
        c = wo_hat[i, 2]             # light arrives along -wo_hat, from its side
        outside = c > 0
        n_list = [1.0, *[n for n, _ in films], n_sub]
        d_list = [np.inf, *[d for _, d in films], np.inf]
        if not outside:
            n_list, d_list = n_list[::-1], d_list[::-1]
        for k in range(4):
            ref[i, k] = tmm_matrix(n_list, d_list, abs(c), wls[i, k], component == 1)
        if component == 1 and radiance:   # (eta_i / eta_t)^2 with i the side of wi
            ref[i] *= (1.0 / n_sub if wi[i, 2] > 0 else n_sub) ** 2
    ref = rotated(ref, wo_hat, wi_hat)
    valid = np.abs(ref[:, :, 0, 0]).max(axis=1) > 0
    assert valid.mean() > 0.3
    assert np.abs(ours - ref)[valid].max() < TMM_TOL
    assert np.abs(ours[~valid]).max(initial=0.0) == 0.0
    assert np.abs(ref[valid][:, :, 2:, 2:]).max() > 0.1


@pytest.mark.parametrize("mode", MODES)
def test_films_conductor_matches_tmm(mode):
    rng = np.random.default_rng(5)
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers(FILMS_C),
                         "eta": 0.2, "k": 3.0, "ext_ior": 1.0})
    _films_case(bsdf, FILMS_C, 0.2 + 3.0j, directions(rng, NT), wavelengths(rng, NT), mode, 0)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("component", [0, 1])
def test_films_dielectric_matches_tmm(mode, component):
    """R and T from both sides (TIR from inside, T = 0 there); grazing lanes skipped
    as in the no-film test."""
    rng = np.random.default_rng(6 + component)
    wi = directions(rng, 2 * NT, 0.0, np.pi)
    wi = wi[np.abs(wi[:, 2]) > 0.02][:NT]
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers(FILMS_D),
                         "int_ior": 1.5, "ext_ior": 1.0})
    _films_case(bsdf, FILMS_D, 1.5, wi, wavelengths(rng, len(wi)), mode, component)


# ---------------------------------------------------------------------------
# Physical outputs, S0 against the unpolarized render, chi2, scalar variant
# ---------------------------------------------------------------------------
PLUGINS = [
    {"type": "thinfilm_conductor", "layers": layers(FILMS_C), "eta": 0.2, "k": 3.0},
    {"type": "thinfilm_dielectric", "layers": layers(FILMS_D), "int_ior": 1.5},
    {"type": "thinfilm_diffuse", "layers": "1.46 500; 0.42+2.47j 5", "reflectance": 0.8},
    {"type": "thinfilm_roughconductor", "layers": layers(FILMS_C), "eta": 0.2, "k": 3.0,
     "alpha": 0.3},
    {"type": "thinfilm_roughdielectric", "layers": layers(FILMS_D), "int_ior": 1.5,
     "alpha": 0.3},
]


@pytest.mark.parametrize("props", PLUGINS, ids=[p["type"] for p in PLUGINS])
@pytest.mark.parametrize("mode", MODES)
def test_outputs_are_physical_stokes_vectors(props, mode):
    """Random Stokes inputs with degree of polarization <= 1 stay physical: S0 >= 0 and
    |(S1, S2, S3)| <= S0. Our matrices are weights times Jones-Mueller matrices (which
    keep a fully polarized beam fully polarized) or depolarizers, so the bound is tight:
    1e-5 relative covers float32 rounding of the 4x4 products."""
    rng = np.random.default_rng(8)
    bsdf = mi.load_dict(props)
    lo_hi = (0.0, np.pi) if "dielectric" in props["type"] else (0.0, np.pi / 2)
    si = interaction(directions(rng, N, *lo_hi), wavelengths(rng, N))
    ctx = ctx_of(mode)
    s1 = mi.Float(rng.uniform(0, 1, N).astype(np.float32))
    s2 = mi.Point2f(*(mi.Float(rng.uniform(0, 1, N).astype(np.float32)) for _ in range(2)))
    outs = [mat(bsdf.sample(ctx, si, s1, s2)[1])]
    if "rough" in props["type"] or "diffuse" in props["type"]:
        outs.append(mat(bsdf.eval(ctx, si, vec(directions(rng, N, *lo_hi)))))
    stokes = rng.normal(size=(N, 3))
    stokes *= (rng.uniform(0, 1, N) / np.linalg.norm(stokes, axis=1))[:, None]
    S_in = np.concatenate([np.ones((N, 1)), stokes], axis=1)
    for k, M in enumerate(outs):
        S = np.einsum("nwij,nj->nwi", M.astype(np.float64), S_in)
        assert np.all(np.isfinite(S))
        assert S[..., 0].min() >= -1e-6
        dop = np.linalg.norm(S[..., 1:], axis=-1)
        assert np.all(dop <= S[..., 0] * (1 + 1e-5) + 1e-6)
        # something is polarized (the diffuse plugin's eval is its depolarizing lobe)
        polarizing = k == 0 or "diffuse" not in props["type"]
        assert (np.abs(S[..., 1:]).max() > 0.01) == polarizing


def _s0_scene(variant: str, spp: int = 4):
    """All five plugins as spheres under a constant sky, one bounce (max_depth 2): every
    path meets one thin-film BSDF and then the emitter, so the intensity of the
    polarized render must equal the unpolarized render (after two polarizing events S0
    differs physically). One film each and ``tabulate`` false: both variants evaluate
    the same exact recursion."""
    mi.set_variant(variant)
    objs = {}
    for i, p in enumerate(PLUGINS):
        p = dict(p, layers="1.46 400" if "diffuse" not in p["type"] else "1.46 400; 0.42+2.47j 5",
                 tabulate=False)
        objs[f"s{i}"] = {"type": "sphere", "center": [2.2 * (i - 2), 0, 0], "radius": 1.0,
                         "bsdf": p}
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 50,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 4, 12], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 96, "height": 24,
                            "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "sky": {"type": "envmap", "bitmap": mi.Bitmap(_sky())},
        **objs})
    return np.array(mi.render(scene, seed=7))


def _sky():
    """A sky that varies with direction (so polarizing reflections see structure)."""
    h, w = 16, 32
    v = np.linspace(0, 1, h)[:, None, None]
    u = np.linspace(0, 1, w)[None, :, None]
    return (0.2 + np.concatenate([v + 0 * u, 0.5 * u + 0 * v, (1 - v) * u], axis=2)) \
        .astype(np.float32)


def test_s0_of_polarized_render_equals_unpolarized_render():
    """Same scene, same seed: the same wavelengths, directions and lobe choices in both
    variants (lobe probabilities use the same unpolarized R and T). Pixels agree to
    float32 rounding of the two evaluations (exact amplitudes against the unrolled or
    real-loop recursion, ~1e-6 relative), except where a lobe choice falls within that
    rounding of its threshold: 1e-5 on the mean absolute difference relative to the
    mean and 99 % of the pixels within 1e-4 relative."""
    try:
        ref = _s0_scene(DEFAULT)
        pol = _s0_scene(VARIANT)
    finally:
        mi.set_variant(VARIANT)
    assert ref.shape == pol.shape
    assert ref.mean() > 0.05
    diff = np.abs(pol - ref)
    assert diff.mean() / ref.mean() < 1e-5
    assert np.mean(diff <= 1e-4 * np.maximum(ref, 1e-2)) > 0.99


@pytest.mark.parametrize("props,theta", [(PLUGINS[3], 40.0), (PLUGINS[4], 130.0)],
                         ids=["roughconductor", "roughdielectric"])


def test_chi2_rough_plugins(props, theta):
    """sample() draws what pdf() says in the polarized variant too (the lobe choice of
    the rough dielectric uses the unpolarized R and T of the exact amplitudes; from
    inside at 130 deg, mostly beyond the critical angle). A 24 x 48 grid integrated on
    16 x 16 points per cell: at 16 x 32 / 8 x 8 the pdf integration is too coarse for
    the narrow refracted lobe (rejected in both variants). The
    sample and pdf functions are those of mitsuba.chi2.BSDFAdapter, with wavelengths
    set (the adapter leaves them at 0 nm, where no film is defined)."""
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    bsdf = mi.load_dict(props)
    t = np.radians(theta)
    wi = np.array([[np.sin(t) * np.cos(0.3), np.sin(t) * np.sin(0.3), np.cos(t)]])
    ctx = mi.BSDFContext()

    def si_of(n):
        return interaction(np.repeat(wi, n, axis=0), np.tile([450.0, 520.0, 610.0, 700.0], (n, 1)))

    def sample_func(sample):
        n = dr.width(sample)
        bs, w = bsdf.sample(ctx, si_of(n), sample[0], mi.Point2f(sample[1], sample[2]))
        nonzero = np.any(mat(w) != 0, axis=(1, 2, 3))
        return bs.wo, mi.Float(nonzero.astype(np.float32))

    def pdf_func(wo):
        return bsdf.pdf(ctx, si_of(dr.width(wo)), wo)

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func,
                         sample_dim=3, sample_count=100_000, res=24, ires=16)
    assert test.run(0.01), test.messages
    assert float(test.histogram_sum[0]) > 0.2


def test_scalar_spectral_polarized_smoke():
    """scalar_spectral_polarized (Python per sample): a coated conductor and a coated
    glass return the matrices of the vectorised variant at one direction."""
    wi = np.array([[0.4, 0.2, np.sqrt(1 - 0.2)]])
    wls = np.array([[450.0, 520.0, 610.0, 700.0]])
    props = [PLUGINS[0], PLUGINS[1]]
    vector = [mat(mi.load_dict(p).sample(ctx_of("Radiance"), interaction(wi, wls),
                                         mi.Float(0.3), mi.Point2f(0.5, 0.5))[1])[0]
              for p in props]
    try:
        mi.set_variant("scalar_spectral_polarized")
        for p, ref in zip(props, vector):
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = mi.Vector3f(*wi[0])
            si.wavelengths = mi.UnpolarizedSpectrum(*wls[0])
            si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
            _, w = mi.load_dict(p).sample(mi.BSDFContext(), si, 0.3, mi.Point2f(0.5, 0.5))
            ours = np.array(w).transpose(2, 0, 1)
            assert np.abs(ours - ref).max() < F32_TOL
            assert np.abs(ours[:, 2:, 2:]).max() > 0.1
    finally:
        mi.set_variant(VARIANT)


# ---------------------------------------------------------------------------
# Gradients of the Mueller matrices (issue 39)
# ---------------------------------------------------------------------------
#: the swept film (film 0 of each plugin's stack) and the central-difference step
GRAD_KEY, GRAD_H = "layers.0.thickness", 0.2


def _first_row(bsdf, si, ctx, wo, s1):
    """The first row of the Mueller weight, without the detached lobe selection: eval
    (rough and diffuse plugins, at ``wo``) or sample's weight times its pdf (the smooth
    plugins: pdf is the probability of the chosen lobe, a sampling decision)."""
    if wo is None:
        bs, w = bsdf.sample(ctx, si, s1, mi.Point2f(0.5, 0.5))
        scale = dr.detach(bs.pdf)
    else:
        w, scale = bsdf.eval(ctx, si, wo), 1.0
    return [w[0][j] * scale for j in range(4)]


@pytest.mark.parametrize("props", PLUGINS, ids=[p["type"] for p in PLUGINS])
def test_thickness_gradient_of_the_mueller_first_row_matches_finite_differences(props):
    """Forward-mode AD of M00..M03 with respect to film 0's thickness, per wavelength,
    against central differences of the same plugin's matrices after thickness edits
    (exact mode: an edit rebuilds no table). Step 0.2 nm: the phase moves by ~4e-3 rad,
    truncation ~1e-5 of the gradient, float32 rounding of the matrices (~1e-7 of entries
    <= 1) over 2h ~1e-4 of it; 2e-3 of the largest |gradient| bounds both with room."""
    rng = np.random.default_rng(39)
    n = 16
    bsdf = mi.load_dict({**props, "tabulate": "false"})
    params = mi.traverse(bsdf)
    d0 = float(params[GRAD_KEY][0])
    wi = directions(rng, n, 0.1, 1.3)
    si = interaction(wi, wavelengths(rng, n))
    ctx = ctx_of("Radiance")
    kind = props["type"]
    # (wo for eval, or s1 for sample; whether the matrix polarizes): the smooth plugins'
    # lobes by sample (s1 1e-3 picks reflection where R > 1e-3, 0.999 the transmission or
    # the diffuse lobe), the rough ones by eval near the mirror and the refracted direction
    near_mirror = directions(rng, n, 0.1, 1.3)
    refracted = -wi * np.array([1 / 1.5, 1 / 1.5, 1.0])
    refracted /= np.linalg.norm(refracted, axis=1)[:, None]
    cases = {
        "thinfilm_conductor": [(None, mi.Float(1e-3), True)],
        "thinfilm_dielectric": [(None, mi.Float(1e-3), True), (None, mi.Float(0.999), True)],
        # the coating's specular lobe polarizes; the diffuse lobe is a depolarizer (M00 only)
        "thinfilm_diffuse": [(None, mi.Float(1e-3), True), (vec(near_mirror), None, False)],
        "thinfilm_roughconductor": [(vec(near_mirror), None, True)],
        "thinfilm_roughdielectric": [(vec(near_mirror), None, True), (vec(refracted), None, True)],
    }[kind]
    for wo, s1, polarizes in cases:
        x = params[GRAD_KEY]
        dr.enable_grad(x)
        params.update()
        x = params[GRAD_KEY]
        dr.set_grad(x, 1.0)
        row = _first_row(bsdf, si, ctx, wo, s1)
        dr.forward_to(*row)
        grad = np.array([np.array(dr.grad(r), dtype=np.float64) for r in row])
        dr.disable_grad(x)
        values = []
        for d in (d0 + GRAD_H, d0 - GRAD_H):
            params[GRAD_KEY] = d
            params.update()
            values.append(np.array([np.array(r, dtype=np.float64) for r in _first_row(bsdf, si, ctx, wo, s1)]))
        params[GRAD_KEY] = d0
        params.update()
        ref = (values[0] - values[1]) / (2 * GRAD_H)
        scale = np.abs(ref).max()
        assert scale > 1e-3, "the case does not depend on the thickness"
        if polarizes:   # the polarizing entries move too, not only M00
            assert np.abs(ref[1:]).max() > 1e-2 * scale
        np.testing.assert_allclose(grad, ref, atol=2e-3 * scale, rtol=0)
