"""The smooth amplitudes of a band-limited row's first level (:mod:`thinfilm_mi.tabulate.band_rows`):
their evaluation in float64 (:func:`amplitudes`, ``R = |N|²/|D|²``), the powers from
them (:func:`powers_of`), the resonances they reveal as zeros of ``D`` near the real
axis (:func:`near_zeros`), and their interpolation between the samples
(:class:`Amplitudes`), which the adaptive panels read instead of the films.
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from thinfilm_mi.optics.core import COMPONENTS, Cx
from thinfilm_mi.tabulate.base import SideData, film_gather

__all__ = ["GRADING", "INTERPOLATION_NODES", "RESOLVE_DISTANCE", "Amplitudes", "amplitudes",
           "near_zeros", "powers_of", "samples_amplitudes"]

#: Panels near a zero ``z_p`` of the resonant denominator ``D`` are at most this
#: times their distance to it (:class:`_Resonances`): Simpson's error estimate
#: alone misses or mis-measures resonances a few samples wide (measured on the
#: 10-film stack: with 1, panels of 16 bins on the flank of a resonance 30 bins
#: wide erred by 1e-2 in area, R_σ by 1e-3).
GRADING = 0.5
#: Zeros farther from the axis than this many first-level samples ask nothing
#: of the first panels (two samples wide).
RESOLVE_DISTANCE = 2.0 / GRADING

#: Nodes of the interpolation of the first level's amplitudes (:class:`Amplitudes`):
#: a quintic through 6 samples 32 or more per fringe errs by ~1e-7 of the
#: amplitudes' scale (the cubic's ~2e-5 would move narrow resonances' areas).
INTERPOLATION_NODES = 6


class Amplitudes:
    """The first level's smooth amplitudes (:func:`amplitudes`, or a quantity's
    ``smooth_terms``) of a set of rows, interpolated along the wavenumber: the
    values (``R`` [, ``T``] or the quantity's channels) at any point between
    the samples, at the cost of a polynomial instead of the films' loop.

    ``N`` and ``D`` are smooth where ``R`` has resonances, made of the
    interference terms of the stack's optical paths; sampled 32 or more times per
    fringe of the longest (:func:`first_step`), the quintic through the six samples
    around a point (Lagrange, :data:`INTERPOLATION_NODES`) gives them within ~1e-7
    of their scale. A resonance is a zero of ``D`` near the axis: an error ``ε`` of
    ``D`` moves it by ``ε / |D'|``, which changes the area of a resonance of half
    width ``d`` by a fraction ``~ε |D| / (|D'| d)`` (~1e-3 at the narrowest,
    :data:`MIN_PANEL`). The samples' power-of-two rescaling (``exponents``) is undone
    in units of their row's largest exponent, exactly (rows whose exponents spread
    over more than :data:`MAX_RANGE` are refined with the films instead)."""

    def __init__(self, terms: np.ndarray, exps: np.ndarray, cos: np.ndarray, quantity,
                 transmission: bool):
        R, P, K = terms.shape
        self.P, self.K, self.cos = P, K, cos
        self.quantity, self.transmission = quantity, transmission
        # the samples in units of 2^(their row's largest exponent), exact powers
        # of two: the amplitudes of s (channels 0-3) and p (4-7) once, the powers'
        # |T|^2 f (8, 9) twice (a quantity's exponents are 0); a row's range of
        # exponents is checked by :meth:`usable`
        shift = exps - exps.max(axis=1, keepdims=True)
        self.range = float(-shift.min()) if shift.size else 0.0
        flat = np.ascontiguousarray(terms, np.float64).reshape(R * P, K)   # the caller's, in place
        if self.range:
            scale = np.exp2(shift.reshape(R * P, 2))
            flat[:, 0:4] *= scale[:, 0:1]
            flat[:, 4:8] *= scale[:, 1:2]
            if quantity.squared_terms and K > 8:
                flat[:, 8:10] *= scale * scale
        self.flat = flat
        self._buffer = None

    #: Largest spread of a row's exponents (powers of two) the common unit
    #: may absorb: their squares stay far above float64's smallest normal.
    MAX_RANGE = 400.0

    def usable(self) -> bool:
        """Whether the samples' exponents are within :data:`MAX_RANGE` along every row."""
        return self.range <= self.MAX_RANGE

    def values(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The values (shape ``(points, C)``) at rows ``r`` and sample coordinates
        ``s`` (fractional indices of the first level's samples)."""
        from drjit.llvm import Float64, UInt32

        from thinfilm_mi.optics.backend import aligned_array, float64_array

        n, P, K = INTERPOLATION_NODES, self.P, self.K
        i0 = np.clip(np.floor(s).astype(np.int64) - (n // 2 - 1), 0, P - n)
        if self._buffer is None:      # one kernel for every stack of K channels
            self._buffer = float64_array(self.flat.ravel())
        x = float64_array(s - i0)
        at = aligned_array((r * P + i0) * K, np.uint32, UInt32)
        out = [Float64(0.0)] * K
        for k in range(n):
            w = Float64(1.0)
            for m in range(n):
                if m != k:
                    w = w * ((x - m) * (1.0 / (k - m)))
            for c in range(K):
                out[c] = dr.fma(w, dr.gather(Float64, self._buffer, at + (k * K + c)), out[c])
        dr.eval(*out)
        out = np.stack([np.array(v, dtype=np.float64) for v in out], axis=-1)
        q, tr = self.quantity, self.transmission
        f = q.values(out, tr)
        grazing = q.grazing(tr)
        near = np.clip(np.rint(s).astype(np.int64), 0, P - 1)
        return np.where((self.cos.reshape(-1)[r * P + near] <= 0.0)[:, None], grazing, f)


def samples_amplitudes(side: SideData) -> bool:
    """Whether the first level samples the amplitudes (:func:`amplitudes`): every
    coherent side with films (sides with incoherent films, whose evaluator has no
    such amplitudes, are sampled without the resonance search)."""
    return 0 < len(side.films) == len(side.fringe_films)


def amplitudes(side: SideData, cos0: np.ndarray, rows: np.ndarray, wl: np.ndarray,
               indices) -> tuple[np.ndarray, np.ndarray]:
    """The stack's projective amplitudes at points ``(cos0[i], wl[rows[i]])``:
    ``(terms, exponents)``, ``terms`` of shape ``(points, C)`` with channels
    ``Re, Im`` of ``N_s, D_s, N_p, D_p`` and, with transmission, ``|T_s|^2 f_s,
    |T_p|^2 f_p`` (``R = |N|^2 / |D|^2``, ``T = |T|^2 f / |D|^2``), and
    ``exponents`` of shape ``(points, 2)`` (s, p): ``N 2^E``, ``D 2^E`` are smooth
    functions of λ without the resonant denominator ``1 / D``, so a few nodes per
    fringe interpolate them where ``R`` itself would need hundreds.

    The films' loop of the render kernels in float64
    (:func:`thinfilm_mi.optics.core.stack_loop_terms` with ``smooth``: its
    power-of-two rescaling keeps every depth within range, and the exponents it
    sums undo it), the films gathered per point's row."""
    from drjit.llvm import Float64, UInt32

    from thinfilm_mi.optics import core as op
    from thinfilm_mi.optics.backend import aligned_array, float64_array

    n0, film_n, n_exit = indices
    film_n = [np.asarray(n, np.complex128) for n in film_n]
    n_exit = np.asarray(n_exit, np.complex128)
    at = aligned_array(rows, np.uint32, UInt32)

    def per_row(values):
        return dr.gather(Float64, float64_array(values), at)

    real = not any(np.any(n.imag) for n in film_n)
    re = np.concatenate([n.real for n in film_n])
    film = film_gather(film_n, [d for _, d in side.films], at, len(wl), real)
    exit_cx = Cx(per_row(n_exit.real), per_row(n_exit.imag) if np.any(n_exit.imag) else 0.0)
    terms, fac, grazing = op.stack_loop_terms(
        per_row(n0), float64_array(cos0), dr.opaque(UInt32, len(film_n), len(rows)), film,
        exit_cx, per_row(wl), transmission=side.transmission, n0_max=float(np.max(n0)),
        film_n_min=float(re.min()) if real else None, label="thinfilm_band", exponents=True,
        smooth=True)
    out = []
    for pol in COMPONENTS:
        N, D, _, _ = terms[pol]
        out += [N.re, N.im, D.re, D.im]
    if side.transmission:
        out += [dr.select(grazing, 0.0, terms[pol][2] * fac[pol]) for pol in COMPONENTS]
    exps = [terms[pol][3] for pol in COMPONENTS]
    dr.eval(*out, *exps)
    return (np.stack([np.array(v, dtype=np.float64) for v in out], axis=-1),
            np.stack([np.array(v, dtype=np.float64) for v in exps], axis=-1))


def powers_of(terms: np.ndarray, transmission: bool) -> np.ndarray:
    """``R`` [, ``T``] (last axis) from :func:`amplitudes` channels (any leading shape)."""
    Ns = terms[..., 0] ** 2 + terms[..., 1] ** 2
    Ds = terms[..., 2] ** 2 + terms[..., 3] ** 2
    Np = terms[..., 4] ** 2 + terms[..., 5] ** 2
    Dp = terms[..., 6] ** 2 + terms[..., 7] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        R = np.minimum(0.5 * (Ns / Ds + Np / Dp), 1.0)
        if not transmission:
            return R[..., None]
        T = 0.5 * (terms[..., 8] / Ds + terms[..., 9] / Dp)
    R = np.where(np.isfinite(R), R, 1.0)
    T = np.clip(np.where(np.isfinite(T), T, 0.0), 0.0, 1.0 - R)
    return np.stack([R, T], axis=-1)


def near_zeros(samples: np.ndarray, channel: int, exponents: np.ndarray | None = None) -> tuple:
    """Zeros of the complex function ``samples[..., channel] + i samples[...,
    channel + 1]`` (shape ``(rows, n, K)``, smooth on the samples' scale) near the
    real axis: ``(row, position, distance)`` arrays, position a sample
    coordinate, distance from the axis in sample steps, for the zeros within
    :data:`RESOLVE_DISTANCE` steps.

    A zero at ``x_p + i d`` makes ``|f|²`` a bowl ``∝ (x - x_p)² + d²`` along the
    axis, so only the samples where ``|f|²`` has a local minimum are examined:
    the cubic through the four samples around it is solved by Newton's method
    (8 steps from the minimum). With ``exponents`` (shape ``(rows, n)``) the
    function is ``f 2^exponents`` (:func:`amplitudes`): neighbours are compared,
    and the cubic fitted, in units of ``2^`` the middle sample's exponent (exact
    powers of two, so the result does not depend on the exponents' split)."""
    f = samples[..., channel] + 1j * samples[..., channel + 1]
    a2 = f.real * f.real + f.imag * f.imag
    n = a2.shape[1]
    before, here, after = a2[:, 0:n - 3], a2[:, 1:n - 2], a2[:, 2:n - 1]
    if exponents is not None:     # neighbours in units of 2^(the sample's exponent): exact
        e = exponents[:, 1:n - 2]
        before = before * np.exp2(2.0 * (exponents[:, 0:n - 3] - e))
        after = after * np.exp2(2.0 * (exponents[:, 2:n - 1] - e))
    low = (here <= before) & (here < after)
    r, i = np.nonzero(low)
    i = i + 1                                   # the minimum's sample, 1 .. n - 3
    f0, f1, f2, f3 = f[r, i - 1], f[r, i], f[r, i + 1], f[r, i + 2]
    if exponents is not None:     # the window in units of 2^(its minimum's exponent)
        e = exponents[r, i]
        f0, f2, f3 = (fk * np.exp2(exponents[r, i + k] - e) for fk, k in ((f0, -1), (f2, 1), (f3, 2)))
    # the cubic through (-1.5, f0), (-0.5, f1), (0.5, f2), (1.5, f3)
    b0 = (-f0 + 9.0 * (f1 + f2) - f3) / 16.0
    b1 = (f0 - 27.0 * f1 + 27.0 * f2 - f3) / 24.0
    b2 = (f0 - f1 - f2 + f3) / 4.0
    b3 = (-f0 + 3.0 * f1 - 3.0 * f2 + f3) / 6.0
    z = np.full(b0.shape, -0.5, np.complex128)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(8):
            z = z - (((b3 * z + b2) * z + b1) * z + b0) / ((3.0 * b3 * z + 2.0 * b2) * z + b1)
        scale = np.abs(b0) + np.abs(b1) + np.abs(b2) + np.abs(b3)
        ok = (np.isfinite(z) & (np.abs(((b3 * z + b2) * z + b1) * z + b0) <= 1e-6 * scale)
              & (np.abs(z.real + 0.5) <= 2.0) & (np.abs(z.imag) < RESOLVE_DISTANCE))
    return r[ok], (i + 0.5 + z.real)[ok], np.abs(z.imag)[ok]
