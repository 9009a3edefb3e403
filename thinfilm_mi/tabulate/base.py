"""What every table build shares: the data of a lit side of a stack, its evaluation in
float64 batches, the table axes, cubic B-splines, the lookup object and the cache.

* :class:`SideData`: a side of a stack as the builders see it (media on a
  wavelength grid, films, the float64 ``rt`` functions), and :func:`evaluate_side`,
  which evaluates ``R`` (and ``T``) at any set of (angle, wavelength) points in
  batches (looping over the films for deep stacks, whose indices
  :func:`film_gather` gathers from one buffer inside the kernel).
* Axes: :func:`u_texel` / :func:`u_nodes_cos` (the angle axis, split at the
  critical angle where the exit medium totally reflects; ``kind="band"`` warps it
  for band-limited tables) and :func:`v_texel` (the wavelength axis, uniform in
  wavenumber).
* Splines: :func:`bspline_coefficients` (interpolating cubic B-splines with
  :data:`GHOST` nodes), :func:`bspline_midpoints` (the values a table predicts
  between its nodes, which the builders verify against exact values).
* :class:`Table`: the float32 ``Texture2f`` a render kernel looks up, with opaque
  scale and offset constants; :class:`TableCache`: built tables shared by key.

The refinement shared by the builders (budget, first step, convergence order, the
linear tables' 4-point rule) is :mod:`thinfilm_mi.tabulate.refine`. The builders on
top are :mod:`thinfilm_mi.tabulate.exact` (tables of the exact values),
:mod:`thinfilm_mi.tabulate.band` (band-limited values of deep stacks),
:mod:`thinfilm_mi.tabulate.colour` and :mod:`thinfilm_mi.tabulate.diffuse` (RGB and
mono tables) and :mod:`thinfilm_mi.tabulate.hemispherical`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from thinfilm_mi.materials.model import GRID, SPECTRAL_RANGE
from thinfilm_mi.optics.core import Cx

SIGMA_MAX = 1.0 / SPECTRAL_RANGE[0]   # 1/nm at 360 nm
SIGMA_MIN = 1.0 / SPECTRAL_RANGE[1]   # 1/nm at 830 nm
HALF_PI = 0.5 * math.pi

#: Largest table (texels per channel) built; beyond it a stack is evaluated exactly.
MAX_TEXELS = 1 << 22
MIN_U, MIN_V = 16, 16
MAX_U, MAX_V = 4096, 8192
#: Nodes beyond each edge of a cubic table (evaluated exactly, outside the
#: tabulated range): the spline's end conditions perturb it by a factor
#: (2 - sqrt 3) = 0.27 less per node inwards, 2 % at the first real node.
GHOST = 3
#: The verification ignores incidence within ~1.1 degrees of grazing
#: (cos(theta) < GRAZING_COS). There, a dielectric film over a metal or a
#: high-index film is a cavity whose inner walls reflect almost totally (the
#: film/ambient interface is lit near its critical angle), with resonances
#: narrower than 0.5 nm that no practical table resolves; such a ray's
#: contribution to an image is a sliver at silhouettes. Tables interpolate
#: there too; benchmarks/speed_vs_error.py reports the error including it.
GRAZING_COS = 0.02
#: Exact evaluations a build may spend (probe, and all rounds' nodes and
#: checks), up to ~1 s for 30 films on two cores: a stack that needs more
#: (sharp resonances, such as the surface plasmon of a metal film seen from
#: inside glass, or the high-Q cavity modes of a deep random stack on a metal)
#: is evaluated exactly. (fig8b's table lit from inside glass needs ~2e5.)
MAX_BUILD_POINTS = 3_000_000   # one budget for every build, exact (~1 s) or band-limited (~2 s)
#: An exact evaluation's cost grows with the films (the recursion visits each):
#: :func:`build_work` weighs a point by its films plus this share of its own
#: (indices, angle, Fresnel terms, numpy bookkeeping).
POINT_WORK = 4
#: :func:`build_work` a build may spend, decided before the work where it can be
#: predicted (the exact probe, the band-limited build's first round and its
#: expected total; then before every round): ~2 s on two cores (the 30-film
#: benchmark stack's band-limited table, 1.6e6 points of 34 film units, took
#: 0.7-1.3 s). Deeper stacks are evaluated exactly at once instead of spending
#: seconds on a table the budget then rejects.
MAX_BUILD_WORK = 100_000_000


def build_work(side: "SideData", points: float) -> float:
    """The cost of ``points`` exact evaluations of ``side`` in film units
    (:data:`POINT_WORK` per point on top of one per film)."""
    return float(points) * (len(side.films) + POINT_WORK)


#: Builds evaluate stacks of this many films or more as a loop over the films: its
#: float64 kernel is compiled once for every depth (the unrolled kernel of 30
#: films took ~0.9 s to compile, once per depth with an empty kernel cache).
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
    (the coherent :func:`~thinfilm_mi.optics.unpolarised.unpolarised_rt` or the
    incoherent-aware one), ``transmission`` whether ``T`` is tabulated too.
    ``rt_loop``, where given, evaluates :data:`BUILD_LOOP_MIN_FILMS` films or
    more as a loop (:func:`~thinfilm_mi.optics.unpolarised.unpolarised_rt_loop`).
    ``kinks``: wavelengths where an index's slope jumps (tabulated data), at
    which the build checks the table too. ``absorbing`` (set by
    :func:`build_table`): whether each film and the exit medium absorb
    anywhere in the range, so that every evaluation of a build traces the same
    kernel whatever its wavelengths. ``quantity``: ``None`` for the powers ``R``
    [, ``T``]; else what is tabulated instead (the Mueller components of polarized
    variants, :data:`thinfilm_mi.tabulate.mueller.MUELLER`), whose ``rt`` and
    ``rt_loop`` return its channels.
    """
    n0: object                      # callable wl -> real ndarray
    films: list                     # [(callable wl -> complex ndarray, thickness)]
    n_exit: object                  # callable wl -> complex ndarray
    transmission: bool
    rt: object
    fringe_films: list = field(default_factory=list)  # indices of coherent films
    rt_loop: object = None
    kinks: np.ndarray = field(default_factory=lambda: np.empty(0))
    absorbing: tuple | None = None
    quantity: object = None


