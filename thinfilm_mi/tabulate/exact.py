"""Tables of a stack's reflectance and transmittance over (angle, wavelength).

Hirayama et al. (sec. 4) precompute ``k_r`` and ``k_t`` at sampled incidence
angles and wavelengths and interpolate linearly, which they found 6x faster than
the recursion at every hit. Here a table is a ``Texture2f`` (Dr.Jit's texture,
float32) whose channels are the unpolarised ``R`` and, where a BSDF needs it,
``T`` of one lighting side of the stack. It is built in float64 with the optics
core (:func:`thinfilm_mi.render.kernel.unpolarised_rt` on ``drjit.llvm.Float64``) and
looked up in the render kernel, where its cost does not depend on the number of
films.

Interpolation: the texture holds the coefficients of the interpolating cubic
B-spline (``Texture2f.eval_cubic``, 16 texels a lookup): its error falls as
h^4, so a fringe needs 4-5x fewer nodes per axis than with the paper's linear
interpolation (h^2) for the same error, and a table ~20x fewer texels. The
coefficients are solved for (a tridiagonal system per axis) on a grid extended
by :data:`GHOST` nodes beyond each edge, at which the stack is evaluated too
(its analytic continuation), so the spline's end conditions do not reach the
tabulated range. Where the exit medium totally reflects, ``R`` has a
square-root kink at the critical angle: the angle axis is split there into two
segments, each a spline of its own with its own ghost nodes (mirrored about
normal and grazing incidence, where the functions are even, and extrapolated
at the critical angle, beyond which neither continues), stored side by side.

Axes (chosen so that the tabulated functions are smooth):

* wavelength: uniform in wavenumber ``1/lambda`` over 360-830 nm, in which an
  interference fringe has a constant period;
* angle: when the exit medium cannot totally reflect, uniform in
  ``w = 1 - sqrt(1 - theta / (pi/2))`` (the films' responses are even in their
  ``q``, so ``R`` is analytic in ``theta``, and in ``w``; nodes crowd towards
  grazing incidence, where coated metals dip sharply and rise to ``R = 1``;
  band-limited tables, :mod:`thinfilm_mi.tabulate.band`, blend in more nodes at
  mid angles: :func:`u_texel`'s ``kind="band"``).
  When it can (light inside glass, exit medium of lower index), the axis is
  split at the critical angle, which sits exactly on a node at every
  wavelength: below it the axis is uniform in the refraction angle ``theta_t``
  in the exit medium, above it in the same ``w`` of
  ``phi = atan(|q_exit| / q_0)``; ``R`` and ``T`` are analytic in both.

The resolution is first estimated by a probe: fine 1-D lines of exact values
along each axis (at fixed angles and wavelengths, and where the lines across
find the sharpest features), each subsampled by 2, 4, 8, ... into 1-D tables
whose interpolation error is then known exactly. That gives each axis's error
as a function of its number of nodes; the target is split between the axes so
that the table has the fewest texels. A stack that would need more than
:data:`MAX_TEXELS` texels even with the whole target on each axis (deep stacks
on metals, with cavity resonances ~0.1 nm wide) is rejected at this point, for
~5·10^4 evaluations. The table is then *verified*: the exact values at the
midpoints between nodes along each axis are compared with the interpolated
ones, and the axis whose error is too large is refined until the sum of both
axes' maximum errors is within the target (default 1e-3 in ``R`` and ``T``).
A stack that would need more than :data:`MAX_TEXELS` texels, or more than
:data:`MAX_BUILD_POINTS` exact evaluations, is not tabulated.

The lookup's scale and offset constants are opaque JIT variables, so a new
table of another shape (a thickness sweep) reuses the compiled render kernel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import drjit as dr
import numpy as np

from thinfilm_mi.optics.core import Cx
from thinfilm_mi.materials.stack import SPECTRAL_RANGE

__all__ = ["SideData", "Table", "build_table", "table_resolution", "MAX_TEXELS"]

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
MAX_BUILD_POINTS = 3_000_000
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
    (the coherent :func:`~thinfilm_mi.render.kernel.unpolarised_rt` or the
    incoherent-aware one), ``transmission`` whether ``T`` is tabulated too.
    ``rt_loop``, where given, evaluates :data:`BUILD_LOOP_MIN_FILMS` films or
    more as a loop (:func:`~thinfilm_mi.render.kernel.unpolarised_rt_loop`).
    ``kinks``: wavelengths where an index's slope jumps (tabulated data), at
    which the build checks the table too. ``absorbing`` (set by
    :func:`build_table`): whether each film and the exit medium absorb
    anywhere in the range, so that every evaluation of a build traces the same
    kernel whatever its wavelengths.
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


def _u_nodes_cos(s: np.ndarray, n0: np.ndarray, n_exit: np.ndarray, kind: str, nu: int,
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


def _v_nodes_wl(t: np.ndarray, nv: int) -> np.ndarray:
    """Inverse of :func:`v_texel`; ``t`` beyond ``[0, nv-1]`` (ghost nodes) gives
    wavelengths outside 360-830 nm."""
    sigma = SIGMA_MAX + (SIGMA_MIN - SIGMA_MAX) * (np.asarray(t, np.float64) / (nv - 1))
    return 1.0 / sigma


# -- resolution ----------------------------------------------------------------
def _phase_step(error: float) -> float:
    """Largest node spacing ``h`` (in fringe phase) at which a fringe ``cos(phi)``
    of unit amplitude interpolates within ``error / 2``: ``5 h^4 / 384`` for the
    cubic interpolating spline."""
    return (38.4 * error) ** 0.25


def table_resolution(side: SideData, error: float, wavelengths: np.ndarray) -> tuple[int, int]:
    """First estimate of ``(nu, nv)`` for a target max error ``error``.

    Each axis gets half the target and enough nodes for the fringe phase it
    spans at the step of :func:`_phase_step` (a conservative unit amplitude),
    plus a floor for the Fresnel terms. The total phase over the wavenumber
    range is ``4 pi sum_j n_j d_j (sigma_max - sigma_min)`` and over the angles
    ``4 pi / lambda_min sum_j d_j (Re q_j(0) - Re q_j(grazing))``. The estimate
    is then verified and refined by :func:`build_table`.
    """
    h = _phase_step(error)
    n0 = side.n0(wavelengths)
    ot_v, ot_u = 0.0, 0.0
    for j in side.fringe_films:
        n, d = side.films[j]
        nj = n(wavelengths)
        ot_v += float(np.max(nj.real)) * d
        q_graz = np.sqrt((nj * nj - n0 * n0).astype(np.complex128))
        ot_u += float(np.max(np.abs(nj.real - np.abs(q_graz.real)))) * d
    phase_v = 4.0 * math.pi * ot_v * (SIGMA_MAX - SIGMA_MIN)
    phase_u = 4.0 * math.pi * ot_u * SIGMA_MAX
    nv = max(MIN_V, int(math.ceil(phase_v / h)) + 1)
    nu = max(MIN_U, int(math.ceil(phase_u / h)) + 1)
    return nu, nv


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


def _bspline_midpoints(coeffs: np.ndarray, axis: int, g: int, n: int) -> np.ndarray:
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


def _bspline_at(coeffs: np.ndarray, t: np.ndarray, g: int) -> np.ndarray:
    """The spline with ``coeffs`` along axis 0 (node ``i`` at index ``i + g``) at
    node coordinates ``t`` (uniform cubic B-spline weights)."""
    i = np.floor(t).astype(np.int64)
    f = (t - i)[(...,) + (None,) * (coeffs.ndim - 1)]
    w = ((1 - f) ** 3 / 6, (3 * f ** 3 - 6 * f ** 2 + 4) / 6,
         (-3 * f ** 3 + 3 * f ** 2 + 3 * f + 1) / 6, f ** 3 / 6)
    return sum(wk * coeffs[i + g - 1 + k] for k, wk in enumerate(w))


# -- building -------------------------------------------------------------------
class Table:
    """A built table: a float32 ``Texture2f`` (channels ``R`` [, ``T``]) with its axes.

    ``values`` holds the cubic spline's coefficients with :data:`GHOST` ghost
    nodes around every segment of each axis: shape ``(nv + 2g, nu + 2g,
    channels)``, or for a split axis ``(nv + 2g, 2 (nu/2 + 2g), channels)``
    (the transmit segment's columns, then the total-reflection segment's).
    """

    def __init__(self, values: np.ndarray, kind: str, error: float, channels: int,
                 resolution: float = 0.0):
        import mitsuba as mi

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
        tensor = mi.TensorXf(np.ascontiguousarray(values, dtype=np.float32))
        self.texture = mi.Texture2f(tensor, use_accel=False, migrate=False,
                                    filter_mode=dr.FilterMode.Linear,
                                    wrap_mode=dr.WrapMode.Clamp)

        # Shape-dependent constants of the lookup, opaque so that a table of
        # another shape reuses the render kernel.
        def constant(value):
            return dr.opaque(mi.Float, value) if dr.is_jit_v(mi.Float) else mi.Float(value)
        self._nu = constant(self.nu)
        self._nv = constant(self.nv)
        self._inv_u = constant(1.0 / values.shape[1])
        self._inv_v = constant(1.0 / (self.nv + 2 * g))
        self._offset = g + 0.5   # node 0 sits at texel centre g
        # a split axis: node coordinates beyond the critical cell are in the
        # second segment, 2g texels further
        self._split = constant(0.5 * self.nu - 0.5) if kind == "tir" else None

    @property
    def texels(self) -> int:
        return self.nu * self.nv

    def _u(self, cos_i, sin_i, n0, n_exit):
        x = u_texel(cos_i, sin_i, n0, n_exit, self.kind, self._nu)
        if self._split is not None:
            x = x + dr.select(x > self._split, 2.0 * GHOST, 0.0)
        return (x + self._offset) * self._inv_u

    def lookup(self, cos_i, n0, n_exit, wavelengths, active=True):
        """``[R]`` or ``[R, T]`` as spectra: one lookup per wavelength.

        ``cos_i`` (>= 0) is a Float; ``n0``, ``n_exit`` (real parts) and
        ``wavelengths`` are ``mi.Spectrum``. A cubic lookup may overshoot
        between nodes: ``R`` is clamped to ``[0, 1]`` and ``T`` to ``[0, 1 - R]``.
        """
        import mitsuba as mi

        cos_i = dr.clip(cos_i, 0.0, 1.0)
        sin_i = dr.safe_sqrt((1.0 - cos_i) * (1.0 + cos_i))
        out = [[] for _ in range(self.channels)]
        if self.kind != "tir":
            u = self._u(cos_i, sin_i, 1.0, 1.0)
        for i in range(len(wavelengths)):
            if self.kind == "tir":
                u = self._u(cos_i, sin_i, n0[i], n_exit[i])
            v = (v_texel(wavelengths[i], self._nv) + self._offset) * self._inv_v
            res = self.texture.eval_cubic(mi.Point2f(u, v), active)
            for c in range(self.channels):
                out[c].append(res[c])
        res = [mi.Spectrum(*vals) for vals in out]
        res[0] = dr.clip(res[0], 0.0, 1.0)
        if self.channels > 1:
            res[1] = dr.clip(res[1], 0.0, 1.0 - res[0])
        return res


def _indices(side: SideData, wl: np.ndarray):
    """``(n0, [film indices], n_exit)`` at the wavelengths ``wl``, each an array
    over ``wl``; beyond 360-830 nm (ghost nodes) held at the edge's value."""
    wl_ix = np.clip(wl, SPECTRAL_RANGE[0], SPECTRAL_RANGE[1])
    return side.n0(wl_ix), [n(wl_ix) for n, _ in side.films], side.n_exit(wl_ix)


