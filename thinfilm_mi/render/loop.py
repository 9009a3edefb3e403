"""The films of a stack as buffers in the render kernel: :class:`LoopFilms` packs
each film's index (on the union of the films' knots) and thickness into buffers that
one symbolic Dr.Jit loop visits, so the kernel and its compile time do not grow with
the number of films. A side of fewer than
:data:`~thinfilm_mi.optics.unpolarized.LOOP_MIN_FILMS` films reads the same buffers
film by film, unrolled (no loop state to carry, each film's code scheduled with its
neighbours').
"""
from __future__ import annotations

import sys

import drjit as dr
import numpy as np

from thinfilm_mi.optics.core import (
    UNBOUNDED,
    Cx,
    clip_transmittance,
    film_bounds,
    incidence,
    phase_factor,
    real_loop_applies,
    stack_rt,
)
from thinfilm_mi.optics.unpolarized import LOOP_MIN_FILMS, unpolarized_rt_loop
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.textures import GRID, mitsuba_module, scalar, texture_on_grid

__all__ = ["LoopFilms"]


class LoopFilms:
    """The films of one side as kernel buffers for :func:`optics.stack_rt_loop`.

    Every film's ``eta`` and ``k`` are evaluated on the union of the films' knots
    (:attr:`SpectralIndex.knots`: the 1 nm grid and the datasets' own knots), where
    each film's data are piecewise linear (:meth:`SpectralIndex.data_on`: a dataset's
    own interpolation, also where its textures hold a resampling of it), so linear
    interpolation on that grid reproduces the data up to float32 rounding.
    One buffer holds, per film and grid cell, ``(eta_i, eta_i+1)`` or, where
    some film absorbs, ``(eta_i, k_i, eta_i+1, k_i+1)``: one gather per film and
    wavelength. The cell and weight of each wavelength are found once, before
    the loop. Thicknesses are a buffer and the film count an opaque integer, so
    neither a thickness sweep nor another depth of stack recompiles the kernel;
    the grid size and whether the films absorb are baked in.
    """

    #: Knots a bin of the cell lookup may hold strictly inside it (see :meth:`_bins`)
    BIN_KNOTS = 2
    #: Finest bins of the cell lookup, per nanometre (a power of two: bin edges exact in
    #: float32); a grid with more knots in a bin this narrow is searched (binary search)
    MAX_BINS_PER_NM = 4

    def __init__(self, films: list, n0: SpectralIndex, exit_: SpectralIndex | None = None):
        mi = mitsuba_module()
        from thinfilm_mi.optics.backend import aligned_array
        grid = np.unique(np.concatenate([GRID[[0, -1]]] + [ix.knots for ix, _, _ in films]))
        self.g0 = float(grid[0])
        self.cells = grid.size - 1
        self.uniform = bool(np.array_equal(grid, GRID))
        eta, k = (np.stack(parts) for parts in zip(*(ix.data_on(grid) for ix, _, _ in films)))
        self.real = bool(np.all(k == 0))
        #: per film: no absorption on the grid
        self.lossless = [bool(np.all(kj == 0)) for kj in k]
        #: Trace-time bounds (see optics.stack_rt_loop): films' smallest real
        #: index (where none absorbs) and the ambient's largest index.
        self.film_n_min = float(eta.min()) if self.real else None
        self.film_n_max = float(eta.max())
        # the media's indices on the grid, read once: the ambient's, and the exit's
        # where it is real (None where it absorbs, or there is none)
        self.n0_max = float(np.max(texture_on_grid(n0.eta)))
        exit_eta = (texture_on_grid(exit_.eta) if exit_ is not None
                    and not np.any(texture_on_grid(exit_.k)) else None)
        #: The ambient's index does not depend on the wavelength: with constant
        #: films, ``q`` and the Fresnel amplitudes are then one per lane.
        self.n0_constant = n0.knots is not None and n0.knots.size == 0
        #: The loop will run optics.stack_rt_loop_real (real amplitudes).
        self.real_steps = real_loop_applies(self.n0_max, self.film_n_min)
        #: ``R`` of one such film over ``exit_`` in closed form (:meth:`_one_film_reflectance`):
        #: the exit medium is real, its index nowhere below the ambient's (real ``q``)
        self.airy = (self.real_steps and len(films) == 1 and exit_eta is not None
                     and float(np.min(exit_eta)) >= self.n0_max)
        #: Trace-time bounds of each film's index (and the exit's, where real) for the
        #: unrolled recursion (optics.stack_rt): a real root, no q = 0 guard where they allow
        self.bounds = [film_bounds(float(e.min()), float(e.max()), float(kj.min()),
                                   float(kj.max()), self.n0_max) for e, kj in zip(eta, k)]
        self.exit_bounds = UNBOUNDED if exit_eta is None else film_bounds(
            float(exit_eta.min()), float(exit_eta.max()), 0.0, 0.0, self.n0_max)
        #: Every film's index is one constant (no knots: a single grid cell): one
        #: real per film, gathered once per lane for all the wavelengths.
        self.constant = self.real and self.cells == 1
        if self.constant:
            cols = [eta[:, 0]]
        elif self.real:
            cols = [eta[:, :-1], eta[:, 1:]]
        else:
            cols = [eta[:, :-1], k[:, :-1], eta[:, 1:], k[:, 1:]]
        self.buffer = aligned_array(np.stack(cols, axis=-1), np.float32, mi.Float)
        self.grid = aligned_array(grid, np.float32, mi.Float)
        # A non-uniform grid (the 1 nm grid and the datasets' knots): per bin of a
        # uniform grid, its first cell and the knots inside it (else a binary search).
        self.bins = None if self.uniform else self._bins(grid.astype(np.float32))
        self.thickness = aligned_array([scalar(d) for _, d, _ in films], np.float32, mi.Float)
        self.n_films = len(films)
        self.count = mi.UInt32(len(films))
        for v in (self.buffer, self.grid, self.thickness, self.count, self.bins):
            if v is not None:
                dr.make_opaque(v)

    def _bins(self, g32: np.ndarray):
        """The cell lookup of a non-uniform grid (knots ``g32``, float32): bins of
        ``1/p`` nm from ``floor(g32[0])`` (the fewest per nanometre, ``p`` a power of two
        up to :attr:`MAX_BINS_PER_NM`, such that no bin holds more than
        :attr:`BIN_KNOTS` knots strictly inside it), each a packet of 8 floats: its
        first cell (as a float, exact below 2^24), the knots inside it (``inf`` where
        fewer), the first cell's lower knot and the inverse widths of the cells it
        touches. One gather per wavelength then finds the cell and its weight, where
        a search walked the knots gather by gather. ``None`` where no such bins exist."""
        mi = mitsuba_module()
        from thinfilm_mi.optics.backend import aligned_array
        w0 = float(np.floor(g32[0]))
        inv_width = (1.0 / np.diff(g32.astype(np.float64))).astype(np.float32)
        per_nm = 1
        while per_nm <= self.MAX_BINS_PER_NM:
            n = int(np.ceil((float(g32[-1]) - w0) * per_nm))
            edges = (w0 + np.arange(n + 1, dtype=np.float64) / per_nm).astype(np.float32)
            first = np.clip(np.searchsorted(g32, edges[:-1], side="right") - 1, 0, self.cells - 1)
            inside = np.searchsorted(g32, edges[1:], side="left") - 1 - first
            if inside.max(initial=0) <= self.BIN_KNOTS:
                break
            per_nm *= 2
        else:
            return None
        packet = np.zeros((n, 8), np.float32)
        packet[:, 0] = first
        packet[:, 3] = g32[first]
        for k in range(self.BIN_KNOTS + 1):
            cell = np.minimum(first + k, self.cells - 1)
            if k:
                packet[:, k] = np.where(inside >= k, g32[np.minimum(first + k, g32.size - 1)],
                                        np.inf)
            packet[:, 4 + k] = inv_width[cell]
        self.w0, self.per_nm, self.last_bin = w0, float(per_nm), float(n - 1)
        #: the dynamic array type of Mitsuba's backend (one packet gather of 8 floats)
        self.packet_type = sys.modules[mi.Float.__module__].ArrayXf
        return aligned_array(packet, np.float32, mi.Float)

    def _cell(self, w):
        """The grid cell holding wavelength ``w`` (an ``mi.Float``) and the weight of its
        upper knot."""
        mi = mitsuba_module()
        if self.uniform:   # knots 1 nm apart from an integer start: exact arithmetic
            i = mi.UInt32(dr.clip(dr.floor(w - self.g0), 0.0, float(self.cells - 1)))
            return i, dr.clip(w - (self.g0 + mi.Float(i)), 0.0, 1.0)
        if self.bins is not None:
            b = mi.UInt32(dr.clip(dr.floor((w - self.w0) * self.per_nm), 0.0, self.last_bin))
            p = dr.gather(self.packet_type, self.bins, b, shape=(8, dr.width(b)))
            lo, inv, i = p[3], p[4], mi.UInt32(p[0])
            for k in range(1, self.BIN_KNOTS + 1):   # past the bin's k-th inner knot
                past = w >= p[k]
                lo, inv = dr.select(past, p[k], lo), dr.select(past, p[4 + k], inv)
                i += mi.UInt32(past)
            return i, dr.clip((w - lo) * inv, 0.0, 1.0)
        i = dr.binary_search(0, self.cells - 1,
                             lambda c: dr.gather(mi.Float, self.grid, c + 1) <= w)
        lo = dr.gather(mi.Float, self.grid, i)
        hi = dr.gather(mi.Float, self.grid, i + 1)
        return i, dr.clip((w - lo) / (hi - lo), 0.0, 1.0)

    def rt(self, n0, cos_theta, exit_: Cx, wl, transmission: bool, thickness_scale,
           evaluator=unpolarized_rt_loop, unrolled=None):
        """``evaluator(n0, cos, count, film, n_exit, wl, transmission, **hints)`` over
        these films: the powers (:func:`unpolarized.unpolarized_rt_loop`) or, in
        polarized variants, the amplitudes (:func:`optics.mueller.loop_amplitudes`).
        Fewer than :data:`~thinfilm_mi.optics.unpolarized.LOOP_MIN_FILMS` films are
        unrolled: ``unrolled(n0, cos, films, n_exit, wl, transmission)`` over the
        gathered films (the amplitudes: :func:`optics.stack_amplitudes`), or by
        default the powers (:meth:`_unrolled_powers`)."""
        mi = mitsuba_module()
        if self.constant:
            if self.n0_constant:
                n0 = n0[0]

            def film(j):
                j = mi.UInt32(j) if isinstance(j, int) else j
                d = dr.gather(mi.Float, self.thickness, j)
                return (Cx(dr.gather(mi.Float, self.buffer, j), 0.0),
                        d if thickness_scale is None else d * thickness_scale)
            return self._rt(film, n0, cos_theta, exit_, wl, transmission, evaluator, unrolled)

        cells = [self._cell(wl[c]) for c in range(len(wl))]
        vec = mi.Vector2f if self.real else mi.Vector4f

        def film(j):
            d = dr.gather(mi.Float, self.thickness, mi.UInt32(j) if isinstance(j, int) else j)
            return (self._index(cells, vec, j),
                    d if thickness_scale is None else d * thickness_scale)

        return self._rt(film, n0, cos_theta, exit_, wl, transmission, evaluator, unrolled)

    def _index(self, cells, vec, j):
        """Film ``j``'s index at the wavelengths of ``cells``; ``j`` an index array, or
        a Python int (unrolled: a film without absorption then has a literal zero
        imaginary part, which the recursion specialises on)."""
        mi = mitsuba_module()
        real = self.real or (isinstance(j, int) and self.lossless[j])
        base = (mi.UInt32(j) if isinstance(j, int) else j) * self.cells
        eta, k = [], []
        for i, t in cells:
            v = dr.gather(vec, self.buffer, base + i)
            if self.real:
                eta.append(dr.lerp(v[0], v[1], t))
            else:
                eta.append(dr.lerp(v[0], v[2], t))
                k.append(dr.lerp(v[1], v[3], t))
        U = mi.UnpolarizedSpectrum
        return Cx(U(*eta), 0.0 if real else U(*k))

    def index(self, wl, j=0) -> Cx:
        """Film ``j``'s index at the wavelengths ``wl`` (one search per wavelength, one
        gather per film and wavelength), what its textures give up to float32 rounding:
        e.g. ``thinfilm_diffuse``'s absorbing film ``N`` (``render/layered/series.py``)."""
        mi = mitsuba_module()
        if self.constant:
            return Cx(mi.UnpolarizedSpectrum(dr.gather(mi.Float, self.buffer, mi.UInt32(j))), 0.0)
        return self._index([self._cell(wl[c]) for c in range(len(wl))],
                           mi.Vector2f if self.real else mi.Vector4f,
                           mi.UInt32(j) if isinstance(j, int) else j)

    def _rt(self, film, n0, cos_theta, exit_: Cx, wl, transmission: bool, evaluator, unrolled):
        if self.n_films >= LOOP_MIN_FILMS:
            return evaluator(n0, cos_theta, self.count, film, exit_, wl, transmission,
                             n0_max=self.n0_max, film_n_min=self.film_n_min,
                             film_n_max=self.film_n_max, films_max=self.n_films)
        if unrolled is not None:
            films = [film(j) for j in range(self.n_films)]
            return unrolled(n0, cos_theta, films, exit_, wl, transmission)
        return self._unrolled_powers(film, n0, cos_theta, exit_, wl, transmission)

    def _unrolled_powers(self, film, n0, cos_theta, exit_: Cx, wl, transmission: bool):
        """The unpolarized ``R`` [, ``T``] of these few films, unrolled: film ``j``
        gathered at a literal ``j`` (the buffers stay kernel inputs: an edit of an
        index or a thickness does not recompile). Real films above the ambient run
        the real-amplitude steps (:func:`optics.stack_rt_loop_real`, a Python
        ``count`` unrolls its loop); others the power form of the recursion
        (:func:`optics.stack_rt`: ``|T|^2`` carried as a power, no transmission
        amplitude), as :func:`~thinfilm_mi.optics.unpolarized.unpolarized_rt_loop`
        forms ``R`` and ``T`` from it."""
        if self.airy and not transmission:
            return self._one_film_reflectance(film, n0, cos_theta, exit_, wl)
        if self.real_steps:
            return unpolarized_rt_loop(n0, cos_theta, self.n_films, film, exit_, wl, transmission,
                                       n0_max=self.n0_max, film_n_min=self.film_n_min,
                                       film_n_max=self.film_n_max, films_max=self.n_films)
        films = [film(j) for j in range(self.n_films)]
        Rs, Rp, Ts, Tp = stack_rt(n0, cos_theta, films, exit_, wl, transmission=transmission,
                                  bounds=self.bounds, n0_max=self.n0_max,
                                  exit_bounds=self.exit_bounds)
        R = 0.5 * (Rs + Rp)
        if not transmission:
            return R
        return R, clip_transmittance(0.5 * (Ts + Tp), R)

    def _one_film_reflectance(self, film, n0, cos_theta, exit_: Cx, wl):
        """``R`` of one real film (index above the ambient's) on a real exit medium of
        index at least the ambient's (:attr:`airy`): every ``q`` is real, so are the
        Fresnel amplitudes ``r01``, ``r12`` of both interfaces, and per polarisation
        the film's reflectance is the Airy sum in closed form

            R = (r01^2 + r12^2 + 2 r01 r12 cos 2δ) / (1 + r01^2 r12^2 + 2 r01 r12 cos 2δ)

        (``|r01 + r12 E|^2 / |1 + r01 r12 E|^2`` with ``E = exp(2iδ)``, ``2δ = 4π q1 d /
        λ``): the recursion's value with no complex arithmetic. With ``r01 = A / B`` and
        ``r12 = C / D`` both numerator and denominator are multiplied by ``(B D)^2``, and
        the two polarisations' ``R`` are added over one product of denominators: one
        division per wavelength (where six were). The denominator is at least ``(1 -
        |r01 r12|)^2 (B D)^2 > 0`` (``|r12| < 1``). At grazing incidence ``r01 = -1`` and
        ``R = 1``."""
        cos0, beta2, q0 = incidence(n0, cos_theta)
        (m, d), = [film(0)]
        n1 = m.re
        n2 = exit_.re
        n0_2, n1_2, n2_2 = n0 * n0, n1 * n1, n2 * n2
        q1 = dr.sqrt(dr.maximum(n1_2 - beta2, 0.0))
        q2 = dr.sqrt(dr.maximum(n2_2 - beta2, 0.0))
        c = phase_factor(Cx(q1, 0.0), d / wl, True).re
        terms = []
        for a0, a1, b1, b2 in ((q0, q1, q1, q2),                       # s: q
                               (q0 * n1_2, q1 * n0_2, q1 * n2_2, q2 * n1_2)):  # p: q / n^2, scaled
            # r01 = A / B, r12 = C / D: numerator and denominator times (B D)^2
            A, B, C, D = a0 - a1, a0 + a1, b1 - b2, b1 + b2
            AD, CB = A * D, C * B
            b = 2.0 * (AD * CB) * c
            terms.append((dr.fma(AD, AD, dr.fma(CB, CB, b)),
                          dr.fma(B * D, B * D, dr.fma(A * C, A * C, b))))
        # R_s + R_p over one division: each denominator lies in [(1 - |r01 r12|)^2,
        # (1 + |r01 r12|)^2] (B D)^2 with B, D >= q1 > 0 and |q| <= n: far inside float32
        (num_s, den_s), (num_p, den_p) = terms
        R = dr.fma(num_s, den_p, num_p * den_s) / (den_s * den_p)
        return dr.select(cos0 <= 0.0, 1.0, dr.minimum(0.5 * R, 1.0))
