"""``thinfilm_diffuse``'s hemispherical terms for the exact model and over a thickness
scale (no plugin classes here).

* :func:`exact_hemispherical` — ``R_dh`` and ``T_hemi`` of a whole coherent stack
  over a base medium of index ``n_b`` (model ``"exact"``), in the base medium's own
  directions: with ``μ`` the cosine there,

      R_dh = 2 ∫_0^1 R_up(μ) μ dμ,   T_hemi = 2 ∫_0^1 T_up(μ) μ dμ,

  ``R_up``, ``T_up`` the exact reflectance and transmittance of the reversed stack
  lit from the base. ``T_hemi`` is the fraction of the base's Lambertian exitance
  that leaves; by reciprocity and the étendue ``n² μ dμ`` it equals
  ``(n_0/n_b)² 2∫ T(μ_0) μ_0 dμ_0`` over the ambient's directions (Mitsuba's
  ``plastic`` radiance factor ``1/η²``). Where ``n_b > n_0`` the base sees total
  internal reflection below ``μ_c = sqrt(1 - (n_0/n_b)²)`` (frustrated by
  absorbing films): the rule is split there, the escape cone integrated in the
  ambient cosine ``μ_0`` (``μ dμ = (n_0/n_b)² μ_0 dμ_0``, smooth at ``μ_c``).
  ``R_up`` and ``T_up`` share the nodes, so a lossless stack gives ``R_dh + T_hemi
  = 1`` to rounding.
* :class:`ScaleTable` — such terms (of any model) over the thickness scale ``s``
  of a ``thickness`` texture: a float texture over ``(s, λ)`` on the 1 nm grid, the
  scale nodes doubled until linear interpolation in ``s`` is within
  :data:`SCALE_ABS`.
"""
from __future__ import annotations

import math
from typing import Callable, Sequence

import drjit as dr
import numpy as np
from drjit.llvm import Float64, UInt32

from thinfilm_mi.llvm import require_llvm
from thinfilm_mi.materials.model import GRID
from thinfilm_mi.optics.backend import float64_array
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.optics.unpolarised import LOOP_MIN_FILMS, unpolarised_rt, unpolarised_rt_loop
from thinfilm_mi.tabulate.base import grid_coordinate, linear_texture, opaque_float

__all__ = ["base_rule", "nodes_for", "exact_hemispherical", "paper_hemispherical", "ScaleTable",
           "SCALE_ABS"]

#: Gauss-Legendre nodes per part of the base medium's hemisphere (as
#: :data:`thinfilm_mi.tabulate.hemispherical.DEFAULT_NODES`).
NODES = 128
#: Lanes (scales x wavelengths x nodes) per float64 kernel launch.
CHUNK_LANES = 1 << 20
#: Largest abs error of linear interpolation in the thickness scale of ``R_dh``
#: and ``T_hemi`` (checked at every midpoint of the scale nodes; the table keeps the
#: midpoints, so its own error is about a quarter of this). ``R_dh`` enters
#: ``1/(1 - k_d R_dh)``: 1e-3 is a relative error of at most 1e-3 k_d/(1 - k_d R_dh)
#: in the diffuse term (0.2 % for a white base under R_dh = 0.5) before that quarter.
SCALE_ABS = 1e-3
#: Scale nodes of the first grid, and the most.
FIRST_SCALE_NODES = 17
MAX_SCALE_NODES = 1025