def _evaluate(side: SideData, cos0: np.ndarray, rows: np.ndarray, wl: np.ndarray,
              indices, scale: np.ndarray | None = None) -> np.ndarray:
    """Exact float64 R [, T] at points ``(cos0[i], wl[rows[i]])`` (flat arrays),
    with ``indices`` (:func:`_indices`) at the wavelengths ``wl``, every film's
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
        buf_re = float64_array(re)
        buf_im = None if real else float64_array(np.concatenate([n.imag for n in film_n]))
        thick = float64_array(np.array([d for _, d in side.films], np.float64))
        width = dr.opaque(UInt32, len(wl))

        def film(j):
            i = j * width + at
            m = Cx(dr.gather(Float64, buf_re, i),
                   0.0 if real else dr.gather(Float64, buf_im, i))
            d = dr.gather(Float64, thick, j)
            return m, d if per_point is None else d * per_point

        res = side.rt_loop(*args, dr.opaque(UInt32, len(film_n), len(rows)), film, *tail,
                           n0_max=float(np.max(n0)), film_n_min=float(re.min()) if real else None,
                           film_n_max=float(re.max()) if real else None,
                           films_max=len(film_n))
    else:
        films = [(cx(n, a), dr.opaque(Float64, float(d)) if per_point is None
                  else dr.opaque(Float64, float(d)) * per_point)
                 for n, a, (_, d) in zip(film_n, absorbing, side.films)]
        res = side.rt(*args, films, *tail)
    res = res if side.transmission else (res,)
    dr.eval(*res)
    return np.stack([np.array(r, dtype=np.float64) for r in res], axis=-1)


class _Points:
    """Point sets (node coordinates ``s`` along u x ``t`` along v, for a table of
    ``nu x nv`` nodes) gathered into one :func:`_evaluate` call."""

    def __init__(self, side: SideData, kind: str):
        self.side, self.kind = side, kind
        self.sets = []   # (t, s, nu, nv, ghost): the product t x s

    def add(self, s, t, nu: int, nv: int, ghost: int = GHOST) -> None:
        """The points ``t x s``; a plain u axis reaches ``ghost`` nodes beyond its ends."""
        self.sets.append((np.asarray(t, np.float64), np.asarray(s, np.float64), nu, nv, ghost))

    @property
    def size(self) -> int:
        return sum(t.size * s.size for t, s, *_ in self.sets)

    def evaluate(self):
        """``[(values (len t, len s, C), cos0 (len t, len s))]`` for every set."""
        wl = np.concatenate([_v_nodes_wl(t, nv) for t, _, _, nv, _ in self.sets])
        wl, inverse = np.unique(wl, return_inverse=True)
        if wl.size == 1:   # Dr.Jit traces a 1-element buffer as a scalar: another kernel
            wl = np.repeat(wl, 2)
        indices = _indices(self.side, wl)
        n0 = np.asarray(indices[0], np.float64)
        ne = np.asarray(indices[2]).real
        cos, rows, start = [], [], 0
        for t, s, nu, _, ghost in self.sets:
            r = inverse[start:start + t.size]
            start += t.size
            c = _u_nodes_cos(s[None, :], n0[r][:, None], ne[r][:, None], self.kind, nu, ghost)
            cos.append(np.broadcast_to(c, (t.size, s.size)))
            rows.append(np.broadcast_to(r[:, None], (t.size, s.size)))
        vals = _evaluate(self.side, np.concatenate([c.ravel() for c in cos]),
                         np.concatenate([r.ravel() for r in rows]), wl, indices)
        out, start = [], 0
        for (t, s, *_), c in zip(self.sets, cos):
            n = t.size * s.size
            out.append((vals[start:start + n].reshape(t.size, s.size, -1), c))
            start += n
        return out


# -- first estimate from fine 1-D lines -------------------------------------------
#: Intervals of the probe's lines along v and along u (a power of two: their
#: subsamplings are tables of 2^k times fewer intervals), and of the finer line
#: taken where the first cannot resolve the target (enough to test MAX_V, MAX_U).
PROBE_V, PROBE_U = 2048, 512
PROBE_V_FINE, PROBE_U_FINE = 2 * MAX_V, 2 * MAX_U
#: Lines placed where the lines along the other axis err most.
PROBE_HOT_LINES = 4
#: Share of the target each axis is probed for: half, less a margin for the
#: columns and rows the probe does not see.
PROBE_SHARE = 0.4
#: Nodes of the reference axis on which the probe's columns and rows are placed.
_REF = 1001


def _line_levels(f: np.ndarray, ok: np.ndarray, intervals: int, min_nodes: int,
                 ends=("values", "values")) -> list:
    """For fine lines ``f`` (shape ``(values, lines, channels)``, ``intervals``
    intervals each), per line: ``[(k, err, at)]`` for ``k`` = 2, 4, 8, ...: the
    largest error at the allowed (``ok``, shape ``(values, lines)``) midpoints
    of the interpolating cubic spline through every ``k``-th value (at least
    ``min_nodes`` nodes), and where it is (fine node coordinate, 0 ..
    intervals). Each subsampling gets :data:`GHOST` ghost nodes as the table
    would (:func:`with_ghosts`): an end ``"values"`` reads them from the
    :func:`_ghosts` fine values the line holds beyond it."""
    ext = (f.shape[0] - 1 - intervals) // 2
    g = GHOST
    levels, k = [], 2
    while intervals // k + 1 >= min_nodes:
        n = intervals // k + 1
        mid = slice(ext + k // 2, ext + intervals, k)
        left = f[ext - g * k:ext:k] if ends[0] == "values" else ends[0]
        right = f[ext + intervals + k:ext + intervals + g * k + 1:k] \
            if ends[1] == "values" else ends[1]
        c = with_ghosts(f[ext:ext + intervals + 1:k], left, right)
        approx = _bspline_midpoints(bspline_coefficients(c, axis=0), 0, g, n)
        dev = np.where(ok[mid], np.abs(approx - f[mid]).max(axis=-1), 0.0)
        i = np.argmax(dev, axis=0)
        levels.append((k, dev[i, np.arange(dev.shape[1])], k // 2 + k * i))
        k *= 2
    return [[(k, float(e[line]), int(at[line])) for k, e, at in levels]
            for line in range(f.shape[1])]


def _ghosts(intervals: int, min_nodes: int) -> int:
    """Fine intervals a probe line extends beyond an end whose ghost nodes are
    evaluated: :data:`GHOST` nodes of its coarsest subsampling."""
    return GHOST * (1 << int(math.log2(intervals // (min_nodes - 1))))


def _nodes_for(levels: list, intervals: int, target: float, order: int) -> tuple:
    """Nodes a line of ``intervals`` fine intervals needs for an error ``target``,
    from its :func:`_line_levels`, interpolated in log-log between the finest
    level that fails and the one below it (local order clamped to [1, order]);
    whether the line resolved it (``False``: even ``k = 2`` fails, and the count
    is extrapolated); and where the failing level errs most (``None`` if none
    fails)."""
    prev = None
    for k, e, at in levels:
        if e > target:
            if prev is None:   # beyond the line's resolution: extrapolate
                e2 = levels[1][1] if len(levels) > 1 else e
                p = min(max(math.log2(max(e2, e) / e), 1.0), order)
                return intervals / (k * (target / e) ** (1.0 / p)) + 1.0, False, at
            p = min(max(math.log2(e / max(prev[1], 1e-300)), 1.0), order)
            ks = min(max(k * (target / e) ** (1.0 / p), prev[0]), k)
            return intervals / ks + 1.0, True, at
        prev = (k, e)
    return intervals / levels[-1][0] + 1.0, True, None


def _probe_columns(kind: str) -> np.ndarray:
    """u node coordinates (on a reference axis of :data:`_REF` nodes, twice that
    for a split axis) of the probe's lines along v: normal incidence, two
    oblique ones and the edge of the grazing sliver; split, more on both sides
    of the critical angle, just beyond which (the surface plasmon, and where
    ``R`` follows the ambient's index most steeply) tables err most."""
    # (just inside the verified range: the sliver's edge itself may round out of it)
    w_graz = 1.0 - math.sqrt(math.asin(1.001 * GRAZING_COS) / HALF_PI)
    if kind == "plain":
        return np.array([0.0, 0.5, 1.0 - math.sqrt(math.asin(0.1) / HALF_PI), w_graz]) * (_REF - 1)
    return np.concatenate([np.array([0.0, 0.5, 0.8, 0.95]) * (_REF - 1),
                           _REF + np.array([0.05, 0.15, 0.3, 0.5, w_graz]) * (_REF - 1)])


class _Curves:
    """The error curves of an axis's probe lines (:func:`_line_levels`): how many
    nodes the axis needs for a given error, as the worst of its lines."""

    def __init__(self, order: int, factor: int):
        self.order, self.factor = order, factor   # factor 2: a split axis's two segments
        self.lines = []    # (levels, intervals, fine)

    def need(self, target: float) -> float:
        """Nodes for ``target``; a coarse line that cannot resolve it defers to the
        fine lines, where there are any."""
        fine = any(f for _, _, f in self.lines)
        n = 0.0
        for levels, intervals, is_fine in self.lines:
            count, resolved, _ = _nodes_for(levels, intervals, target, self.order)
            if resolved or is_fine or not fine:
                n = max(n, count)
        return self.factor * n


def _probe(side: SideData, kind: str, error: float, axis: str, lines: np.ndarray,
           intervals: int, curves: _Curves, stats: dict, fine: bool = False) -> tuple:
    """Fine 1-D lines of exact values along ``axis`` (``"v"``: at the u node
    coordinates ``lines`` of a reference axis of :data:`_REF` nodes, twice that
    if split; ``"u"``: at the v coordinates ``lines`` of such an axis), each
    subsampled by 2, 4, 8, ...: a subsampling is a 1-D table whose error at its
    midpoints is known exactly (:func:`_line_levels`). The lines' error curves
    are added to ``curves``, the points evaluated to ``stats["probe_points"]``.

    Returns ``hot`` (``[(nodes, coordinate)]``: where on the other axis's
    reference each line errs most, for the lines that fail :data:`PROBE_SHARE`
    of ``error``, with the nodes they need for it) and the line that needs most
    ``(nodes, line, resolved)``.
    """
    split = kind == "tir"
    min_nodes = 65 if fine else 17
    ext = _ghosts(intervals, min_nodes)
    pts = _Points(side, kind)
    if axis == "v":
        pts.add(lines, np.arange(-ext, intervals + ext + 1.0), 2 * _REF if split else _REF,
                intervals + 1)
    elif split:
        pts.add(np.arange(2.0 * (intervals + 1)), lines, 2 * (intervals + 1), _REF)
    else:
        pts.add(np.arange(-ext, intervals + ext + 1.0), lines, intervals + 1, _REF, ghost=ext)
    ((vals, cos),) = pts.evaluate()
    stats["probe_points"] += pts.size
    if axis == "v":
        parts = [(vals, cos, ("values", "values"))]
    else:   # (lines, values, C) -> (values, lines, C)
        vals, cos = np.swapaxes(vals, 0, 1), cos.T
        m = intervals + 1   # a split axis: two segments of m nodes each
        parts = ([(vals[:m], cos[:m], SPLIT_ENDS[0]), (vals[m:], cos[m:], SPLIT_ENDS[1])]
                 if split else [(vals, cos, ("values", "values"))])
    hot, worst = [], (-1.0, None, True)
    for segment, (f, c, ends) in enumerate(parts):
        for i, levels in enumerate(_line_levels(f, c >= GRAZING_COS, intervals, min_nodes,
                                                ends)):
            curves.lines.append((levels, intervals, fine))
            n, resolved, at = _nodes_for(levels, intervals, PROBE_SHARE * error, curves.order)
            if n > worst[0]:
                worst = (n, lines[i], resolved)
            if at is not None:
                hot.append((n, segment * _REF + at / intervals * (_REF - 1)))
    return hot, worst


def _estimate(side: SideData, kind: str, error: float, max_texels: int, stats: dict):
    """``(nu, nv)`` for a first table, from :func:`_probe`.

    Resonances are narrow in both directions, so a fixed set of lines misses
    them: lines along u at five wavelengths find where along u each errs most;
    lines along v run at :func:`_probe_columns` and there; more lines along u
    run where those along v err most. An axis whose lines could not resolve
    :data:`PROBE_SHARE` of the target is probed again at its worst line, on a
    line fine enough to test :data:`MAX_V` / :data:`MAX_U`.

    The target is then split between the axes to minimise the texels: each
    axis's error curve is measured, and where one converges slowly (a kink of
    a tabulated index along λ is only first order) it is cheaper to give it
    most of the error. ``(None, None)`` where even the whole ``error`` per axis
    would need more than MAX_U, MAX_V or ``max_texels`` texels: a stack that no
    table resolves fails in milliseconds.
    """
    split = kind == "tir"
    cu, cv = _Curves(4, 2 if split else 1), _Curves(4, 1)

    def hot(found):
        return [c for _, c in sorted(found, reverse=True)[:PROBE_HOT_LINES]]

    u_rows = np.linspace(0.0, _REF - 1.0, 5)
    hot_u, worst_u = _probe(side, kind, error, "u", u_rows, PROBE_U, cu, stats)
    cols = np.unique(np.concatenate([_probe_columns(kind), hot(hot_u)]))
    hot_v, worst_v = _probe(side, kind, error, "v", cols, PROBE_V, cv, stats)
    if hot_v:
        _, w = _probe(side, kind, error, "u", np.unique(hot(hot_v)), PROBE_U, cu, stats)
        worst_u = max(worst_u, w, key=lambda x: x[0])
    for axis, (_, line, resolved), curves, fine in (("v", worst_v, cv, PROBE_V_FINE),
                                                    ("u", worst_u, cu, PROBE_U_FINE)):
        if not resolved:
            _probe(side, kind, error, axis, np.array([line]), fine, curves, stats, fine=True)
    if cu.need(error) > MAX_U or cv.need(error) > MAX_V \
            or cu.need(error) * cv.need(error) > max_texels:
        return None, None
    budget = 2.0 * PROBE_SHARE * error
    splits = [(cu.need(a * budget) * cv.need((1.0 - a) * budget), a)
              for a in np.linspace(0.1, 0.9, 17)]
    a = min(splits)[1]
    return cu.need(a * budget), cv.need((1.0 - a) * budget)


#: What the last :func:`build_table` did: ``kind``, ``probe_points`` and
#: ``points`` (exact evaluations by the probe and in all), ``rounds`` (tables
#: built and verified) and ``result`` ("table", "rejected by the probe", "over
#: budget", "critical angle varies"). For inspection only: under Mitsuba's
#: parallel scene loading, builds on other threads replace it.
last_build: dict = {}


def build_table(side: SideData, error: float, wavelengths: np.ndarray,
                max_texels: int = MAX_TEXELS) -> Table | None:
    """Build and verify a table of the exact values of one side, or ``None`` if
    the target cannot be met within ``max_texels`` texels and
    :data:`MAX_BUILD_POINTS` evaluations (or the exit medium's critical angle
    depends on λ). (Band-limited tables, for stacks this rejects:
    :func:`thinfilm_mi.tabulate.band.build_table`.)

    The table holds the coefficients of the interpolating cubic B-spline, on a
    plain u axis or on each segment of a split one (total internal
    reflection), whose ghost nodes come from :data:`SPLIT_ENDS`. The first
    resolution is the larger of :func:`table_resolution`'s (from the optical
    thickness) and the probe's (:func:`_estimate`, which also rejects hopeless
    stacks early). Verification: the exact values midway between neighbouring
    nodes along u (on every other v row) and along v (on every other u column)
    are compared with the interpolated ones; the sum of the two maxima (for
    incidence outside the grazing sliver, :data:`GRAZING_COS`) must be within
    ``error``. The cell across the critical angle of a split axis has zero
    width in angle and is skipped. Otherwise the axis that exceeds its share
    is refined, at the convergence order observed between rounds.

    What the build did is left in :data:`last_build`.
    """
    global last_build
    kind = tir_kind(side.n0(wavelengths), side.n_exit(wavelengths))
    last_build = stats = {"kind": kind, "probe_points": 0, "rounds": 0, "points": 0,
                          "result": "critical angle varies", "resolution": 0.0}
    if kind is None:
        return None
    g, order = GHOST, 4
    split = kind == "tir"
    side.absorbing = (tuple(bool(np.any(n(wavelengths).imag)) for n, _ in side.films)
                      + (bool(np.any(np.asarray(side.n_exit(wavelengths)).imag)),))
    nu, nv = table_resolution(side, error, wavelengths)
    pu, pv = _estimate(side, kind, error, max_texels, stats)
    stats["points"] = stats["probe_points"]
    if pu is None:
        stats["result"] = "rejected by the probe"
        return None
    nu = min(max(nu, int(math.ceil(1.05 * pu))), MAX_U)
    nv = min(max(nv, int(math.ceil(1.05 * pv))), MAX_V)
    stats["result"] = "over budget"
    history = {}
    for _ in range(MAX_ROUNDS + 1):
        if split:
            nu += nu % 2
        # the nodes (a split axis's ghosts are not evaluated), and the checks
        points = (nu + (0 if split else 2 * g)) * (nv + 2 * g) + nu * nv \
            + len(side.kinks) * (nu // 2)
        if (nu > MAX_U or nv > MAX_V or nu * nv > max_texels
                or stats["points"] + points > MAX_BUILD_POINTS):
            return None
        stats["points"] += points
        stats["rounds"] += 1
        m = nu // 2
        su = np.arange(0 if split else -g, nu + (0 if split else g), dtype=np.float64)
        tv = np.arange(-g, nv + g, dtype=np.float64)
        mu = np.arange(nu - 1) + 0.5
        if split:
            mu = mu[mu != m - 0.5]
        rows = np.arange(0, nv, 2) + g      # every other real v row (index into tv)
        cols = np.arange(0, nu, 2)          # every other real u node
        # Where an index's slope jumps (tabulated data) the spline errs most
        # beside, not between, the nodes: check there too.
        kinks = v_texel(side.kinks, nv)
        pts = _Points(side, kind)
        pts.add(su, tv, nu, nv)
        pts.add(mu, tv[rows], nu, nv)
        pts.add(cols.astype(np.float64), np.concatenate([np.arange(nv - 1) + 0.5, kinks]),
                nu, nv)
        (nodes, _), (mid_u, cos_u), (mid_v, cos_v) = pts.evaluate()
        # Spline coefficients along u, per segment with its ghosts, then along v.
        if split:
            segs = [np.moveaxis(with_ghosts(np.moveaxis(part, 1, 0), *ends), 0, 1)
                    for part, ends in zip((nodes[:, :m], nodes[:, m:]), SPLIT_ENDS)]
            cu = [bspline_coefficients(seg, axis=1) for seg in segs]
            approx_u = np.concatenate([_bspline_midpoints(c[rows], 1, g, m) for c in cu],
                                      axis=1)
            cu = np.concatenate(cu, axis=1)
            texel = cols + g + np.where(cols >= m, 2 * g, 0)
        else:
            cu = bspline_coefficients(nodes, axis=1)
            approx_u = _bspline_midpoints(cu[rows], 1, g, nu)
            texel = cols + g
        coeffs = bspline_coefficients(cu, axis=0)
        # The spline along v through node column j has the coefficients
        # B_u coeffs (B_u: the u spline's (1, 4, 1) / 6 at its nodes).
        cv = (coeffs[:, texel - 1] + 4.0 * coeffs[:, texel] + coeffs[:, texel + 1]) / 6.0
        approx_v = np.concatenate([_bspline_midpoints(cv, 0, g, nv), _bspline_at(cv, kinks, g)])
        dev = np.abs(mid_u - approx_u).max(axis=-1)
        err_u = float(np.max(np.where(cos_u >= GRAZING_COS, dev, 0.0)))
        dev = np.abs(mid_v - approx_v).max(axis=-1)
        err_v = float(np.max(np.where(cos_v >= GRAZING_COS, dev, 0.0)))
        stats.setdefault("errors", []).append((nu, nv, err_u, err_v))
        if err_u + err_v <= error:
            stats["result"] = "table"
            return Table(coeffs, kind, err_u + err_v, nodes.shape[-1])
        # Refine: aim at REFINE_SHARE of the target; an axis already within
        # half of that keeps its nodes and leaves the rest to the other.
        budget = REFINE_SHARE * error
        if err_u <= 0.5 * budget:
            goal = {"u": err_u, "v": budget - err_u}
        elif err_v <= 0.5 * budget:
            goal = {"u": budget - err_v, "v": err_v}
        else:
            goal = {"u": 0.5 * budget, "v": 0.5 * budget}
        factors = {}
        for axis, n, err in (("u", nu, err_u), ("v", nv, err_v)):
            if err <= goal[axis]:
                factors[axis] = 1.0
                continue
            # Once the fringes are resolved the error falls as h^order; before
            # that more slowly: use the order seen since the last round.
            p, last = order, history.get(axis)
            if last is not None and last[0] != n and last[1] > 0 and err > 0:
                p = min(max(math.log(last[1] / err) / math.log((n - 1) / (last[0] - 1)), 1.0),
                        order)
            factors[axis] = min(3.0, 1.05 * (err / goal[axis]) ** (1.0 / p))
            history[axis] = (n, err)
        if nu * nv * factors["u"] * factors["v"] > 4 * max_texels:
            return None   # hopeless within the budget: do not spend the time
        nu = int(math.ceil((nu - 1) * factors["u"])) + 1
        nv = int(math.ceil((nv - 1) * factors["v"])) + 1
    return None


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
