"""The films of a deep stack as a loop in the render kernel: :class:`LoopFilms` packs
each film's index (on the union of the films' knots) and thickness into buffers that
one symbolic Dr.Jit loop visits, so the kernel and its compile time do not grow with
the number of films.
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from thinfilm_mi.optics.core import Cx, real_loop_applies
from thinfilm_mi.optics.unpolarized import unpolarized_rt_loop
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.textures import GRID, mitsuba_module, scalar, texture_on_grid

__all__ = ["LoopFilms"]


class LoopFilms:
    """The films of one side as kernel buffers for :func:`optics.stack_rt_loop`.

    Every film's ``eta`` and ``k`` are evaluated through its textures on the
    union of the films' knots (:attr:`SpectralIndex.knots`: the 1 nm grid and
    the datasets' own knots), where each texture is piecewise linear, so linear
    interpolation on that grid reproduces the texture up to float32 rounding.
    One buffer holds, per film and grid cell, ``(eta_i, eta_i+1)`` or, where
    some film absorbs, ``(eta_i, k_i, eta_i+1, k_i+1)``: one gather per film and
    wavelength. The cell and weight of each wavelength are found once, before
    the loop. Thicknesses are a buffer and the film count an opaque integer, so
    neither a thickness sweep nor another depth of stack recompiles the kernel;
    the grid size and whether the films absorb are baked in.
    """

    #: Knots a wavelength may lie beyond its whole nanometre's first cell (the cell
    #: search's steps, in place of a binary search over the union of the knots)
    SKIP = 2

    def __init__(self, films: list, n0: SpectralIndex):
        mi = mitsuba_module()
        from thinfilm_mi.optics.backend import aligned_array
        grid = np.unique(np.concatenate([GRID[[0, -1]]] + [ix.knots for ix, _, _ in films]))
        self.g0 = float(grid[0])
        self.cells = grid.size - 1
        self.uniform = bool(np.array_equal(grid, GRID))
        eta = np.stack([texture_on_grid(ix.eta, grid) for ix, _, _ in films])
        k = np.stack([texture_on_grid(ix.k, grid) for ix, _, _ in films])
        self.real = bool(np.all(k == 0))
        #: Trace-time bounds (see optics.stack_rt_loop): films' smallest real
        #: index (where none absorbs) and the ambient's largest index.
        self.film_n_min = float(eta.min()) if self.real else None
        self.film_n_max = float(eta.max())
        self.n0_max = float(np.max(texture_on_grid(n0.eta)))
        #: The ambient's index does not depend on the wavelength: with constant
        #: films, ``q`` and the Fresnel amplitudes are then one per lane.
        self.n0_constant = n0.knots is not None and n0.knots.size == 0
        #: The loop will run optics.stack_rt_loop_real (real amplitudes).
        self.real_steps = real_loop_applies(self.n0_max, self.film_n_min)
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
        # A non-uniform grid (the 1 nm grid and the datasets' knots): the first cell of
        # each whole nanometre, from which a wavelength is at most SKIP knots further
        # (checked here; else a binary search).
        g32 = grid.astype(np.float32)
        whole = np.floor(g32[0]) + np.arange(int(np.ceil(g32[-1] - np.floor(g32[0]))) + 1)
        first = np.clip(np.searchsorted(g32, whole, side="right") - 1, 0, self.cells - 1)
        ahead = np.searchsorted(g32, whole + 1.0, side="left") - 1 - first
        self.start = None
        if not self.uniform and ahead.max(initial=0) <= self.SKIP:
            self.w0 = float(whole[0])
            self.start = aligned_array(first, np.uint32, mi.UInt32)
        self.thickness = aligned_array([scalar(d) for _, d, _ in films], np.float32, mi.Float)
        self.n_films = len(films)
        self.count = mi.UInt32(len(films))
        for v in (self.buffer, self.grid, self.thickness, self.count):
            dr.make_opaque(v)

    def _cell(self, w):
        """The grid cell holding wavelength ``w`` (an ``mi.Float``) and the weight of its
        upper knot."""
        mi = mitsuba_module()
        if self.uniform:   # knots 1 nm apart from an integer start: exact arithmetic
            i = mi.UInt32(dr.clip(dr.floor(w - self.g0), 0.0, float(self.cells - 1)))
            return i, dr.clip(w - (self.g0 + mi.Float(i)), 0.0, 1.0)
        if self.start is not None:
            last = float(dr.width(self.start) - 1)
            i = dr.gather(mi.UInt32, self.start, mi.UInt32(dr.clip(dr.floor(w - self.w0), 0.0, last)))
            for _ in range(self.SKIP):
                i += mi.UInt32((i < self.cells - 1) & (dr.gather(mi.Float, self.grid, i + 1) <= w))
        else:
            i = dr.binary_search(0, self.cells - 1,
                                 lambda c: dr.gather(mi.Float, self.grid, c + 1) <= w)
        lo = dr.gather(mi.Float, self.grid, i)
        hi = dr.gather(mi.Float, self.grid, i + 1)
        return i, dr.clip((w - lo) / (hi - lo), 0.0, 1.0)

    def rt(self, n0, cos_theta, exit_: Cx, wl, transmission: bool, thickness_scale,
           evaluator=unpolarized_rt_loop):
        """``evaluator(n0, cos, count, film, n_exit, wl, transmission, **hints)`` over
        these films: the powers (:func:`unpolarized.unpolarized_rt_loop`) or, in
        polarized variants, the amplitudes (:func:`optics.mueller.loop_amplitudes`)."""
        mi = mitsuba_module()
        if self.constant:
            if self.n0_constant:
                n0 = n0[0]

            def film(j):
                d = dr.gather(mi.Float, self.thickness, j)
                return (Cx(dr.gather(mi.Float, self.buffer, j), 0.0),
                        d if thickness_scale is None else d * thickness_scale)
            return self._rt(film, n0, cos_theta, exit_, wl, transmission, evaluator)

        cells = [self._cell(wl[c]) for c in range(len(wl))]
        vec = mi.Vector2f if self.real else mi.Vector4f

        def film(j):
            d = dr.gather(mi.Float, self.thickness, j)
            return (self._index(cells, vec, j),
                    d if thickness_scale is None else d * thickness_scale)

        return self._rt(film, n0, cos_theta, exit_, wl, transmission, evaluator)

    def _index(self, cells, vec, j):
        mi = mitsuba_module()
        base = j * self.cells
        eta, k = [], []
        for i, t in cells:
            v = dr.gather(vec, self.buffer, base + i)
            if self.real:
                eta.append(dr.lerp(v[0], v[1], t))
            else:
                eta.append(dr.lerp(v[0], v[2], t))
                k.append(dr.lerp(v[1], v[3], t))
        U = mi.UnpolarizedSpectrum
        return Cx(U(*eta), 0.0 if self.real else U(*k))

    def index(self, wl, j=0) -> Cx:
        """Film ``j``'s index at the wavelengths ``wl`` (one search per wavelength, one
        gather per film and wavelength), what its textures give up to float32 rounding:
        e.g. ``thinfilm_diffuse``'s absorbing film ``N`` (``render/coated_diffuse.py``)."""
        mi = mitsuba_module()
        if self.constant:
            return Cx(mi.UnpolarizedSpectrum(dr.gather(mi.Float, self.buffer, mi.UInt32(j))), 0.0)
        return self._index([self._cell(wl[c]) for c in range(len(wl))],
                           mi.Vector2f if self.real else mi.Vector4f, j)

    def _rt(self, film, n0, cos_theta, exit_: Cx, wl, transmission: bool, evaluator):
        return evaluator(n0, cos_theta, self.count, film, exit_, wl, transmission,
                         n0_max=self.n0_max, film_n_min=self.film_n_min,
                         film_n_max=self.film_n_max, films_max=self.n_films)