def base_rule(n_amb: np.ndarray, n_base: np.ndarray, nodes: int = NODES):
    """Per wavelength, cosines ``μ`` in the base medium and weights of ``2 ∫_0^1 f(μ) μ
    dμ`` (each shape ``(len n_amb, m)``): one Gauss-Legendre rule where ``n_b <= n_0``,
    else split at the critical cosine, the escape cone taken in ``μ_0`` (module
    docstring)."""
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    t = 0.5 * (x + 1.0)
    ratio = (np.asarray(n_amb, np.float64) / np.asarray(n_base, np.float64))[:, None]
    nw = ratio.shape[0]
    if np.all(ratio >= 1.0):
        mu = np.broadcast_to(t, (nw, t.size))
        return np.ascontiguousarray(mu), np.ascontiguousarray(np.broadcast_to(w * t, (nw, t.size)))
    r2 = np.minimum(ratio, 1.0) ** 2
    mu_c = np.sqrt(1.0 - r2)
    # the total-reflection part [0, mu_c]
    mu_a = mu_c * t[None, :]
    w_a = w[None, :] * mu_c * mu_a
    # the escape cone in the ambient cosine
    mu_b = np.sqrt(1.0 - r2 * (1.0 - t[None, :] ** 2))
    w_b = w[None, :] * r2 * t[None, :]
    # where n_b < n_0 at some wavelengths: no total reflection (mu_c = 0), the
    # second part over mu in [0, 1] directly
    plain = (ratio >= 1.0)[:, 0]
    mu_b[plain] = t
    w_b[plain] = w * t
    return np.concatenate([mu_a, mu_b], axis=1), np.concatenate([w_a, w_b], axis=1)


def _lanes(values: np.ndarray, ns: int, nm: int) -> np.ndarray:
    """Per-wavelength ``values`` on lanes laid out as scales x wavelengths x nodes."""
    return np.tile(np.repeat(np.asarray(values), nm), ns)


def nodes_for(films: Sequence[tuple[np.ndarray, float]], s_max: float = 1.0) -> int:
    """Gauss-Legendre nodes for the hemispherical terms of ``films`` up to the scale
    ``s_max``: ``8 W + 16`` within ``[32, NODES]``, with ``W = 2 Σ max(Re n) d s_max /
    360 nm`` a bound on the fringes over the hemisphere (measured: 32 nodes are within
    4e-7 of 128 for SiO2 735 nm; Au 6 nm, W = 6)."""
    w = 2.0 * s_max * sum(float(np.max(np.real(n))) * float(d) for n, d in films) / 360.0
    return int(min(NODES, max(32, 8 * math.ceil(w) + 16)))


