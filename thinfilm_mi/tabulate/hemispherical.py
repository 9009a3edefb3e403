"""Hemispherical (cosine-weighted) terms of a coating over a diffuse base, for the
coated-diffuse model (:mod:`thinfilm_mi.render.layered.series`), at one or at many
thickness scales.

Per wavelength the coated diffuse base needs two angular integrals of the coating
between the ambient and the base:

* ``T_hemi = 2 ∫_0^1 t(μ) μ dμ`` — the fraction of the base's Lambertian exitance that
  leaves through the coating;
* ``R_dh = 2 ∫_0^1 R_up(μ) μ dμ`` — the fraction that the coating sends back down onto
  the base (its hemispherical reflectance seen from below).

Two configurations give them (one float64 engine, :func:`_over_scales`, runs the optics
core on ``drjit.llvm.Float64`` lanes laid out as scales x wavelengths x rule nodes, every
thickness times the lane's scale; deep coatings as a loop over the films):

* :func:`paper_terms` (and :func:`hemispherical_factors` at one scale) — the paper's
  models, over the ambient's cosines ``μ``: with an absorbing film ``N`` (the coating's
  semi-infinite exit medium) ``t = k_t k_a`` and ``R_up = k_a² k_r`` (down and up through
  film ``N``, the coating reflecting alike from both sides: exact for a lossless coating,
  ``R_up + t <= 1`` otherwise); without one, the coating over a base medium matched to
  the ambient, ``t = T`` and ``R_up`` the exact reflectance of the reversed coating.
* :func:`exact_hemispherical` — the whole stack (coherent but for its incoherent films)
  over a base medium of index ``n_b`` (model ``"exact"``), in the base medium's own directions, ``R_up`` and ``T_up``
  of the reversed stack lit from the base. ``T_hemi`` is the fraction of the base's
  Lambertian exitance that leaves; by reciprocity and the étendue ``n² μ dμ`` it equals
  ``(n_0/n_b)² 2∫ T(μ_0) μ_0 dμ_0`` over the ambient's directions (Mitsuba's ``plastic``
  radiance factor ``1/η²``). Where ``n_b > n_0`` the base sees total internal reflection
  below ``μ_c = sqrt(1 - (n_0/n_b)²)`` (frustrated by absorbing films): the rule
  (:func:`base_rule`) is split there, the escape cone integrated in the ambient cosine
  ``μ_0`` (``μ dμ = (n_0/n_b)² μ_0 dμ_0``, smooth at ``μ_c``).

Films marked incoherent (thicker than the stack's ``coherence_thickness``) are averaged
as the render kernel averages them (:mod:`thinfilm_mi.optics.incoherent`): their phase
never enters, and a lossless one's thickness does not matter.

Each uses one Gauss-Legendre rule for both terms, so ``T_hemi + R_dh = 1`` holds to
rounding for a lossless coating whatever the quadrature error of each, which is what
makes a lossless coating on a white base conserve energy exactly. The terms are
computed at load time (and again when a thickness changes) on the 1 nm grid.

* :class:`ScaleTable` — the terms (of any model) over the thickness scale ``s`` of a
  ``thickness`` texture: a float texture over ``(s, λ)`` on the 1 nm grid, the scale
  nodes doubled until linear interpolation in ``s`` is within :data:`SCALE_ABS`.

Gradients (AD variants): ``R_dh`` enters the diffuse term through the series
``1/(1 - k_d R_dh)``, so its derivatives matter; ``T_hemi`` only enters the (detached)
lobe-selection probability. :func:`r_dh_partials` gives ``∂R_dh(λ)/∂x`` for every
film's thickness and index (real and imaginary part), by reverse-mode AD through the
same float64 quadrature, and :class:`DerivativeTable` holds them on the 1 nm grid for
the render kernel, which adds ``Σ_x ∂R_dh/∂x (x - detach(x))`` to ``R_dh`` where a
parameter carries gradients. ``R_dh(λ)`` depends on the indices at ``λ`` only, so the
chain rule through any index texture (a number, a dataset's values) is exact.
"""
from __future__ import annotations

import math
import threading
from typing import Callable, Sequence

import drjit as dr
import numpy as np
from drjit.llvm import Float64, UInt32