def tir_kind(n0: np.ndarray, n_exit: np.ndarray) -> str | None:
    """``"tir"`` if the exit medium is real and of lower index than ``n0`` at every
    node wavelength, ``"plain"`` if it never is, ``None`` if it changes with λ
    (not tabulated: the kink would cross nodes)."""
    real = np.all(np.abs(n_exit.imag) <= 1e-6)
    lower = n_exit.real < n0
    if real and np.all(lower):
        return "tir"
    if not real or not np.any(lower):
        return "plain"
    return None


# -- axis mappings (generic over array types: numpy-free, Dr.Jit math) ---------
def u_texel(cos_i, sin_i, n0, n_exit, kind: str, nu):
    """The continuous node coordinate (0 .. nu-1) of an incidence direction.

    ``n0`` and ``n_exit`` are the real indices at the lookup's wavelength;
    ``nu`` (the number of angle nodes) may be a Python number or an opaque
    Float, so that the kernel does not depend on the table's shape. An
    angle ``a`` in [0, pi/2] that ends at grazing incidence is mapped through
    ``w = 1 - sqrt(x)`` with ``x = (pi/2 - a) / (pi/2)`` (computed as
    ``atan2(cos, sin)``, free of cancellation): ``w`` is analytic at both ends
    (``R`` is even in the angle at normal incidence) and puts nodes
    quadratically closer towards grazing incidence, where coated metals show
    their sharp pseudo-Brewster dip and the rise to ``R = 1``.

    ``kind="band"`` (band-limited tables, :mod:`thinfilm_mi.tabulate.band`) blends
    that ``w`` with ``S = 2a/π - (m sin(4a)/2 + (1 - m) sin(2a)) / π`` (``m`` =
    :data:`BAND_MID`), whose node density ``∝ m sin²(2a) + (1 - m) sin²(a)``
    rises to mid and high angles: ``BAND_WARP S + (1 - BAND_WARP) w``. A
    band-limited ``R``'s features move along λ as the angle changes, fastest
    between 30° and 75°, where ``w`` alone is sparsest.
    """
    if kind == "plain" or kind == "band":
        x = (1.0 / HALF_PI) * dr.atan2(cos_i, sin_i)
        w = 1.0 - dr.sqrt(x)
        if kind == "band":
            sin2 = 2.0 * sin_i * cos_i
            sin4 = 2.0 * sin2 * (cos_i * cos_i - sin_i * sin_i)
            S = (1.0 - x) - (0.5 * BAND_MID * sin4 + (1.0 - BAND_MID) * sin2) * (0.5 / HALF_PI)
            w = BAND_WARP * S + (1.0 - BAND_WARP) * w
        return (nu - 1) * w
    m = 0.5 * nu            # split tables have an even nu: nodes 0..m-1 | m..nu-1
    beta = n0 * sin_i
    d2 = (n_exit - beta) * (n_exit + beta)            # q_exit^2
    q_exit = dr.sqrt(dr.maximum(d2, 0.0))
    a = dr.sqrt(dr.maximum(-d2, 0.0))                 # |q_exit| beyond the critical angle
    theta_t = dr.atan2(beta, q_exit)
    x = (1.0 / HALF_PI) * dr.atan2(n0 * cos_i, a)     # 1 - phi / (pi/2)
    return dr.select(d2 > 0, (m - 1) * (1.0 / HALF_PI) * theta_t,
                     m + (m - 1) * (1.0 - dr.sqrt(x)))


