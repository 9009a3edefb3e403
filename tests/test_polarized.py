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

import numpy as np
import pytest
import tmm

import drjit as dr
import mitsuba as mi

import thinfilm_mi  # noqa: F401  (registers the plugins in every variant)

VARIANT = "llvm_ad_spectral_polarized"
DEFAULT = "llvm_ad_spectral"
MODES = ["Radiance", "Importance"]
# float32 against float32: the matrices are products of a few float32 operations on
# entries <= 1 (Fresnel terms, 3 rotations by angles from float32 vectors); 2e-5
# covers their rounding (~1e-6) with room for cos(theta) near 0 and TIR.
F32_TOL = 2e-5
# float32 stack recursion against tmm's float64: phase error < 1e-5 rad and power error
# < 1e-5 for <= 3 films <= 500 nm (tests/test_bsdf_specular.py), plus the rotation.
TMM_TOL = 5e-5

pytestmark = pytest.mark.skipif(VARIANT not in mi.variants(), reason="no polarized variant")


@pytest.fixture(scope="module", autouse=True)
def polarized_variant():
    mi.set_variant(VARIANT)
    yield
    mi.set_variant(DEFAULT)


def ctx_of(mode: str, component=None):
    ctx = mi.BSDFContext(getattr(mi.TransportMode, mode))
    if component is not None:
        ctx.component = component
    return ctx


def directions(rng, n, lo=0.0, hi=np.pi / 2):
    """Random unit vectors with polar angle in [lo, hi) and a random azimuth (numpy)."""
    th, ph = rng.uniform(lo, hi, n), rng.uniform(0.0, 2 * np.pi, n)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=1)


def vec(a):
    return mi.Vector3f(*(mi.Float(a[:, i].astype(np.float32)) for i in range(3)))


def interaction(wi, wls):
    """A SurfaceInteraction3f at the origin with wi (numpy n x 3) and wavelengths (n x 4)."""
    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = vec(wi)
    si.wavelengths = mi.UnpolarizedSpectrum(*(mi.Float(wls[:, c].astype(np.float32))
                                              for c in range(4)))
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    return si


def mat(m) -> np.ndarray:
    """A Mueller matrix of spectra as numpy (lane, wavelength, 4, 4)."""
    return np.array(m).transpose(3, 2, 0, 1)


def wavelengths(rng, n):
    return rng.uniform(360.0, 830.0, (n, 4))


# ---------------------------------------------------------------------------
# The amplitude map on bare interfaces
# ---------------------------------------------------------------------------
def test_bare_interface_map_matches_mitsuba_fresnel():
    """conj(our r, t) are Mitsuba's amplitudes: our s/p matrices (amplitudes.jones_shape,
    modes.sp_matrix) equal mueller.specular_reflection/transmission for a conductor
    (complex eta) and a dielectric lit from both sides, TIR included."""
    from thinfilm_mi.amplitudes import jones_shape
    from thinfilm_mi.kernel import unpolarised_powers
    from thinfilm_mi.modes import sp_matrix
    from thinfilm_mi.optics import (Cx, stack_amplitudes, transmittance_factor_p,
                                    transmittance_factor_s)

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
        R, T = unpolarised_powers(a, True)
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
