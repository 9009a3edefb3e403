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
"""
from __future__ import annotations

from typing import Sequence

import drjit as dr
import numpy as np
from drjit.llvm import Float64, UInt32

from thinfilm_mi.optics.backend import float64_array, repeated
from thinfilm_mi.llvm import require_llvm
from thinfilm_mi.optics.core import Cx, film_attenuation
from thinfilm_mi.render.kernel import LOOP_MIN_FILMS, unpolarised_rt, unpolarised_rt_loop
from thinfilm_mi.render.textures import GRID, texture_on_grid  # GRID: where the factors are tabulated

__all__ = ["GRID", "texture_on_grid", "unpolarised_rt", "hemispherical_factors"]

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
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    mu = 0.5 * (x + 1.0)          # nodes on (0, 1)
    wmu = 0.5 * w                 # weights for ∫_0^1
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
    weight = 2.0 * wmu * mu
    T_hemi = np.clip(t @ weight, 0.0, 1.0)
    R_dh = np.clip(R_up @ weight, 0.0, 1.0 - T_hemi)
    return T_hemi, R_dh


def _film_loop(coating, nw: int, nm: int):
    """``(count, film)`` for :func:`kernel.unpolarised_rt_loop` over ``coating``
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