#: Share of the mid-angle term ``S`` in the angle axis of band-limited tables
#: (:func:`u_texel`, ``kind="band"``), and the share of ``sin²(2a)`` in its
#: density. Chosen from the interpolation error of ``R_σ`` per 5° of incidence
#: on the plain axis (10-film benchmark stack, 129 nodes: 8e-5 at 80-85°, 2.5e-2
#: at 45-50°): the blend that equalises it needs ~0.6x the nodes.
BAND_WARP = 0.6
BAND_MID = 0.6


def band_warp(theta: np.ndarray) -> np.ndarray:
    """The ``"band"`` axis coordinate (0 at normal, 1 at grazing incidence) of
    angles ``theta`` (radians; negative angles continue it analytically)."""
    x = 1.0 - theta / HALF_PI
    S = (1.0 - x) - (0.5 * BAND_MID * np.sin(4.0 * theta)
                     + (1.0 - BAND_MID) * np.sin(2.0 * theta)) * (0.5 / HALF_PI)
    return BAND_WARP * S + (1.0 - BAND_WARP) * (1.0 - np.sqrt(x))


def band_cos(u: np.ndarray) -> np.ndarray:
    """Inverse of :func:`band_warp` as ``cos θ`` (float64 numpy, any shape): ``u < 0``
    continues to negative angles, ``u > 1`` mirrors about grazing incidence
    (as the plain axis's ghosts)."""
    u = np.asarray(u, np.float64)
    target = np.where(u > 1.0, 2.0 - u, u)
    lo = np.full(target.shape, -HALF_PI)
    hi = np.full(target.shape, HALF_PI)
    for _ in range(60):     # the warp increases monotonically on [-pi/2, pi/2]
        mid = 0.5 * (lo + hi)
        below = band_warp(mid) < target
        lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
    return np.cos(0.5 * (lo + hi))