from thinfilm_mi.llvm import require_llvm
from thinfilm_mi.materials.model import GRID  # where the factors are tabulated
from thinfilm_mi.optics.backend import aligned_array, float64_array
from thinfilm_mi.optics.core import Cx, film_attenuation
from thinfilm_mi.optics.incoherent import incoherent_rt
from thinfilm_mi.optics.unpolarized import LOOP_MIN_FILMS, unpolarized_rt, unpolarized_rt_loop
from thinfilm_mi.tabulate.base import film_gather, grid_coordinate, linear_texture, opaque_float
from thinfilm_mi.tabulate.refine import interleave

__all__ = ["hemispherical_factors", "paper_terms", "exact_hemispherical", "base_rule", "nodes_for",
           "r_dh_partials", "DerivativeTable", "ScaleTable", "DEFAULT_NODES", "PER_FILM",
           "PARTIALS_LANE_FILMS", "CHUNK_LANES", "SCALE_ABS", "FIRST_SCALE_NODES", "MAX_SCALE_NODES"]

#: Gauss-Legendre nodes in μ = cos θ (per part of a split rule). A 500 nm SiO2 film
#: changes its phase by about one wave over the hemisphere; 128 nodes integrate such
#: oscillations (and those of films ten times thicker) to well below 1e-6.
DEFAULT_NODES = 128
#: Lanes (scales x wavelengths x nodes) per float64 kernel launch.
CHUNK_LANES = 1 << 20
#: Largest abs error of linear interpolation in the thickness scale of ``R_dh``
#: and ``T_hemi`` (checked at every midpoint of the scale nodes; the table keeps the
#: midpoints, so its own error is about a quarter of this). ``R_dh`` enters
#: ``1/(1 - k_d R_dh)``: 1e-3 is a relative error of at most 1e-3 k_d/(1 - k_d R_dh)
#: in the diffuse term (0.2 % for a white base under R_dh = 0.5) before that quarter.
SCALE_ABS = 1e-3
#: Scale nodes of the first grid of a :class:`ScaleTable`, and the most.
FIRST_SCALE_NODES = 17
MAX_SCALE_NODES = 1025


def _rule(nodes: int):
    """Gauss-Legendre nodes ``μ`` on (0, 1) and the weights of ``2 ∫_0^1 f(μ) μ dμ``."""
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    mu = 0.5 * (x + 1.0)
    return mu, w * mu            # 2 * (w / 2) * mu


def base_rule(n_amb: np.ndarray, n_base: np.ndarray, nodes: int = DEFAULT_NODES):
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


def nodes_for(films: Sequence[tuple[np.ndarray, float]], s_max: float = 1.0,
              incoherent: Sequence[bool] | None = None) -> int:
    """Gauss-Legendre nodes for the hemispherical terms of ``films`` up to the scale
    ``s_max``: ``8 W + 16`` within ``[32, DEFAULT_NODES]``, with ``W = 2 Σ max(Re n) d
    s_max / 360 nm`` a bound on the fringes over the hemisphere, over the films not
    marked in ``incoherent`` (an incoherent film has no fringes): eight nodes a fringe
    resolve the integrand's oscillation."""
    flags = incoherent or [False] * len(films)
    w = 2.0 * s_max * sum(float(np.max(np.real(n))) * float(d)
                          for (n, d), inc in zip(films, flags) if not inc) / 360.0
    return int(min(DEFAULT_NODES, max(32, 8 * math.ceil(min(w, DEFAULT_NODES)) + 16)))


def _lanes(values: np.ndarray, ns: int, nm: int) -> np.ndarray:
    """Per-wavelength ``values`` on lanes laid out as scales x wavelengths x nodes."""
    return np.tile(np.repeat(np.asarray(values), nm), ns)


