"""What every table build shares: the data of a lit side of a stack, its evaluation in
float64 batches, the table axes, cubic B-splines, the lookup object and the cache.

* :class:`SideData`: a side of a stack as the builders see it (media on a
  wavelength grid, films, the float64 ``rt`` functions), and :func:`evaluate_side`,
  which evaluates ``R`` (and ``T``) at any set of (angle, wavelength) points in
  batches (looping over the films for deep stacks, whose indices
  :func:`film_gather` gathers from one buffer inside the kernel).
* Axes: the angle axis is one of :data:`~thinfilm_mi.tabulate.axes.AXES` (plain,
  split at the critical angle where the exit medium totally reflects, or warped for
  band-limited tables); :func:`v_texel` is the wavelength axis, uniform in
  wavenumber.
* Splines: :func:`bspline_coefficients` (interpolating cubic B-splines with
  :data:`GHOST` nodes), :func:`bspline_midpoints` (the values a table predicts
  between its nodes, which the builders verify against exact values).
* :class:`Table`: the float32 ``Texture2f`` a render kernel looks up, with opaque
  scale and offset constants, interpolated as one of :data:`INTERPOLATIONS` says (the
  spline's coefficients, or the spline resampled for bilinear lookups by
  :mod:`thinfilm_mi.tabulate.bilinear`); :class:`TableCache`: built tables shared by key.

The refinement shared by the builders (budget, first step, convergence order, the
linear tables' 4-point rule) is :mod:`thinfilm_mi.tabulate.refine`. The builders on
top are :mod:`thinfilm_mi.tabulate.exact` (tables of the exact values),
:mod:`thinfilm_mi.tabulate.band` (band-limited values of deep stacks),
:mod:`thinfilm_mi.tabulate.integrated` and :mod:`thinfilm_mi.tabulate.diffuse` (RGB and
mono tables) and :mod:`thinfilm_mi.tabulate.hemispherical`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from thinfilm_mi.materials.model import GRID, SPECTRAL_RANGE
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.tabulate.axes import GHOST, AngleAxis, GhostEnd

__all__ = ["BILINEAR", "BUILD_LOOP_MIN_FILMS", "BuildReport", "CUBIC", "Bilinear", "CubicSpline",
           "GRAZING_COS", "INTERPOLATIONS",
           "MAX_ROUNDS", "MAX_U", "MAX_V", "MIN_U", "MIN_V",
           "REFINE_SHARE", "SIGMA_MAX", "SIGMA_MIN", "SideData", "Table",
           "TableCache", "bspline_at", "bspline_coefficients", "bspline_weights", "bspline_midpoints",
           "evaluate_side", "film_gather", "grid_coordinate", "linear_texture", "opaque_float",
           "side_indices", "unique_wavelengths", "v_nodes_wl", "v_texel", "with_ghosts"]

SIGMA_MAX = 1.0 / SPECTRAL_RANGE[0]   # 1/nm at 360 nm
SIGMA_MIN = 1.0 / SPECTRAL_RANGE[1]   # 1/nm at 830 nm

MIN_U, MIN_V = 16, 16
MAX_U, MAX_V = 4096, 8192
#: The verification ignores incidence within ~1.1 degrees of grazing
#: (cos(theta) < GRAZING_COS). There, a dielectric film over a metal or a
#: high-index film is a cavity whose inner walls reflect almost totally (the
#: film/ambient interface is lit near its critical angle), with resonances
#: narrower than 0.5 nm that no practical table resolves; such a ray's
#: contribution to an image is a sliver at silhouettes. Tables interpolate
#: there too; benchmarks/speed_vs_error.py reports the error including it.
GRAZING_COS = 0.02
#: Builds evaluate stacks of this many films or more as a loop over the films: its
#: float64 kernel is compiled once for every depth, where an unrolled one compiles anew
#: (for most of a second) for each.
BUILD_LOOP_MIN_FILMS = 4
#: Refinement rounds after the first estimate.
MAX_ROUNDS = 6
#: A refinement aims at this share of the target (the rest is margin).
REFINE_SHARE = 0.8


@dataclass
class SideData:
    """One lighting side of a stack, with every index on the wavelength nodes.

    ``n0`` is the (real) index of the medium the light comes from, ``films``
    ``(index, thickness_nm)`` pairs from that side inwards (index: complex numpy
    array over ``wavelengths``), ``n_exit`` the complex exit index. ``rt`` is
    the evaluator ``(n0, cos0, films, n_exit, wl, transmission) -> R | (R, T)``
    (the coherent :func:`~thinfilm_mi.optics.unpolarized.unpolarized_rt` or the
    incoherent-aware one), ``transmission`` whether ``T`` is tabulated too.
    ``rt_loop``, where given, evaluates :data:`BUILD_LOOP_MIN_FILMS` films or
    more as a loop (:func:`~thinfilm_mi.optics.unpolarized.unpolarized_rt_loop`).
    ``kinks``: wavelengths where an index's slope jumps (tabulated data), at
    which the build checks the table too. ``absorbing`` (set by the builds,
    :meth:`set_absorbing`): whether each film and the exit medium absorb
    anywhere in the range, so that every evaluation of a build traces the same
    kernel whatever its wavelengths. ``quantity``: what is tabulated, one of
    :data:`~thinfilm_mi.tabulate.quantities.QUANTITIES` (the powers ``R`` [, ``T``],
    or the Mueller components of polarized variants), whose channels ``rt`` and
    ``rt_loop`` return.
    """
    n0: object                      # callable wl -> real ndarray
    films: list                     # [(callable wl -> complex ndarray, thickness)]
    n_exit: object                  # callable wl -> complex ndarray
    transmission: bool
    rt: object
    quantity: object
    fringe_films: list = field(default_factory=list)  # indices of coherent films
    rt_loop: object = None
    kinks: np.ndarray = field(default_factory=lambda: np.empty(0))
    absorbing: tuple | None = None

    def set_absorbing(self, wavelengths: np.ndarray) -> "SideData":
        """Set :attr:`absorbing` from the indices at ``wavelengths`` (whether each film and
        the exit medium absorb anywhere there); returns the side."""
        self.absorbing = (tuple(bool(np.any(np.asarray(n(wavelengths)).imag)) for n, _ in self.films)
                          + (bool(np.any(np.asarray(self.n_exit(wavelengths)).imag)),))
        return self


# -- the wavelength axis (generic over array types: Dr.Jit math) -------------------
def v_texel(wavelength, nv):
    """Node coordinate (0 .. nv-1) of a wavelength: uniform in 1/λ, 360 nm at 0
    (``nv`` a Python number or an opaque Float)."""
    return (SIGMA_MAX - 1.0 / wavelength) * ((nv - 1) * (1.0 / (SIGMA_MAX - SIGMA_MIN)))


def v_nodes_wl(t: np.ndarray, nv: int) -> np.ndarray:
    """Inverse of :func:`v_texel`; ``t`` beyond ``[0, nv-1]`` (ghost nodes) gives
    wavelengths outside 360-830 nm."""
    sigma = SIGMA_MAX + (SIGMA_MIN - SIGMA_MAX) * (np.asarray(t, np.float64) / (nv - 1))
    return 1.0 / sigma

# -- cubic B-spline coefficients ---------------------------------------------------
#: The pole of the cubic B-spline interpolation filter, ``z + 1/z = -4``.
_POLE = math.sqrt(3.0) - 2.0
#: Terms of each recursive filter kept: 2^5 = 32, |pole|^32 = 5e-19.
_POLE_STEPS = 5


def bspline_coefficients(values: np.ndarray, axis: int) -> np.ndarray:
    """Coefficients ``c`` of the clamped cubic B-spline that interpolates
    ``values`` along ``axis``: ``(c[i-1] + 4 c[i] + c[i+1]) / 6 = f[i]`` with
    ``c[-1] = c[0]`` and ``c[N] = c[N-1]`` (the clamping of
    ``Texture2f.eval_cubic`` with ``WrapMode.Clamp``).

    That system is the unbounded one for ``f`` extended by half-sample
    mirroring (its solution is then mirrored too, so ``c[-1] = c[0]``), whose
    inverse is the recursive filter pair ``c = -6 z (1 - z q^-1)^-1 (1 - z
    q)^-1 f`` (``q`` the shift, ``z`` = :data:`_POLE`; Unser, "Splines: a
    perfect fit for signal and image processing", IEEE SPM 16(6), 1999). Each
    recursion runs as :data:`_POLE_STEPS` doubling steps ``y += z^s y(i - s)``,
    ``s = 1, 2, 4, ...``: a few whole-array numpy operations instead of a loop
    over the nodes, and no SciPy (whose import costs ~0.2 s in a new process).
    """
    f = np.moveaxis(np.asarray(values, np.float64), axis, 0)
    n = f.shape[0]
    ext = 1 << _POLE_STEPS
    j = np.arange(-ext, n + ext) % (2 * n)
    y = f[np.where(j >= n, 2 * n - 1 - j, j)]
    power, s = _POLE, 1
    for _ in range(_POLE_STEPS):     # causal: y[i] = sum_k z^k f[i - k]
        y[s:] = y[s:] + power * y[:-s]
        power, s = power * power, 2 * s
    power, s = _POLE, 1
    for _ in range(_POLE_STEPS):     # anticausal: c[i] = sum_k z^k y[i + k]
        y[:-s] = y[:-s] + power * y[s:]
        power, s = power * power, 2 * s
    return np.moveaxis((-6.0 * _POLE) * y[ext:ext + n], 0, axis)


def bspline_midpoints(coeffs: np.ndarray, axis: int, g: int, n: int) -> np.ndarray:
    """The spline at the midpoints ``i + 1/2`` (``i`` = 0 .. n-2) of the ``n``
    real nodes along ``axis`` (stored after ``g`` ghost nodes)."""
    c = np.moveaxis(coeffs, axis, 0)
    k = np.arange(n - 1) + g
    mid = (c[k - 1] + 23.0 * (c[k] + c[k + 1]) + c[k + 2]) * (1.0 / 48.0)
    return np.moveaxis(mid, 0, axis)


def with_ghosts(real: np.ndarray, left, right, g: int = GHOST) -> np.ndarray:
    """``real`` (nodes along axis 0) with ``g`` ghost nodes before and after.

    An end is either an array of the ``g`` values there, in the axis's order
    (evaluated: the stack's analytic continuation), or a
    :class:`~thinfilm_mi.tabulate.axes.GhostEnd` (:data:`~thinfilm_mi.tabulate.axes.MIRROR`:
    the function is even about the end node; :data:`~thinfilm_mi.tabulate.axes.EXTRAPOLATE`:
    the cubic through the four nodes nearest the end)."""
    lo = left.outwards(real, g)[::-1] if isinstance(left, GhostEnd) else np.asarray(left)
    hi = right.outwards(real[::-1], g) if isinstance(right, GhostEnd) else np.asarray(right)
    return np.concatenate([lo, real, hi], axis=0)


def bspline_weights(f):
    """The uniform cubic B-spline's weights of the four coefficients around a cell, at the
    fraction ``f`` (a number or an array) of the cell."""
    return ((1 - f) ** 3 / 6, (3 * f ** 3 - 6 * f ** 2 + 4) / 6,
            (-3 * f ** 3 + 3 * f ** 2 + 3 * f + 1) / 6, f ** 3 / 6)


def bspline_at(coeffs: np.ndarray, t: np.ndarray, g: int) -> np.ndarray:
    """The spline with ``coeffs`` along axis 0 (node ``i`` at index ``i + g``) at
    node coordinates ``t`` (:func:`bspline_weights`)."""
    i = np.floor(t).astype(np.int64)
    f = (t - i)[(...,) + (None,) * (coeffs.ndim - 1)]
    return sum(wk * coeffs[i + g - 1 + k] for k, wk in enumerate(bspline_weights(f)))


# -- building -------------------------------------------------------------------
def opaque_float(value: float):
    """``value`` as a ``mi.Float`` that is an opaque kernel input (a plain value in scalar
    variants), so that changing it (an edit, a table of another shape) never recompiles a
    kernel."""
    import mitsuba as mi
    return dr.opaque(mi.Float, value) if dr.is_jit_v(mi.Float) else mi.Float(value)


def linear_texture(values: np.ndarray):
    """A float32 ``Texture1f``/``Texture2f`` of ``values`` (the last axis holds the
    channels; one or two axes before it), linearly interpolated and clamped at its edges,
    as every table lookup reads it."""
    import mitsuba as mi
    texture = {1: mi.Texture1f, 2: mi.Texture2f}[values.ndim - 1]
    return texture(mi.TensorXf(np.ascontiguousarray(values, np.float32)), use_accel=False,
                   migrate=False, filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp)


class CubicSpline:
    """A table's texture holds the coefficients of the interpolating cubic B-spline
    with :data:`GHOST` ghost nodes around every segment of each axis: shape ``(nv +
    2g, nu + 2g, channels)``, or for a split axis ``(nv + 2g, 2 (nu/2 + 2g),
    channels)`` (the transmit segment's columns, then the total-reflection
    segment's); a lookup reads 16 texels (``Texture2f.eval_cubic``). What the builders
    make and verify (:mod:`~thinfilm_mi.tabulate.exact`, :mod:`~thinfilm_mi.tabulate.band`)."""

    name = "cubic"

    @staticmethod
    def nodes(shape, axis, factors) -> tuple[int, int]:
        """``(nu, nv)``: the spline's nodes along the angle and the wavelength."""
        return shape[1] - 2 * GHOST * axis.segments, shape[0] - 2 * GHOST

    @staticmethod
    def constants(table, shape) -> None:
        g = GHOST
        table._inv_u = opaque_float(1.0 / shape[1])
        table._inv_v = opaque_float(1.0 / shape[0])
        table._offset = g + 0.5   # node 0 sits at texel centre g
        # a split axis: node coordinates beyond the critical cell are in the
        # second segment, 2g texels further
        table._split = opaque_float(0.5 * table.nu - 0.5) if table.axis.split else None

    @staticmethod
    def u(table, x):
        if table._split is not None:
            x = x + dr.select(x > table._split, 2.0 * GHOST, 0.0)
        return (x + table._offset) * table._inv_u

    @staticmethod
    def v(table, t):
        return (t + table._offset) * table._inv_v

    @staticmethod
    def eval(texture, pos, active):
        return texture.eval_cubic(pos, active)


class Bilinear:
    """A table's texture holds the values of the spline resampled ``factors = (ku,
    kv)`` times finer along each axis, read by bilinear interpolation (4 texels a
    lookup, where the spline reads 16: :mod:`~thinfilm_mi.tabulate.bilinear`). Shape
    ``(kv (nv - 1) + 1, ku (nu - 1) + 1, channels)``, or for a split axis two
    segments of ``ku (nu/2 - 1) + 1`` columns side by side (the cell between them,
    across the critical angle, has no width: no lookup falls in it)."""

    name = "linear"

    @staticmethod
    def nodes(shape, axis, factors) -> tuple[int, int]:
        ku, kv = factors
        per_segment = shape[1] // axis.segments
        return axis.segments * ((per_segment - 1) // ku + 1), (shape[0] - 1) // kv + 1

    @staticmethod
    def constants(table, shape) -> None:
        ku, kv = table.factors
        table._inv_u = opaque_float(1.0 / shape[1])
        table._inv_v = opaque_float(1.0 / shape[0])
        table._ku, table._kv = opaque_float(ku), opaque_float(kv)
        # a split axis: the second segment's node m starts at column ku (m - 1) + 1
        table._split = opaque_float(0.5 * table.nu - 0.5) if table.axis.split else None
        table._seam = opaque_float(1.0 - ku) if table.axis.split else None

    @staticmethod
    def u(table, x):
        xf = x * table._ku
        if table._split is not None:
            xf = xf + dr.select(x > table._split, table._seam, 0.0)
        return (xf + 0.5) * table._inv_u

    @staticmethod
    def v(table, t):
        return dr.fma(t, table._kv, 0.5) * table._inv_v

    @staticmethod
    def eval(texture, pos, active):
        return texture.eval(pos, active)


CUBIC, BILINEAR = CubicSpline(), Bilinear()
#: How a :class:`Table`'s texture is interpolated, by name (the name is what the table
#: store keeps on disk).
INTERPOLATIONS = {i.name: i for i in (CUBIC, BILINEAR)}


class Table:
    """A built table: a float32 ``Texture2f`` (channels ``R`` [, ``T``], or the Mueller
    components) with its axes, interpolated as ``interpolation`` (one of
    :data:`INTERPOLATIONS`) says: the cubic spline the builders verify
    (:class:`CubicSpline`, the texture holds its coefficients), or its values resampled
    ``factors`` times finer for bilinear lookups (:class:`Bilinear`)."""

    def __init__(self, values: np.ndarray, axis: AngleAxis, error: float, channels: int,
                 resolution: float = 0.0, shear=None, interpolation=CUBIC, factors=(1, 1)):
        #: the angle axis (:data:`~thinfilm_mi.tabulate.axes.AXES`)
        self.axis = axis
        self.interpolation = interpolation
        #: resampling factors along the angle and the wavelength (:class:`Bilinear`)
        self.factors = tuple(int(f) for f in factors)
        self.nu, self.nv = interpolation.nodes(values.shape, axis, self.factors)
        self.channels = channels
        #: the verified max abs interpolation error (sum of both axes' maxima, and of
        #: the resampling's), against ``R_σ`` for a band-limited table
        self.error = error
        #: ``spectral_resolution`` (nm) of the band-limited values tabulated
        #: (:mod:`thinfilm_mi.tabulate.band`); 0: the exact values
        self.resolution = resolution
        #: bytes of the texture's float32 data
        self.nbytes = int(values.size) * 4
        self.texture = linear_texture(values)

        # Shape-dependent constants of the lookup, opaque so that a table of
        # another shape reuses the render kernel.
        self._nu = opaque_float(self.nu)
        self._nv = opaque_float(self.nv)
        interpolation.constants(self, values.shape)
        #: a band-limited table's sheared v axis (:class:`~thinfilm_mi.tabulate.band.Shear`)
        self.shear = shear
        if shear is not None:
            self._v_scale = opaque_float((self.nv - 1) / (SIGMA_MAX - shear.low))

    @property
    def texels(self) -> int:
        return self.nu * self.nv

    def values(self) -> np.ndarray:
        """The texture's float32 data (float32 numpy, as built)."""
        return np.array(self.texture.tensor(), dtype=np.float32)

    def _u(self, cos_i, sin_i, n0, n_exit):
        return self.interpolation.u(self, self.axis.texel(cos_i, sin_i, n0, n_exit, self._nu))

    def lookup(self, cos_i, n0, n_exit, wavelengths, active=True, sin_i=None):
        """``[R]`` or ``[R, T]`` as spectra: one lookup per wavelength.

        ``cos_i`` (>= 0) is a Float; ``n0``, ``n_exit`` (real parts) and
        ``wavelengths`` are ``mi.Spectrum``. A cubic lookup may overshoot
        between nodes: ``R`` is clamped to ``[0, 1]`` and ``T`` to ``[0, 1 - R]``.
        """
        res = self.lookup_channels(cos_i, n0, n_exit, wavelengths, active, sin_i)
        res[0] = dr.clip(res[0], 0.0, 1.0)
        if self.channels > 1:
            res[1] = dr.clip(res[1], 0.0, 1.0 - res[0])
        return res

    def lookup_channels(self, cos_i, n0, n_exit, wavelengths, active=True, sin_i=None) -> list:
        """Every channel as a spectrum, as interpolated (unclamped); arguments as
        :meth:`lookup`, or (not a split table) ``cos_i`` and ``sin_i`` one direction
        per wavelength (lists; :func:`thinfilm_mi.render.mirror.mirrored_rt`)."""
        import mitsuba as mi

        each = isinstance(cos_i, list)
        if not each:
            cos_i = dr.clip(cos_i, 0.0, 1.0)
            sin_i = dr.safe_sqrt((1.0 - cos_i) * (1.0 + cos_i))
        out = [[] for _ in range(self.channels)]
        if not self.axis.needs_n_exit and not each:
            u = self._u(cos_i, sin_i, 1.0, 1.0)
        factor = self.shear.factor(sin_i) if self.shear is not None and not each else None
        for i in range(len(wavelengths)):
            if self.axis.needs_n_exit:
                u = self._u(cos_i, sin_i, n0[i], n_exit[i])
            elif each:
                u = self._u(cos_i[i], sin_i[i], 1.0, 1.0)
                factor = self.shear.factor(sin_i[i]) if self.shear is not None else None
            t = (v_texel(wavelengths[i], self._nv) if factor is None
                 else (SIGMA_MAX - factor / wavelengths[i]) * self._v_scale)
            res = self.interpolation.eval(self.texture,
                                          mi.Point2f(u, self.interpolation.v(self, t)), active)
            for c in range(self.channels):
                out[c].append(res[c])
        return [mi.UnpolarizedSpectrum(*vals) for vals in out]


def unique_wavelengths(wl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(wl, return_inverse=True)``, the same arrays, by a stable sort: a
    build's wavelengths come as sorted runs (one grid per angle node), which it merges
    in linear time where ``np.unique``'s quicksort does not see them."""
    wl = np.asarray(wl).ravel()
    order = np.argsort(wl, kind="stable")
    ordered = wl[order]
    first = np.empty(ordered.size, bool)
    first[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
    inverse = np.empty(wl.size, np.intp)
    inverse[order] = np.cumsum(first) - 1
    return ordered[first], inverse


def side_indices(side: SideData, wl: np.ndarray):
    """``(n0, [film indices], n_exit)`` at the wavelengths ``wl``, each an array
    over ``wl``; beyond 360-830 nm (ghost nodes) held at the edge's value."""
    wl_ix = np.clip(wl, SPECTRAL_RANGE[0], SPECTRAL_RANGE[1])
    return side.n0(wl_ix), [n(wl_ix) for n, _ in side.films], side.n_exit(wl_ix)


def film_gather(film_n, thicknesses, at, width: int, real: bool, scale=None):
    """``film(j)`` for the float64 film loops of :mod:`thinfilm_mi.optics.core`: film
    ``j``'s index at each point's row ``at`` (a ``UInt32`` array), gathered inside the
    kernel from one buffer of ``len(film_n) x width`` entries (``film_n``: the films'
    complex indices over ``width`` wavelengths; a literal zero imaginary part where
    ``real``), and its thickness (times the per-point ``scale`` if given)."""
    from drjit.llvm import Float64, UInt32

    from thinfilm_mi.optics.backend import float64_array

    buf_re = float64_array(np.concatenate([n.real for n in film_n]))
    buf_im = None if real else float64_array(np.concatenate([n.imag for n in film_n]))
    thick = float64_array(np.array(thicknesses, np.float64))
    w = dr.opaque(UInt32, width)

    def film(j):
        i = j * w + at
        m = Cx(dr.gather(Float64, buf_re, i), 0.0 if real else dr.gather(Float64, buf_im, i))
        d = dr.gather(Float64, thick, j)
        return m, d if scale is None else d * scale
    return film


def evaluate_side(side: SideData, cos0: np.ndarray, rows: np.ndarray, wl: np.ndarray,
              indices, scale: np.ndarray | None = None) -> np.ndarray:
    """Exact float64 R [, T] at points ``(cos0[i], wl[rows[i]])`` (flat arrays),
    with ``indices`` (:func:`side_indices`) at the wavelengths ``wl``, every film's
    thickness times ``scale[i]`` if given (a flat array); returns shape
    (len cos0, channels). One trace and one kernel launch for all the points;
    the phase follows the wavelength also beyond 360-830 nm.

    The per-wavelength values go in as small buffers gathered inside the kernel
    at ``rows`` (no per-point copies: fresh large numpy buffers cost page
    faults); real indices with a literal zero imaginary part (the core's
    real-index paths). Deep stacks run as a loop gathering film ``j``'s index
    at row ``r`` from a buffer at ``j * len(wl) + r``."""
    from drjit.llvm import Float64, UInt32

    from thinfilm_mi.optics.backend import aligned_array, float64_array

    n0, film_n, n_exit = indices
    film_n = [np.asarray(n, np.complex128) for n in film_n]
    at = aligned_array(rows, np.uint32, UInt32)

    def per_row(values):
        return dr.gather(Float64, float64_array(values), at)

    absorbing = side.absorbing or (tuple(bool(np.any(n.imag)) for n in film_n)
                                   + (bool(np.any(np.asarray(n_exit).imag)),))

    def cx(values, complex_):
        values = np.asarray(values, np.complex128)
        return Cx(per_row(values.real), per_row(values.imag) if complex_ else 0.0)

    args = (per_row(n0), float64_array(cos0))
    per_point = None if scale is None else float64_array(np.asarray(scale, np.float64))
    tail = (cx(n_exit, absorbing[-1]), per_row(wl), side.transmission)
    if side.rt_loop is not None and len(film_n) >= BUILD_LOOP_MIN_FILMS:
        re = np.concatenate([n.real for n in film_n])
        real = not any(absorbing[:-1])
        film = film_gather(film_n, [d for _, d in side.films], at, len(wl), real, per_point)
        res = side.rt_loop(*args, dr.opaque(UInt32, len(film_n), len(rows)), film, *tail,
                           n0_max=float(np.max(n0)), film_n_min=float(re.min()) if real else None,
                           film_n_max=float(re.max()) if real else None,
                           films_max=len(film_n))
    else:
        films = [(cx(n, a), dr.opaque(Float64, float(d)) if per_point is None
                  else dr.opaque(Float64, float(d)) * per_point)
                 for n, a, (_, d) in zip(film_n, absorbing, side.films)]
        res = side.rt(*args, films, *tail)
    res = res if isinstance(res, tuple) else (res,)
    dr.eval(*res)
    return np.stack([np.array(r, dtype=np.float64) for r in res], axis=-1)


class BuildReport(dict):
    """What one table build did, returned through the builders' ``report`` argument
    (never left in a module global: Mitsuba runs constructors, and so builds, on
    several threads). Keys: ``kind`` (the angle axis's name), ``points`` (exact
    evaluations in all), ``rounds`` (tables built and verified), ``result``
    ("table", "rejected by the probe", "over budget", "critical angle varies",
    "colour check failed"), ``resolution`` (nm, 0 for exact values); exact builds
    add ``probe_points``, band-limited ones ``colour_error(s)``, ``errors`` (per
    round) and ``exact_attempt`` (the report of the exact build tried first)."""


class TableCache:
    """Built tables (or ``None`` for a stack that cannot be tabulated) by key, shared
    between BSDFs with identical optics; least recently used first out.

    Bounded in bytes as well as in entries: a sweep or an optimisation that builds
    thousands of distinct tables would otherwise keep hundreds of tables of up to
    2-32 MiB each alive (RSS grew from 116 to 641 MB over 2500 rebuilds with a
    count bound of 257 alone). With 32 MiB (the bound until tables of 1-3 films were
    resampled for bilinear lookups, 2-8 MiB each: 64 MiB since), 1200 rebuilds of random 1-3-film
    tables stayed at 225-250 MB from a 122 MB start, and clearing the cache,
    ``dr.flush_malloc_cache()`` and the C library's ``malloc_trim`` gave back all
    of it (no leak). Tables still used by a BSDF stay alive through it.
    Thread-safe: plugin constructors run on several threads under Mitsuba's
    parallel scene loading.
    """

    def __init__(self, max_bytes: int = 64 << 20, max_entries: int = 1024):
        import threading
        from collections import OrderedDict

        self.max_bytes = max_bytes
        self.max_entries = max_entries
        self._items: "OrderedDict[str, Table | None]" = OrderedDict()
        self._lock = threading.Lock()
        self.nbytes = 0

    def __len__(self) -> int:
        return len(self._items)

    def __contains__(self, key: str) -> bool:
        return key in self._items

    def get(self, key: str):
        """``(True, table)`` for a cached key (now the most recently used), else
        ``(False, None)``."""
        with self._lock:
            if key not in self._items:
                return False, None
            self._items.move_to_end(key)
            return True, self._items[key]

    def put(self, key: str, table) -> None:
        size = table.nbytes if table is not None else 0
        with self._lock:
            if key in self._items:
                return
            self._items[key] = table
            self.nbytes += size
            while self._items and (self.nbytes > self.max_bytes
                                   or len(self._items) > self.max_entries):
                _, old = self._items.popitem(last=False)
                self.nbytes -= old.nbytes if old is not None else 0

    def clear(self) -> None:
        with self._lock:
            self._items.clear()
            self.nbytes = 0


def grid_coordinate(wavelengths):
    """The texture coordinate of ``wavelengths`` (nm) in a 1-D texture of the values
    on ``GRID`` (texel ``i`` holds ``GRID[i]`` at its centre, ``(i + 1/2) / len``)."""
    lo, hi = SPECTRAL_RANGE
    n = GRID.size
    return (wavelengths - lo) * ((n - 1) / ((hi - lo) * n)) + 0.5 / n