def u_nodes_cos(s: np.ndarray, n0: np.ndarray, n_exit: np.ndarray, kind: str, nu: int,
                 ghost: int = GHOST):
    """Inverse of :func:`u_texel` (float64 numpy): cos(theta_i) at node
    coordinates ``s`` (any shape broadcasting with the per-λ ``n0``, ``n_exit``).

    On a plain axis ``s`` may lie up to ``ghost`` nodes beyond either end:
    ``w < 0`` continues to negative angles (``cos`` of ``|theta|``) and
    ``w > 1`` mirrors about grazing incidence (``cos = sin((1 - w)^2 pi/2)``
    is even about ``w = 1``), both the analytic continuation of ``R(w)``."""
    if kind == "plain":
        w = np.clip(s / (nu - 1), -ghost / (nu - 1), 1.0 + ghost / (nu - 1))
        return np.sin((1.0 - w) ** 2 * HALF_PI)
    m = nu // 2
    t = np.clip(s / (m - 1), 0.0, 1.0) * HALF_PI          # transmit segment: theta_t
    beta = n_exit * np.sin(t)
    cos_t = np.sqrt(np.maximum(1.0 - (beta / n0) ** 2, 0.0))
    rho = np.sqrt(np.maximum(n0 * n0 - n_exit * n_exit, 0.0))
    w = np.clip((s - m) / (m - 1), 0.0, 1.0)             # TIR segment
    cos_p = rho * np.sin((1.0 - w) ** 2 * HALF_PI) / n0
    return np.where(s < m - 0.5, cos_t, cos_p)


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
    (evaluated: the stack's analytic continuation), ``"mirror"`` (the function
    is even about the end node: ``f(-k) = f(k)``) or ``"extrapolate"`` (the
    cubic through the four nodes nearest the end, where no continuation can be
    evaluated: at a critical angle)."""
    def outwards(spec, inner):
        # the ghosts at -1, -2, ..., -g of the nodes inner[0], inner[1], ...
        if spec == "mirror":
            return inner[1:g + 1]
        f0, f1, f2, f3 = inner[0], inner[1], inner[2], inner[3]
        return np.stack([4 * f0 - 6 * f1 + 4 * f2 - f3,
                         10 * f0 - 20 * f1 + 15 * f2 - 4 * f3,
                         20 * f0 - 45 * f1 + 36 * f2 - 10 * f3][:g])
    lo = np.asarray(left) if not isinstance(left, str) else outwards(left, real)[::-1]
    hi = np.asarray(right) if not isinstance(right, str) else outwards(right, real[::-1])
    return np.concatenate([lo, real, hi], axis=0)


#: How each end of a segment of the u axis gets its ghost nodes
#: (:func:`with_ghosts`): a plain axis's are evaluated; a split axis's transmit
#: segment is even about normal incidence (uniform in the refraction angle),
#: its total-reflection segment about grazing incidence (``w = 1``), and both
#: are extrapolated at the critical angle, beyond which they do not continue.
SPLIT_ENDS = (("mirror", "extrapolate"), ("extrapolate", "mirror"))


def bspline_at(coeffs: np.ndarray, t: np.ndarray, g: int) -> np.ndarray:
    """The spline with ``coeffs`` along axis 0 (node ``i`` at index ``i + g``) at
    node coordinates ``t`` (uniform cubic B-spline weights)."""
    i = np.floor(t).astype(np.int64)
    f = (t - i)[(...,) + (None,) * (coeffs.ndim - 1)]
    w = ((1 - f) ** 3 / 6, (3 * f ** 3 - 6 * f ** 2 + 4) / 6,
         (-3 * f ** 3 + 3 * f ** 2 + 3 * f + 1) / 6, f ** 3 / 6)
    return sum(wk * coeffs[i + g - 1 + k] for k, wk in enumerate(w))


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


class Table:
    """A built table: a float32 ``Texture2f`` (channels ``R`` [, ``T``]) with its axes.

    ``values`` holds the cubic spline's coefficients with :data:`GHOST` ghost
    nodes around every segment of each axis: shape ``(nv + 2g, nu + 2g,
    channels)``, or for a split axis ``(nv + 2g, 2 (nu/2 + 2g), channels)``
    (the transmit segment's columns, then the total-reflection segment's).
    """

    def __init__(self, values: np.ndarray, kind: str, error: float, channels: int,
                 resolution: float = 0.0, shear=None):
        g = GHOST
        segments = 2 if kind == "tir" else 1
        self.nv, self.nu = values.shape[0] - 2 * g, values.shape[1] - 2 * g * segments
        self.kind = kind
        self.channels = channels
        #: the verified max abs interpolation error (sum of both axes' maxima),
        #: against ``R_σ`` for a band-limited table
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
        self._inv_u = opaque_float(1.0 / values.shape[1])
        self._inv_v = opaque_float(1.0 / (self.nv + 2 * g))
        self._offset = g + 0.5   # node 0 sits at texel centre g
        # a split axis: node coordinates beyond the critical cell are in the
        # second segment, 2g texels further
        self._split = opaque_float(0.5 * self.nu - 0.5) if kind == "tir" else None
        #: a band-limited table's sheared v axis (:class:`~thinfilm_mi.tabulate.shear.Shear`)
        self.shear = shear
        if shear is not None:
            self._v_scale = opaque_float((self.nv - 1) / (SIGMA_MAX - shear.low))

    @property
    def texels(self) -> int:
        return self.nu * self.nv

    def _u(self, cos_i, sin_i, n0, n_exit):
        x = u_texel(cos_i, sin_i, n0, n_exit, self.kind, self._nu)
        if self._split is not None:
            x = x + dr.select(x > self._split, 2.0 * GHOST, 0.0)
        return (x + self._offset) * self._inv_u

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
        if self.kind != "tir" and not each:
            u = self._u(cos_i, sin_i, 1.0, 1.0)
        factor = self.shear.factor(sin_i) if self.shear is not None and not each else None
        for i in range(len(wavelengths)):
            if self.kind == "tir":
                u = self._u(cos_i, sin_i, n0[i], n_exit[i])
            elif each:
                u = self._u(cos_i[i], sin_i[i], 1.0, 1.0)
                factor = self.shear.factor(sin_i[i]) if self.shear is not None else None
            t = (v_texel(wavelengths[i], self._nv) if factor is None
                 else (SIGMA_MAX - factor / wavelengths[i]) * self._v_scale)
            v = (t + self._offset) * self._inv_v
            res = self.texture.eval_cubic(mi.Point2f(u, v), active)
            for c in range(self.channels):
                out[c].append(res[c])
        return [mi.UnpolarizedSpectrum(*vals) for vals in out]


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
    several threads). Keys: ``kind`` (the angle axis), ``points`` (exact
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
    count bound of 257 alone). With 32 MiB, 1200 rebuilds of random 1-3-film
    tables stayed at 225-250 MB from a 122 MB start, and clearing the cache,
    ``dr.flush_malloc_cache()`` and the C library's ``malloc_trim`` gave back all
    of it (no leak). Tables still used by a BSDF stay alive through it.
    Thread-safe: plugin constructors run on several threads under Mitsuba's
    parallel scene loading.
    """

    def __init__(self, max_bytes: int = 32 << 20, max_entries: int = 1024):
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
