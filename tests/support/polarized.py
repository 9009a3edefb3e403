"""The polarized variant the Mueller-matrix tests run in, and their helpers: directions,
interactions, Mueller matrices as numpy, the s/p matrix from tmm, Mitsuba's rotation of
Stokes bases.

A test module imports ``pytestmark`` (the skip when no polarized variant is compiled)
and the autouse module fixture ``polarized_variant`` (which restores the suite's default
variant, ``llvm_ad_spectral``, afterwards).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tmm

VARIANT = "llvm_ad_spectral_polarized"


DEFAULT = "llvm_ad_spectral"


pytestmark = pytest.mark.skipif(VARIANT not in mi.variants(), reason="no polarized variant")


@pytest.fixture(scope="module", autouse=True)
def polarized_variant():
    mi.set_variant(VARIANT)
    yield
    mi.set_variant(DEFAULT)


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


def tmm_matrix(n_list, d_list, cos, lam, transmission):
    """The s/p Mueller matrix from tmm (float64): amplitudes conjugated into Mitsuba's
    convention, A = conj(a), and the Mueller matrix of ``mueller.specular_reflection``:
    c cos(delta) = Re(A_p conj(A_s)), c sin(delta) = Im(A_p conj(A_s)). For
    transmission the powers are tmm's T (power entering the exit medium)."""
    th = np.arccos(np.clip(cos, 0.0, 1.0))
    out = {}
    for pol in "sp":
        out[pol] = tmm.coh_tmm(pol, n_list, d_list, th, lam)
    if transmission:
        a, P = "t", "T"
    else:
        a, P = "r", "R"
    Ps, Pp = out["s"][P], out["p"][P]
    As, Ap = np.conj(out["s"][a]), np.conj(out["p"][a])
    z = Ap * np.conj(As)
    C = np.sqrt(Ps * Pp) * (z / abs(z) if abs(z) > 0 else 0.0)
    return np.array([[(Ps + Pp) / 2, (Ps - Pp) / 2, 0, 0],
                     [(Ps - Pp) / 2, (Ps + Pp) / 2, 0, 0],
                     [0, 0, C.real, -C.imag],
                     [0, 0, C.imag, C.real]])


def rotated(M, wo_hat, wi_hat):
    """``M`` (lane, wavelength, 4, 4) rotated as Mitsuba's smooth plugins rotate:
    s axes n x (-wo_hat) and n x wi_hat into the Stokes bases of -wo_hat and wi_hat."""
    n = np.array([0.0, 0.0, 1.0])
    s_in, s_out = np.cross(n, -wo_hat), np.cross(n, wi_hat)
    s_in /= np.linalg.norm(s_in, axis=1, keepdims=True)
    s_out /= np.linalg.norm(s_out, axis=1, keepdims=True)
    U = mi.UnpolarizedSpectrum
    m = mi.Spectrum([[U(*(mi.Float(M[:, w, i, j].astype(np.float32)) for w in range(4)))
                      for j in range(4)] for i in range(4)])
    return mat(mi.mueller.rotate_mueller_basis(
        m, vec(-wo_hat), vec(s_in), mi.mueller.stokes_basis(vec(-wo_hat)),
        vec(wi_hat), vec(s_out), mi.mueller.stokes_basis(vec(wi_hat))))
