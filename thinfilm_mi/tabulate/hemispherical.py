"""Hemispherical (cosine-weighted) averages of a coating, for ``thinfilm_diffuse``.

The coated Lambertian BSDF needs, per wavelength, two angular integrals of the
coating between the ambient and the diffuse base:

* ``T_hemi = 2 ∫_0^1 t(μ) μ dμ`` — the fraction of the base's Lambertian
  exitance that leaves through the coating (by reciprocity ``t`` is the same
  factor that lets light in at ``μ = cos θ`` in the ambient);
* ``R_dh = 2 ∫_0^1 R_up(μ) μ dμ`` — the fraction that the coating sends back
  down onto the base (its hemispherical reflectance seen from below).

Both are computed once at load time (and again when a thickness changes) with
the float64 run of the optics core (:mod:`thinfilm_mi.optics.core` on
``drjit.llvm.Float64``) over a Gauss-Legendre rule in ``μ``, on a 1 nm grid of
wavelengths; the plugin stores them as ``regular`` spectra. Because ``T_hemi``
and ``R_dh`` use the same nodes, ``T_hemi + R_dh = 1`` holds to rounding for a
lossless coating whatever the quadrature error of each, which is what makes a
lossless coating on a white base conserve energy exactly.

Gradients (AD variants): ``R_dh`` enters the "multiple" model's value through
the series ``1/(1 - k_d R_dh)``, so its derivatives matter; ``T_hemi`` only
enters the (detached) lobe-selection probability. :func:`r_dh_partials` gives
``∂R_dh(λ)/∂x`` for every film's thickness and index (real and imaginary part),
by reverse-mode AD through the same float64 quadrature, and
:class:`DerivativeTable` holds them on the 1 nm grid for the render kernel,
which adds ``Σ_x ∂R_dh/∂x (x - detach(x))`` to ``R_dh`` where a parameter
carries gradients. ``R_dh(λ)`` depends on the indices at ``λ`` only, so the
chain rule through any index texture (a number, a dataset's values) is exact.
"""
from __future__ import annotations

import threading
from typing import Sequence

import drjit as dr
import numpy as np
from drjit.llvm import Float64, UInt32

from thinfilm_mi.llvm import require_llvm
from thinfilm_mi.materials.model import GRID  # where the factors are tabulated
from thinfilm_mi.optics.backend import aligned_array, float64_array, repeated
from thinfilm_mi.optics.core import Cx, film_attenuation
from thinfilm_mi.optics.unpolarised import LOOP_MIN_FILMS, unpolarised_rt, unpolarised_rt_loop
from thinfilm_mi.tabulate.base import grid_coordinate, linear_texture

__all__ = ["hemispherical_factors",
           "r_dh_partials", "DerivativeTable"]

#: Gauss-Legendre nodes in μ = cos θ. A 500 nm SiO2 film changes its phase by
#: about one wave over the hemisphere; 128 nodes integrate such oscillations
#: (and those of films ten times thicker) to well below 1e-6.
DEFAULT_NODES = 128


def hemispherical_factors(n_amb: np.ndarray, coating: Sequence[tuple[np.ndarray, float]],
                          n_exit: np.ndarray, film_n: tuple[np.ndarray, float] | None,
                          wavelengths: np.ndarray = GRID, nodes: int = DEFAULT_NODES):
    """``(T_hemi, R_dh)`` per wavelength (float64 numpy arrays).

    ``n_amb`` (real), the coating's film indices and ``n_exit`` are arrays over
    ``wavelengths``. Two configurations, matching ``thinfilm_diffuse``:

    * ``film_n`` is ``None``: the coating lies directly on a base medium of index
      ``n_exit`` (real). ``t = T`` of the coating and ``R_up`` is the exact
      reflectance of the reversed coating lit from the base medium.
    * ``film_n = (index, thickness)``: the paper's absorbing innermost film.
      The coating's exit medium is ``n_exit`` = that film, semi-infinite;
      ``t = k_t k_a`` and ``R_up = k_a^2 k_r`` (down and up through the film,
      and the coating reflecting equally from both sides, which is exact for
      a lossless coating and keeps ``R_up + t <= 1`` otherwise).
    """
    require_llvm()
    mu, weight = _rule(nodes)
    nw, nm = len(wavelengths), len(mu)
    wl = repeated(wavelengths, nm)
    cos0 = float64_array(np.tile(mu, nw))
    n0 = repeated(n_amb, nm)
    exit_ = repeated(n_exit, nm, complex_=True)
    if len(coating) >= LOOP_MIN_FILMS:
        # deep coatings: a loop over the films, so the kernel does not grow with them
        def rt(n0_, films, n_exit_, transmission=True):
            count, film = _film_loop(films, nw, nm)
            return unpolarised_rt_loop(n0_, cos0, count, film, n_exit_, wl, transmission)
        films = list(coating)
    else:
        def rt(n0_, films, n_exit_, transmission=True):
            return unpolarised_rt(n0_, cos0, films, n_exit_, wl, transmission)
        # opaque thicknesses: a thickness edit reuses the kernel
        films = [(repeated(n, nm, complex_=True), dr.opaque(Float64, float(d)))
                 for n, d in coating]
    R, T = rt(n0, films, exit_)
    if film_n is None:
        t = T
        R_up = rt(exit_.re, films[::-1], Cx(n0, 0.0), transmission=False)
    else:
        k_a = film_attenuation(n0, cos0, repeated(film_n[0], nm, complex_=True),
                               dr.opaque(Float64, float(film_n[1])), wl)
        t = T * k_a
        R_up = R * k_a * k_a
    dr.eval(t, R_up)
    t = np.array(t, dtype=np.float64).reshape(nw, nm)
    R_up = np.array(R_up, dtype=np.float64).reshape(nw, nm)
    T_hemi = np.clip(t @ weight, 0.0, 1.0)
    R_dh = np.clip(R_up @ weight, 0.0, 1.0 - T_hemi)
    return T_hemi, R_dh


def _rule(nodes: int):
    """Gauss-Legendre nodes ``μ`` on (0, 1) and the weights of ``2 ∫_0^1 f(μ) μ dμ``."""
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    mu = 0.5 * (x + 1.0)
    return mu, w * mu            # 2 * (w / 2) * mu


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
    coating's films visited by a loop (:func:`unpolarised.unpolarised_rt_loop`, so that
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
                return unpolarised_rt(n_in, cos0, [], exit_, wl, transmission=False)
            return unpolarised_rt_loop(n_in, cos0, ADUInt32(F), film, exit_, wl,
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


def _film_loop(coating, nw: int, nm: int):
    """``(count, film)`` for :func:`unpolarised.unpolarised_rt_loop` over ``coating``
    (``[(index over the nw wavelengths, thickness)]``) on lanes laid out as
    ``nw`` wavelengths x ``nm`` angles: each film's index is gathered per lane
    from one buffer of ``films x nw`` entries (padded: a gather needs a source)."""
    n = np.concatenate([np.asarray(ix, np.complex128) for ix, _ in coating] + [np.zeros(1)])
    eta, k = float64_array(n.real), float64_array(n.imag)
    thickness = float64_array(np.r_[[float(d) for _, d in coating], 0.0])
    lane_wl = UInt32(np.repeat(np.arange(nw, dtype=np.uint32), nm))

    def film(j):
        i = j * nw + lane_wl
        return (Cx(dr.gather(Float64, eta, i), dr.gather(Float64, k, i)),
                dr.gather(Float64, thickness, j))
    return UInt32(len(coating)), film