def _over_scales(n_in, mu, films, n_exit, wavelengths, scales, reduce, film_n=None,
                 transmission: bool = True, incoherent: Sequence[bool] | None = None):
    """``reduce(R, T, k_a, s)`` per chunk of ``scales`` (``R``, ``T``, ``k_a``: float64
    numpy of shape ``(chunk, nw, nm)``, ``T`` ``None`` without ``transmission``, ``k_a``
    ``None`` without ``film_n``; ``s``: the chunk's scales) for the stack ``films``
    (``[(index over wavelengths, thickness)]`` from the incident medium ``n_in``, real)
    over ``n_exit`` (complex; real: a literal zero imaginary part) at the cosines ``mu``
    ``(nw, nm)``, every thickness times the scale; ``film_n = (index, thickness)``: the
    attenuation ``k_a`` through that film along the lanes' directions; ``incoherent``: one
    flag per film of ``films``, those averaged incoherently (unrolled, as the kernel
    evaluates them). The results are stacked along the first axis."""
    wl = np.asarray(wavelengths, np.float64)
    nw, nm = mu.shape
    scales = np.asarray(scales, np.float64).reshape(-1)
    per = max(1, CHUNK_LANES // (nw * nm))
    out = []
    for a in range(0, scales.size, per):
        s = scales[a:a + per]
        ns = s.size
        cos = float64_array(np.tile(mu.ravel(), ns))
        lane_wl = float64_array(_lanes(wl, ns, nm))
        n0 = float64_array(_lanes(n_in, ns, nm))
        if np.iscomplexobj(n_exit):
            exit_ = Cx(float64_array(_lanes(np.real(n_exit), ns, nm)),
                       float64_array(_lanes(np.imag(n_exit), ns, nm)))
        else:
            exit_ = Cx(float64_array(_lanes(n_exit, ns, nm)), 0.0)
        lane_s = float64_array(np.repeat(s, nw * nm))
        if len(films) >= LOOP_MIN_FILMS and not any(incoherent or ()):
            # deep coatings: a loop over the films, so the kernel does not grow with them
            at = UInt32(np.tile(np.repeat(np.arange(nw, dtype=np.uint32), nm), ns))
            indices = [np.asarray(ix, np.complex128) * np.ones(nw) for ix, _ in films] + [np.zeros(1)]
            film = film_gather(indices, [float(d) for _, d in films] + [0.0], at, nw, False, lane_s)
            rt = unpolarized_rt_loop(n0, cos, UInt32(len(films)), film, exit_, lane_wl, transmission)
        else:
            # opaque thicknesses: a thickness edit reuses the kernel (incoherent films
            # unrolled, as the render kernel evaluates them: the average has no loop form)
            stack = [(Cx(float64_array(_lanes(np.real(n), ns, nm)),
                         float64_array(_lanes(np.imag(n), ns, nm))),
                      lane_s * dr.opaque(Float64, float(d))) for n, d in films]
            rt = (incoherent_rt(n0, cos, stack, exit_, lane_wl, list(incoherent), transmission)
                  if any(incoherent or ()) else
                  unpolarized_rt(n0, cos, stack, exit_, lane_wl, transmission))
        R, T = rt if transmission else (rt, None)
        k_a = None
        if film_n is not None:
            n_f = np.asarray(film_n[0], np.complex128) * np.ones(nw)
            k_a = film_attenuation(n0, cos, Cx(float64_array(_lanes(n_f.real, ns, nm)),
                                               float64_array(_lanes(n_f.imag, ns, nm))),
                                   dr.opaque(Float64, float(film_n[1])) * lane_s, lane_wl)
        dr.eval(*[x for x in (R, T, k_a) if x is not None])
        out.append(reduce(*[None if x is None else np.array(x, np.float64).reshape(ns, nw, nm)
                            for x in (R, T, k_a)], s))
    return tuple(np.concatenate(parts) for parts in zip(*out))


def _hemi(R_up, t, weight):
    """``(R_dh, T_hemi)`` (each ``(scales, wavelengths)``) from ``R_up`` and ``t`` at the
    rule's nodes ``(scales, wavelengths, nodes)``, clamped to ``T_hemi`` in [0, 1] and
    ``R_dh`` in [0, 1 - T_hemi] (rounding only). ``weight``: one rule ``(nodes,)`` for
    every wavelength, or one per wavelength ``(wavelengths, nodes)``."""
    if weight.ndim == 1:
        T_hemi = np.clip(np.stack([tk @ weight for tk in t]), 0.0, 1.0)
        return np.clip(np.stack([rk @ weight for rk in R_up]), 0.0, 1.0 - T_hemi), T_hemi
    T_hemi = np.clip(np.einsum("swm,wm->sw", t, weight), 0.0, 1.0)
    return np.clip(np.einsum("swm,wm->sw", R_up, weight), 0.0, 1.0 - T_hemi), T_hemi


def paper_terms(n_amb: np.ndarray, coating: Sequence[tuple[np.ndarray, float]],
                n_exit: np.ndarray, film_n: tuple[np.ndarray, float] | None,
                wavelengths: np.ndarray = GRID, scales: Sequence[float] = (1.0,),
                nodes: int | None = None, incoherent: Sequence[bool] | None = None):
    """``(R_dh, T_hemi)`` of the paper's models at every thickness scale of ``scales``,
    each of shape ``(len scales, len wavelengths)``, over the ambient's cosines.

    ``n_amb`` (real), the coating's film indices and ``n_exit`` are arrays over
    ``wavelengths``. ``film_n = (index, thickness)``: the absorbing film ``N``, the
    coating's semi-infinite exit medium (``n_exit`` is not read), ``t = k_t k_a``,
    ``R_up = k_a² k_r``; ``None``: the coating over the base medium ``n_exit`` (real),
    ``t = T``, ``R_up`` the reversed coating's reflectance lit from the base medium.
    ``nodes``: of the rule (default :func:`nodes_for` the films and the largest scale).
    ``incoherent``: one flag per film of ``coating``, the films averaged incoherently."""
    require_llvm()
    scales = np.asarray(scales, np.float64).reshape(-1)
    films = list(coating) + ([] if film_n is None else [film_n])
    flags = list(incoherent) if incoherent is not None else [False] * len(coating)
    nodes = nodes or nodes_for(films, float(np.max(scales, initial=0.0)),
                               flags + [False] * (len(films) - len(flags)))
    mu, weight = _rule(nodes)
    nw = np.asarray(wavelengths).size
    mu = np.ascontiguousarray(np.broadcast_to(mu, (nw, mu.size)))
    n0 = np.asarray(n_amb, np.float64) * np.ones(nw)
    if film_n is not None:
        return _over_scales(n0, mu, list(coating), np.asarray(film_n[0], np.complex128) * np.ones(nw),
                            wavelengths, scales,
                            lambda R, T, k_a, s: _hemi(R * k_a * k_a, T * k_a, weight), film_n,
                            incoherent=flags)
    n_b = np.asarray(n_exit, np.complex128) * np.ones(nw)
    (t,) = _over_scales(n0, mu, list(coating), n_b, wavelengths, scales, lambda R, T, k_a, s: (T,),
                        incoherent=flags)
    (R_up,) = _over_scales(n_b.real, mu, list(coating)[::-1], n0, wavelengths, scales,
                           lambda R, T, k_a, s: (R,), transmission=False, incoherent=flags[::-1])
    return _hemi(R_up, t, weight)


def hemispherical_factors(n_amb: np.ndarray, coating: Sequence[tuple[np.ndarray, float]],
                          n_exit: np.ndarray, film_n: tuple[np.ndarray, float] | None,
                          wavelengths: np.ndarray = GRID, nodes: int = DEFAULT_NODES):
    """``(T_hemi, R_dh)`` per wavelength (float64 numpy arrays) of :func:`paper_terms`
    (same arguments) at scale 1 with :data:`DEFAULT_NODES` nodes."""
    R_dh, T_hemi = paper_terms(n_amb, coating, n_exit, film_n, wavelengths, (1.0,), nodes)
    return T_hemi[0], R_dh[0]


def exact_hemispherical(n_amb: np.ndarray, films: Sequence[tuple[np.ndarray, float]],
                        n_base: np.ndarray, wavelengths: np.ndarray = GRID,
                        scales: Sequence[float] = (1.0,), nodes: int | None = None,
                        incoherent: Sequence[bool] | None = None):
    """``(R_dh, T_hemi)`` of the stack ``films`` (``[(index over wavelengths,
    thickness nm)]``, from the ambient; none: the bare interface) between the ambient
    ``n_amb`` and the base medium ``n_base`` (both real, over ``wavelengths``), every
    thickness times each of ``scales``: float64 arrays of shape ``(len scales, len
    wavelengths)``. ``nodes``: per part of the rule (default :func:`nodes_for`);
    ``incoherent``: one flag per film, the films averaged incoherently."""
    require_llvm()
    scales = np.asarray(scales, np.float64).reshape(-1)
    flags = list(incoherent) if incoherent is not None else [False] * len(films)
    nodes = nodes or nodes_for(films, float(np.max(scales, initial=0.0)), flags)
    mu, weight = base_rule(n_amb, n_base, nodes)
    return _over_scales(np.asarray(n_base, np.float64), mu, list(films)[::-1],
                        np.asarray(n_amb, np.complex128), wavelengths, scales,
                        lambda R, T, k_a, s: _hemi(R, T, weight), incoherent=flags[::-1])


#: Parameters per film in :func:`r_dh_partials`: thickness (nm), Re n, Im n.
PER_FILM = 3
#: Lanes (wavelengths x nodes) x films per reverse-mode pass of :func:`r_dh_partials`:
#: the loop over the films stores its state (14 float64) per film and lane, ~60 MB.
PARTIALS_LANE_FILMS = 1 << 19
#: One reverse-mode pass at a time (Dr.Jit's AD graph is shared between threads).
#: Re-entrant: a thread waiting for a kernel runs other tasks of Dr.Jit's pool, so a
#: plain lock held across an evaluation deadlocks if one of them gets here too.
_PARTIALS_LOCK = threading.RLock()


def r_dh_partials(n_amb: np.ndarray, coating: Sequence[tuple[np.ndarray, float]],
                  n_exit: np.ndarray, film_n: tuple[np.ndarray, float] | None,
                  wavelengths: np.ndarray = GRID, nodes: int = DEFAULT_NODES) -> np.ndarray:
    """``∂R_dh(λ)/∂x`` of :func:`hemispherical_factors`'s ``R_dh`` (same arguments,
    same rule), shape ``(PER_FILM * films, len wavelengths)``: per film of
    ``coating`` and then ``film_n`` (if given), the derivatives with respect to its
    thickness (per nm), the real and the imaginary part of its index. With
    ``film_n`` that index is also the coating's exit medium (``n_exit`` is not
    read). The base medium and the ambient are not parameters.

    Reverse-mode AD (float64, LLVM backend) of ``Σ_λ Σ_μ w_μ R_up(μ, λ)``, the
    coating's films visited by a loop (:func:`unpolarized.unpolarized_rt_loop`, so that
    the kernel does not grow with the films) that gathers each film's parameters
    per wavelength from buffers: the gradient of a buffer entry is the partial at
    that wavelength. Wavelengths are taken in blocks of
    :data:`PARTIALS_LANE_FILMS` lanes x films (the loop's stored state). The clamps
    of :func:`hemispherical_factors` act only at rounding level and are not
    differentiated; a node exactly at a film's critical angle (an infinite
    derivative of a square root, a set of measure zero) contributes 0.
    """
    require_llvm()
    mu, weight = _rule(nodes)
    wavelengths = np.asarray(wavelengths, np.float64)
    nw = wavelengths.size

    def on(v):
        return np.broadcast_to(np.asarray(v), (nw,))
    coating = [(on(n), float(d)) for n, d in coating]
    film_n = None if film_n is None else (on(film_n[0]), float(film_n[1]))
    n_amb, n_exit = on(n_amb), on(n_exit)
    block = max(1, PARTIALS_LANE_FILMS // (mu.size * max(len(coating), 1)))
    out = np.zeros((PER_FILM * (len(coating) + (film_n is not None)), nw))
    for a in range(0, nw, block):
        b = slice(a, min(nw, a + block))
        block_n = None if film_n is None else (film_n[0][b], film_n[1])
        with _PARTIALS_LOCK:
            out[:, b] = _partials_block(n_amb[b], [(n[b], d) for n, d in coating], n_exit[b],
                                        block_n, wavelengths[b], mu, weight)
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0)


def _partials_block(n_amb, coating, n_exit, film_n, wavelengths, mu, weight) -> np.ndarray:
    """:func:`r_dh_partials` on one block of wavelengths."""
    from drjit.llvm.ad import Float64 as ADFloat64
    from drjit.llvm.ad import UInt32 as ADUInt32

    nw, nm, F = wavelengths.size, mu.size, len(coating)

    def lanes(values):
        return aligned_array(np.repeat(values, nm), np.float64, ADFloat64)

    def leaf(values):
        x = aligned_array(values, np.float64, ADFloat64)
        dr.enable_grad(x)
        return x

    # the loop visits the films from the side the light comes from: the reversed
    # coating (lit from the base) without film N, the coating itself over film N
    order = list(range(F)) if film_n is not None else list(range(F))[::-1]
    with dr.resume_grad():
        bufs = [leaf(np.concatenate([np.full(nw, coating[i][1]) for i in order] + [[0.0]])),
                leaf(np.concatenate([coating[i][0].real for i in order] + [[0.0]])),
                leaf(np.concatenate([coating[i][0].imag for i in order] + [[0.0]]))]
        lane_wl = ADUInt32(np.repeat(np.arange(nw, dtype=np.uint32), nm))

        def film(j):
            i = j * nw + lane_wl
            d, re, im = (dr.gather(ADFloat64, x, i) for x in bufs)
            return Cx(re, im), d

        wl = lanes(wavelengths)
        n0 = lanes(n_amb)
        cos0 = aligned_array(np.tile(mu, nw), np.float64, ADFloat64)

        def reflectance(n_in, exit_):
            if F == 0:
                return unpolarized_rt(n_in, cos0, [], exit_, wl, transmission=False)
            return unpolarized_rt_loop(n_in, cos0, ADUInt32(F), film, exit_, wl,
                                       transmission=False, max_iterations=F)
        if film_n is None:
            R_up = reflectance(lanes(n_exit.real), Cx(n0, 0.0))
            last = []
        else:
            last = [leaf(np.full(nw, film_n[1])), leaf(film_n[0].real), leaf(film_n[0].imag)]
            d_f = dr.gather(ADFloat64, last[0], lane_wl)
            n_f = Cx(dr.gather(ADFloat64, last[1], lane_wl), dr.gather(ADFloat64, last[2], lane_wl))
            k_a = film_attenuation(n0, cos0, n_f, d_f, wl)
            R_up = reflectance(n0, n_f) * k_a * k_a
        w = aligned_array(np.tile(weight, nw), np.float64, ADFloat64)
        dr.backward(dr.sum(R_up * w))
        grads = [np.array(dr.grad(x), np.float64) for x in bufs + last]
    out = np.zeros((PER_FILM * (F + len(last) // PER_FILM), nw))
    for pos, i in enumerate(order):           # back to the coating's order
        for p in range(PER_FILM):
            out[PER_FILM * i + p] = grads[p][pos * nw:(pos + 1) * nw]
    for p, g in enumerate(grads[PER_FILM:]):
        out[PER_FILM * F + p] = g
    return out


class DerivativeTable:
    """:func:`r_dh_partials` on the 1 nm grid (``GRID``) as a float texture
    (linear in ``λ``, as the ``R_dh`` it differentiates), for the render kernel."""

    def __init__(self, partials: np.ndarray):
        self.texture = linear_texture(partials.T)

    def tangent(self, wavelengths, carriers: dict, active=True):
        """``Σ_p ∂R_dh/∂x_p (λ) c_p`` at ``wavelengths`` (``mi.UnpolarizedSpectrum``,
        nm), with ``carriers`` mapping a parameter's row ``p`` to ``c_p = x_p -
        detach(x_p)`` (``mi.UnpolarizedSpectrum``: 0 in value, carrying the
        parameter's gradient): added to ``R_dh``, it gives ``R_dh`` its derivatives."""
        import mitsuba as mi
        out = []
        for k in range(dr.size_v(mi.UnpolarizedSpectrum)):
            row = self.texture.eval(mi.Point1f(grid_coordinate(wavelengths[k])), active)
            term = 0.0
            for p, c in carriers.items():
                term = term + row[p] * c[k]
            out.append(term)
        return mi.UnpolarizedSpectrum(*out)


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
                u = interleave(u, mid, 0)
                values = interleave(values, v_mid, 0)
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
