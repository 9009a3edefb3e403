"""Characteristic matrices of a stack in numpy complex128, with exact derivatives.

The design loop needs R and T of one stack at a few hundred (wavelength, angle)
points *and* their derivatives with respect to every film thickness, every free
index and every possible needle, many times per second. This module computes
them with the characteristic (Abelès) matrices of Born & Wolf (sec. 1.6), in the
conventions of :mod:`thinfilm_mi.optics.core` (``n + ik`` with ``k >= 0``, time
dependence ``exp(-i w t)``, ``q = n cos(theta) = sqrt(n^2 - beta^2)`` with the
decaying root, ``beta = n0 sin(theta0)``):

* tilted admittances ``eta = q`` (s) and ``eta = n^2 / q`` (p), the components'
  :meth:`~thinfilm_mi.optics.polarization.Component.admittance`; phase
  ``delta = 2 pi q d / lambda``;
* ``M = [[cos delta, -i sin delta / eta], [-i eta sin delta, cos delta]]``,
  ``[B, C] = M_1 M_2 ... M_L [1, eta_exit]`` (film 1 meets the light first);
* ``r = (eta_0 B - C) / (eta_0 B + C)``, ``R = |r|^2`` and
  ``T = 4 eta_0 Re(eta_exit) / |eta_0 B + C|^2`` (the power entering the exit
  medium), for both polarisations.

``r`` here is the amplitude of the tangential field; its phase is not tmm's for
p light, so only the powers R and T leave this module (they are what the design
targets hold). The products are ordinary float64 matrix products, fine for the
dielectric and thin metal films of coating designs (an overflow needs
``Im delta > 700``, a metal film microns thick); the renderer's recursion in
:mod:`thinfilm_mi.optics.core` stays the reference for everything else, and
tests/design/test_matrices.py checks this module against tmm.

Derivatives are forward-mode through prefix products ``P_j = M_1 ... M_{j-1}``
and suffix vectors ``S_j = M_{j+1} ... M_L [1, eta_exit]``: a change of film j
changes ``[B, C]`` by ``P_j dM_j S_j``, so all of them cost about three stack
evaluations. A *needle* (Tikhonravov & Trubetskov) is a film of zero thickness
inserted at depth z inside film j; its derivative is
``P_j M_j(z) N M_j(d_j - z) S_j`` with ``N = dM/dd`` of the needle material at
``d = 0``, evaluated for every depth of a grid and every material in one pass.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from thinfilm_mi.optics.polarization import Component

__all__ = ["normal_index", "Response", "stack_response", "film_index_response", "needle_response"]

TWO_PI = 2.0 * np.pi


def normal_index(n: np.ndarray, beta2: np.ndarray) -> np.ndarray:
    """``q = sqrt(n^2 - beta2)``, the root with ``Im q > 0``, or ``Im q = 0`` and
    ``Re q >= 0`` (the wave that decays or propagates away from the interface),
    as :func:`thinfilm_mi.optics.core.sqrt_decaying` chooses it."""
    w = np.sqrt(np.asarray(n * n - beta2, dtype=np.complex128))
    flip = (w.imag < 0) | ((w.imag == 0) & (w.real < 0))
    return np.where(flip, -w, w)


def _matrix(c, s, eta):
    """``[[c, -i s / eta], [-i eta s, c]]`` as its four entries (row by row)."""
    return c, -1j * s / eta, -1j * eta * s, c


def _mul(a, b):
    """Product of two 2x2 matrices given as entry tuples."""
    return (a[0] * b[0] + a[1] * b[2], a[0] * b[1] + a[1] * b[3],
            a[2] * b[0] + a[3] * b[2], a[2] * b[1] + a[3] * b[3])


def _matvec(m, v):
    """Matrix (entry tuple) times vector (pair)."""
    return m[0] * v[0] + m[1] * v[1], m[2] * v[0] + m[3] * v[1]


@dataclass
class Response:
    """R and T at P points, and optionally their derivatives ``dR``, ``dT``
    (P, K) with respect to K parameters (thicknesses in nm, then indices)."""

    R: np.ndarray
    T: np.ndarray
    dR: np.ndarray | None = None
    dT: np.ndarray | None = None


class _Stack:
    """Films of one polarisation at P points: admittances, phases, matrices and
    the prefix / suffix products."""

    def __init__(self, n_in, n_out, films, d, wl, beta2, pol: Component):
        self.pol = pol
        self.k0 = TWO_PI / wl
        self.beta2 = beta2
        q0 = normal_index(n_in.astype(np.complex128), beta2)
        self.eta0 = pol.admittance(n_in, q0).real
        q_out = normal_index(n_out, beta2)
        self.eta_out = pol.admittance(n_out, q_out)
        self.films = films
        self.d = [np.asarray(dj, dtype=np.float64) for dj in d]
        self.q = [normal_index(n, beta2) for n in films]
        self.eta = [pol.admittance(n, q) for n, q in zip(films, self.q)]
        self.delta = [self.k0 * q * dj for q, dj in zip(self.q, self.d)]
        shape = np.broadcast_shapes(wl.shape, *(x.shape for x in self.delta))
        self.c = [np.cos(x) for x in self.delta]
        self.s = [np.sin(x) for x in self.delta]
        self.M = [_matrix(c, s, e) for c, s, e in zip(self.c, self.s, self.eta)]
        self.pre = [(1.0, 0.0, 0.0, 1.0)]          # pre[j] = M_1 ... M_{j-1}
        for m in self.M:
            self.pre.append(_mul(self.pre[-1], m))
        suf = [(np.ones(shape, dtype=np.complex128), np.broadcast_to(self.eta_out, shape))]
        for m in reversed(self.M):
            suf.append(_matvec(m, suf[-1]))
        self.suf = suf[::-1]          # suf[j] = M_j ... M_L [1, eta_out]; suf[L] = [1, eta_out]
        B, C = self.suf[0]
        self.D = self.eta0 * B + C
        self.r = (self.eta0 * B - C) / self.D
        self.R = np.abs(self.r) ** 2
        self.T = 4.0 * self.eta0 * self.eta_out.real / np.abs(self.D) ** 2

    def powers_from(self, dB, dC):
        """dR, dT (..., K) from the changes dB, dC (..., K) of [B, C]."""
        e0 = self.eta0[..., None]
        r, D = self.r[..., None], self.D[..., None]
        dr = (e0 * dB * (1.0 - r) - dC * (1.0 + r)) / D
        dR = 2.0 * (np.conj(r) * dr).real
        dD = e0 * dB + dC
        dT = -2.0 * self.T[..., None] * (np.conj(D) * dD).real / np.abs(D) ** 2
        return dR, dT

    def dM_dthickness(self, j):
        """dM_j / dd_j (entry tuple)."""
        k = self.k0 * self.q[j]
        c, s, eta = self.c[j], self.s[j], self.eta[j]
        return -k * s, -1j * k * c / eta, -1j * k * eta * c, -k * s

    def dM_dindex(self, j, dn):
        """dM_j / dn for a change ``dn`` of the film's complex index (1 for n, 1j for k)."""
        n, q, eta = self.films[j], self.q[j], self.eta[j]
        dq = n * dn / q
        deta = self.pol.admittance_derivative(n, q, dn, dq)
        ddelta = self.k0 * dq * self.d[j]
        c, s = self.c[j], self.s[j]
        return (-s * ddelta, -1j * (c * ddelta / eta - s * deta / (eta * eta)),
                -1j * (deta * s + eta * c * ddelta), -s * ddelta)

    def through(self, j, dM):
        """``P_j dM S_{j+1}``: the change (dB, dC) of [B, C] for a change dM of film j."""
        return _matvec(self.pre[j], _matvec(dM, self.suf[j + 1]))