def _over_scales(n_in, mu, films, n_exit, wavelengths, scales, reduce):
    """``reduce(R, T, s)`` per chunk of ``scales`` (``R``, ``T``: float64 numpy of
    shape ``(chunk, nw, nm)``; ``s``: the chunk's scales) for the stack ``films``
    (``[(index over wavelengths, thickness)]`` from the incident medium ``n_in``,
    real) over ``n_exit`` (complex) at the cosines ``mu`` ``(nw, nm)``, every thickness
    times the scale; the results stacked along the first axis."""
    wl = np.asarray(wavelengths, np.float64)
    nw, nm = mu.shape
    per = max(1, CHUNK_LANES // (nw * nm))
    out = []
    for a in range(0, scales.size, per):
        s = scales[a:a + per]
        ns = s.size
        cos = float64_array(np.tile(mu.ravel(), ns))
        lane_wl = float64_array(_lanes(wl, ns, nm))
        n0 = float64_array(_lanes(n_in, ns, nm))
        exit_ = Cx(float64_array(_lanes(np.real(n_exit), ns, nm)),
                   float64_array(_lanes(np.imag(n_exit), ns, nm)))
        lane_s = float64_array(np.repeat(s, nw * nm))
        if len(films) >= LOOP_MIN_FILMS:
            count, film = _film_loop(films, nw, nm, ns, lane_s)
            R, T = unpolarised_rt_loop(n0, cos, count, film, exit_, lane_wl, True)
        else:
            stack = [(Cx(float64_array(_lanes(np.real(n), ns, nm)),
                         float64_array(_lanes(np.imag(n), ns, nm))),
                      lane_s * dr.opaque(Float64, float(d))) for n, d in films]
            R, T = unpolarised_rt(n0, cos, stack, exit_, lane_wl, True)
        dr.eval(R, T)
        out.append(reduce(np.array(R, np.float64).reshape(ns, nw, nm),
                          np.array(T, np.float64).reshape(ns, nw, nm), s))
    return tuple(np.concatenate(parts) for parts in zip(*out))


def _hemi(R_up, t, weight):
    """``(R_dh, T_hemi)`` from ``R_up`` and ``t`` at the nodes (clamped as
    :func:`thinfilm_mi.tabulate.hemispherical.hemispherical_factors` does)."""
    T_hemi = np.clip(np.einsum("swm,wm->sw", t, weight), 0.0, 1.0)
    return np.clip(np.einsum("swm,wm->sw", R_up, weight), 0.0, 1.0 - T_hemi), T_hemi


def exact_hemispherical(n_amb: np.ndarray, films: Sequence[tuple[np.ndarray, float]],
                        n_base: np.ndarray, wavelengths: np.ndarray = GRID,
                        scales: Sequence[float] = (1.0,), nodes: int | None = None):
    """``(R_dh, T_hemi)`` of the stack ``films`` (``[(index over wavelengths,
    thickness nm)]``, from the ambient) between the ambient ``n_amb`` and the base
    medium ``n_base`` (both real, over ``wavelengths``), every thickness times each
    of ``scales``: float64 arrays of shape ``(len scales, len wavelengths)``.
    ``nodes``: per part of the rule (default :func:`nodes_for`)."""
    require_llvm()
    scales = np.asarray(scales, np.float64).reshape(-1)
    nodes = nodes or nodes_for(films, float(np.max(scales, initial=0.0)))
    mu, weight = base_rule(n_amb, n_base, nodes)
    return _over_scales(np.asarray(n_base, np.float64), mu, list(films)[::-1],
                        np.asarray(n_amb, np.complex128), wavelengths, scales,
                        lambda R, T, s: _hemi(R, T, weight))


def paper_hemispherical(n_amb: np.ndarray, coating: Sequence[tuple[np.ndarray, float]],
                        film_n: tuple[np.ndarray, float], wavelengths: np.ndarray = GRID,
                        scales: Sequence[float] = (1.0,), nodes: int | None = None):
    """The paper's terms with an absorbing film ``N`` (``film_n = (index, thickness)``,
    the coating's semi-infinite exit medium, and an attenuation ``k_a``), as
    :func:`thinfilm_mi.tabulate.hemispherical.hemispherical_factors` gives them, at
    every thickness scale of ``scales`` at once: ``t = k_t k_a``, ``R_up = k_a² k_r``
    over the ambient's cosines."""
    require_llvm()
    scales = np.asarray(scales, np.float64).reshape(-1)
    nodes = nodes or nodes_for(list(coating) + [film_n], float(np.max(scales, initial=0.0)))
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    mu = 0.5 * (x + 1.0)
    nw = np.asarray(n_amb).size
    weight = np.broadcast_to(w * mu, (nw, mu.size))
    wl = np.asarray(wavelengths, np.float64)
    n0 = np.asarray(n_amb, np.float64)[:, None]
    n_f = np.asarray(film_n[0], np.complex128)[:, None]
    q = np.sqrt(n_f ** 2 - n0 ** 2 * (1.0 - mu[None, :] ** 2) + 0j)
    q = np.where(q.imag < 0, -q, q)                       # the decaying root
    decay = (4.0 * math.pi / wl)[:, None] * q.imag * float(film_n[1])   # per unit scale

    def reduce(R, T, s):
        k_a = np.exp(-decay[None, :, :] * s[:, None, None])
        return _hemi(R * k_a * k_a, T * k_a, weight)
    return _over_scales(np.asarray(n_amb, np.float64), np.ascontiguousarray(np.broadcast_to(mu, (nw, mu.size))),
                        list(coating), film_n[0], wavelengths, scales, reduce)


def _film_loop(films, nw: int, nm: int, ns: int, lane_s):
    """``(count, film)`` for :func:`unpolarised_rt_loop` over ``films`` on lanes laid
    out as ``ns`` scales x ``nw`` wavelengths x ``nm`` nodes: each film's index is
    gathered per lane from one buffer of ``films x nw`` entries (padded), its
    thickness times the lane's scale."""
    n = np.concatenate([np.asarray(ix, np.complex128) * np.ones(nw) for ix, _ in films]
                       + [np.zeros(1)])
    eta, k = float64_array(n.real), float64_array(n.imag)
    thickness = float64_array(np.r_[[float(d) for _, d in films], 0.0])
    lane_wl = UInt32(np.tile(np.repeat(np.arange(nw, dtype=np.uint32), nm), ns))

    def film(j):
        i = j * nw + lane_wl
        return (Cx(dr.gather(Float64, eta, i), dr.gather(Float64, k, i)),
                dr.gather(Float64, thickness, j) * lane_s)
    return UInt32(len(films)), film


class ScaleTable:
    """``R_dh``, ``T_hemi`` and ``∂R_dh/∂s`` over the thickness scale ``s`` in ``[0,
    s_max]`` and the 1 nm grid, as a float texture for the render kernel (linear in
    both).

    ``hemi(scales) -> (R_dh, T_hemi)`` (each ``(len scales, len GRID)``) gives the
    terms of the plugin's model. Nodes uniform in ``u = sqrt(s / s_max)`` (the terms
    of a thin metal film curve most near ``s = 0``), doubled until every new
    midpoint is predicted by linear interpolation within :data:`SCALE_ABS` (at most
    :data:`MAX_SCALE_NODES`); the table keeps the midpoints. ``∂R_dh/∂s`` at the
    nodes is the second-order difference of the node values (``np.gradient``).
    ``s_max <= 0``: one node at ``s = 0``."""

    def __init__(self, hemi: Callable, s_max: float):
        if s_max <= 0.0:
            s = np.zeros(1)
            values = np.stack(hemi(s), axis=-1)                 # (1, nw, 2)
            slope = np.zeros_like(values[..., :1])
        else:
            u = np.linspace(0.0, 1.0, FIRST_SCALE_NODES)
            values = np.stack(hemi(s_max * u ** 2), axis=-1)
            while u.size < MAX_SCALE_NODES:
                mid = 0.5 * (u[:-1] + u[1:])
                v_mid = np.stack(hemi(s_max * mid ** 2), axis=-1)
                err = float(np.max(np.abs(v_mid - 0.5 * (values[:-1] + values[1:]))))
                u = _interleave(u, mid)
                values = _interleave(values, v_mid)
                if err <= SCALE_ABS:
                    break
            s = s_max * u ** 2
            slope = np.gradient(values[..., :1], s, axis=0)
        values = np.concatenate([values, slope], axis=-1)     # (ns, nw, 3)
        self.scales = s
        self.values = values                                    # for tests
        self.s_max = float(s[-1])
        ns = s.size
        self._texture = linear_texture(values)
        self._inv = opaque_float(1.0 / self.s_max if self.s_max > 0 else 0.0)
        self._span = (ns - 1) / ns
        self._half = 0.5 / ns

    def lookup(self, wavelengths, scale, active=True):
        """``(R_dh, T_hemi, ∂R_dh/∂s)`` as ``mi.UnpolarizedSpectrum`` at ``wavelengths``
        (nm) and the thickness ``scale``, detached from ``scale``."""
        import mitsuba as mi
        u = dr.sqrt(dr.clip(dr.detach(scale) * self._inv, 0.0, 1.0))
        v = u * self._span + self._half
        out = ([], [], [])
        for k in range(dr.size_v(mi.UnpolarizedSpectrum)):
            res = self._texture.eval(mi.Point2f(grid_coordinate(wavelengths[k]), v), active)
            for c in range(3):
                out[c].append(res[c])
        return tuple(mi.UnpolarizedSpectrum(*o) for o in out)


def _interleave(a: np.ndarray, mid: np.ndarray) -> np.ndarray:
    out = np.empty((a.shape[0] + mid.shape[0],) + a.shape[1:], a.dtype)
    out[0::2], out[1::2] = a, mid
    return out