def stack_response(n_in, n_out, films, d, wl, beta2, pol, index_groups=(), derivatives=True) -> Response:
    """R and T of one polarisation with their derivatives.

    ``n_in`` (P,) real index of the medium the light comes from, ``n_out`` (P,)
    complex index of the exit medium, ``films`` a list of L complex arrays (P,)
    in the order the light meets them, ``d`` (L,) thicknesses in nm, ``wl``
    (P,) wavelengths in nm, ``beta2`` (P,) ``(n_in sin theta)^2``, ``pol`` the
    component (:data:`~thinfilm_mi.optics.polarization.S` or ``P``).
    ``index_groups``: for each free index a list of the films that share it;
    its derivative is the sum over them (a change of the real part n).
    The derivatives ``dR``, ``dT`` are (P, L + len(index_groups)). The point
    arrays may broadcast against thicknesses of another shape: points (P, 1) and
    each ``d[j]`` (B,) give R and T of B stacks at once, (P, B), and derivatives
    (P, B, K); ``derivatives=False`` skips them.
    """
    st = _Stack(n_in, n_out, films, d, wl, beta2, pol)
    if not derivatives:
        return Response(st.R, st.T)
    L = len(films)
    shape = np.shape(st.R)
    dB, dC = [], []
    for j in range(L):
        b, c = st.through(j, st.dM_dthickness(j))
        dB.append(np.broadcast_to(b, shape))
        dC.append(np.broadcast_to(c, shape))
    for members in index_groups:
        b = c = np.zeros(shape, dtype=np.complex128)
        for j in members:
            db, dc = st.through(j, st.dM_dindex(j, 1.0))
            b, c = b + db, c + dc
        dB.append(b)
        dC.append(c)
    if not dB:
        return Response(st.R, st.T, np.zeros(shape + (0,)), np.zeros(shape + (0,)))
    dR, dT = st.powers_from(np.stack(dB, axis=-1), np.stack(dC, axis=-1))
    return Response(st.R, st.T, dR, dT)


def film_index_response(n_in, n_out, films, d, wl, beta2, pol) -> Response:
    """R and T of one polarisation (arguments as :func:`stack_response`) with
    their derivatives with respect to each film's thickness, then each film's
    ``n`` and each film's ``k``: ``dR``, ``dT`` (P, 3 L). A fit whose films'
    indices follow dispersion models chains these per point to its parameters."""
    st = _Stack(n_in, n_out, films, d, wl, beta2, pol)
    shape = np.shape(st.R)
    L = len(films)
    if not L:
        return Response(st.R, st.T, np.zeros(shape + (0,)), np.zeros(shape + (0,)))
    thick = [st.through(j, st.dM_dthickness(j)) for j in range(L)]
    index = [st.through(j, st.dM_dindex(j, 1.0)) for j in range(L)]
    # dM_dindex is complex-linear in its change: a change 1j of the index (of k) is 1j times it
    dB = [np.broadcast_to(b, shape) for b, _ in thick] + [b for b, _ in index] + [1j * b for b, _ in index]
    dC = [np.broadcast_to(c, shape) for _, c in thick] + [c for _, c in index] + [1j * c for _, c in index]
    dR, dT = st.powers_from(np.stack(dB, axis=-1), np.stack(dC, axis=-1))
    return Response(st.R, st.T, dR, dT)


def needle_response(n_in, n_out, films, d, wl, beta2, pol, depths, needles) -> Response:
    """dR and dT with respect to the thickness of a needle, at 0 thickness.

    ``depths``: for each film j an array of depths z (nm from the film's side
    that the light meets first, within [0, d_j]); ``needles``: the needle
    materials' indices, a list of M arrays (P,). Returns a :class:`Response`
    whose ``dR``, ``dT`` are (P, Z, M) with Z the total number of depths (film 0's
    first). ``R`` and ``T`` are the stack's own. With no films, ``depths`` must be
    ``[np.zeros(1)]`` (the one interface) and ``films`` empty.
    """
    st = _Stack(n_in, n_out, films, d, wl, beta2, pol)
    P = wl.shape[0]
    q_n = [normal_index(n, beta2) for n in needles]
    eta_n = np.stack([pol.admittance(n, q) for n, q in zip(needles, q_n)], axis=-1)   # (P, M)
    kappa = st.k0[:, None] * np.stack(q_n, axis=-1)                                      # (P, M)
    col = (lambda a: np.asarray(a)[:, None] if np.ndim(a) else a)
    parts = []
    if not films:
        parts.append((tuple(col(x) for x in st.pre[0]), tuple(col(x) for x in st.suf[0])))
    for j, z in enumerate(depths[:len(films)]):
        z = np.asarray(z, dtype=np.float64)[None, :]
        kq = st.k0[:, None] * st.q[j][:, None]       # (P, 1)
        eta = st.eta[j][:, None]
        top = _matrix(np.cos(kq * z), np.sin(kq * z), eta)                 # M_j(z), entries (P, Z)
        rest = d[j] - z
        bottom = _matrix(np.cos(kq * rest), np.sin(kq * rest), eta)       # M_j(d - z)
        parts.append((_mul(tuple(col(x) for x in st.pre[j]), top),
                      _matvec(bottom, tuple(col(x) for x in st.suf[j + 1]))))
    Zs = [np.broadcast_shapes(*(np.shape(x) for x in u + v))[1] for u, v in parts]
    u = [np.concatenate([np.broadcast_to(p[0][i], (P, z)) for p, z in zip(parts, Zs)], axis=1) for i in range(4)]
    v = [np.concatenate([np.broadcast_to(p[1][i], (P, z)) for p, z in zip(parts, Zs)], axis=1) for i in range(2)]
    # N v = kappa * (-i v1 / eta_n, -i eta_n v0), for each needle material: (P, Z, M)
    Nv0 = -1j * kappa[:, None, :] * v[1][..., None] / eta_n[:, None, :]
    Nv1 = -1j * kappa[:, None, :] * v[0][..., None] * eta_n[:, None, :]
    dB = u[0][..., None] * Nv0 + u[1][..., None] * Nv1
    dC = u[2][..., None] * Nv0 + u[3][..., None] * Nv1
    Z, M = dB.shape[1], len(needles)
    dR, dT = st.powers_from(dB.reshape(P, -1), dC.reshape(P, -1))
    return Response(st.R, st.T, dR.reshape(P, Z, M), dT.reshape(P, Z, M))
