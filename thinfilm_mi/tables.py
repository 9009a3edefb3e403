"""Tables of a stack's reflectance and transmittance over (angle, wavelength).

Hirayama et al. (sec. 4) precompute ``k_r`` and ``k_t`` at sampled incidence
angles and wavelengths and interpolate linearly, which they found 6x faster than
the recursion at every hit. Here a table is a ``Texture2f`` (Dr.Jit's bilinear
texture, float32) whose channels are the unpolarised ``R`` and, where a BSDF
needs it, ``T`` of one lighting side of the stack. It is built in float64 with
the optics core (:func:`thinfilm_mi.kernel.unpolarised_rt` on
``drjit.llvm.Float64``) and looked up in the render kernel, where its cost does
not depend on the number of films.

Axes (chosen so that the tabulated functions are smooth, hence linear
interpolation converges as h^2 everywhere):

* wavelength: uniform in wavenumber ``1/lambda`` over 360-830 nm, in which an
  interference fringe has a constant period;
* angle: when the exit medium cannot totally reflect, uniform in
  ``w = 1 - sqrt(1 - theta / (pi/2))`` (the films' responses are even in their
  ``q``, so ``R`` is analytic in ``theta``, and in ``w``; nodes crowd towards
  grazing incidence, where coated metals dip sharply and rise to ``R = 1``).
  When it can (light inside glass, exit medium of lower index), ``R`` has a
  square-root kink at the critical angle. The axis is then split at the
  critical angle, which sits exactly on a node at every wavelength: below it
  the axis is uniform in the refraction angle ``theta_t`` in the exit medium,
  above it in the same ``w`` of ``phi = atan(|q_exit| / q_0)``; ``R`` and ``T``
  are analytic in both.

The resolution is chosen from the stack's optical thickness (fringes narrow as
``n d`` grows) and then *verified*: the exact values at the midpoints between
nodes along each axis are compared with the interpolated ones, and the axis
whose error is too large is refined until the sum of both axes' maximum errors
is within the target (default 1e-3 in ``R`` and ``T``). A stack that would need
more than :data:`MAX_TEXELS` texels is not tabulated.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import drjit as dr
import numpy as np

from .optics import Cx
from .stack import SPECTRAL_RANGE

__all__ = ["SideData", "Table", "build_table", "table_resolution", "MAX_TEXELS"]

SIGMA_MAX = 1.0 / SPECTRAL_RANGE[0]   # 1/nm at 360 nm
SIGMA_MIN = 1.0 / SPECTRAL_RANGE[1]   # 1/nm at 830 nm
HALF_PI = 0.5 * math.pi

#: Largest table (texels per channel) built; beyond it a stack is evaluated exactly.
MAX_TEXELS = 1 << 22
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
#: Exact evaluations a build may spend (all rounds, nodes and checks), about
#: 0.3 s on one core: a stack that needs more (sharp resonances, such as the
#: surface plasmon of a metal film seen from inside glass) is evaluated exactly.
MAX_BUILD_POINTS = 3_000_000
#: Refinement rounds after the first estimate.
MAX_ROUNDS = 6


@dataclass
class SideData:
    """One lighting side of a stack, with every index on the wavelength nodes.

    ``n0`` is the (real) index of the medium the light comes from, ``films``
    ``(index, thickness_nm)`` pairs from that side inwards (index: complex numpy
    array over ``wavelengths``), ``n_exit`` the complex exit index. ``rt`` is
    the evaluator ``(n0, cos0, films, n_exit, wl, transmission) -> R | (R, T)``
    (the coherent :func:`~thinfilm_mi.kernel.unpolarised_rt` or the
    incoherent-aware one), ``transmission`` whether ``T`` is tabulated too.
    """
    n0: object                      # callable wl -> real ndarray
    films: list                     # [(callable wl -> complex ndarray, thickness)]
    n_exit: object                  # callable wl -> complex ndarray
    transmission: bool
    rt: object
    fringe_films: list = field(default_factory=list)  # indices of coherent films


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
def u_texel(cos_i, sin_i, n0, n_exit, kind: str, nu: int):
    """The continuous texel coordinate (0 .. nu-1) of an incidence direction.

    ``n0`` and ``n_exit`` are the real indices at the lookup's wavelength. An
    angle ``a`` in [0, pi/2] that ends at grazing incidence is mapped through
    ``w = 1 - sqrt(x)`` with ``x = (pi/2 - a) / (pi/2)`` (computed as
    ``atan2(cos, sin)``, free of cancellation): ``w`` is analytic at both ends
    (``R`` is even in the angle at normal incidence) and puts nodes
    quadratically closer towards grazing incidence, where coated metals show
    their sharp pseudo-Brewster dip and the rise to ``R = 1``.
    """
    if kind == "plain":
        x = (1.0 / HALF_PI) * dr.atan2(cos_i, sin_i)
        return (nu - 1) * (1.0 - dr.sqrt(x))
    m = nu // 2
    beta = n0 * sin_i
    d2 = (n_exit - beta) * (n_exit + beta)            # q_exit^2
    q_exit = dr.sqrt(dr.maximum(d2, 0.0))
    a = dr.sqrt(dr.maximum(-d2, 0.0))                 # |q_exit| beyond the critical angle
    theta_t = dr.atan2(beta, q_exit)
    x = (1.0 / HALF_PI) * dr.atan2(n0 * cos_i, a)     # 1 - phi / (pi/2)
    return dr.select(d2 > 0, (m - 1) * (1.0 / HALF_PI) * theta_t,
                     m + (m - 1) * (1.0 - dr.sqrt(x)))


def _u_nodes_cos(s: np.ndarray, n0: np.ndarray, n_exit: np.ndarray, kind: str, nu: int):
    """Inverse of :func:`u_texel` (float64 numpy): cos(theta_i) at texel
    coordinates ``s`` (any shape broadcasting with the per-λ ``n0``, ``n_exit``)."""
    if kind == "plain":
        w = np.clip(s / (nu - 1), 0.0, 1.0)
        return np.sin((1.0 - w) ** 2 * HALF_PI)
    m = nu // 2
    t = np.clip(s / (m - 1), 0.0, 1.0) * HALF_PI          # transmit segment: theta_t
    beta = n_exit * np.sin(t)
    cos_t = np.sqrt(np.maximum(1.0 - (beta / n0) ** 2, 0.0))
    rho = np.sqrt(np.maximum(n0 * n0 - n_exit * n_exit, 0.0))
    w = np.clip((s - m) / (m - 1), 0.0, 1.0)             # TIR segment
    cos_p = rho * np.sin((1.0 - w) ** 2 * HALF_PI) / n0
    return np.where(s < m - 0.5, cos_t, cos_p)


def v_texel(wavelength, nv: int):
    """Texel coordinate (0 .. nv-1) of a wavelength: uniform in 1/λ, 360 nm at 0."""
    return (SIGMA_MAX - 1.0 / wavelength) * ((nv - 1) / (SIGMA_MAX - SIGMA_MIN))


def _v_nodes_wl(t: np.ndarray, nv: int) -> np.ndarray:
    sigma = SIGMA_MAX + (SIGMA_MIN - SIGMA_MAX) * (np.asarray(t, np.float64) / (nv - 1))
    return 1.0 / sigma


# -- resolution ----------------------------------------------------------------
def table_resolution(side: SideData, error: float, wavelengths: np.ndarray) -> tuple[int, int]:
    """First estimate of ``(nu, nv)`` for a target max error ``error``.

    Linear interpolation of a fringe ``A cos(phi)`` sampled every ``h`` in
    phase errs by at most ``A h^2 / 8``; with ``A = 1`` (a conservative
    amplitude) and half the target for each axis, ``h = sqrt(4 error)``. The total phase over the wavenumber range
    is ``4 pi sum_j n_j d_j (sigma_max - sigma_min)`` and over the angles
    ``4 pi / lambda_min sum_j d_j (Re q_j(0) - Re q_j(grazing))``; each axis gets
    enough nodes for its phase range at that step (plus a floor for the Fresnel
    terms). The estimate is then verified and refined by :func:`build_table`.
    """
    h = math.sqrt(4.0 * error)
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


# -- building -------------------------------------------------------------------
class Table:
    """A built table: a float32 ``Texture2f`` (channels ``R`` [, ``T``]) with its axes."""

    def __init__(self, values: np.ndarray, kind: str, error: float, channels: int):
        import mitsuba as mi

        self.nv, self.nu = values.shape[:2]
        self.kind = kind
        self.channels = channels
        #: the verified max abs interpolation error (sum of both axes' maxima)
        self.error = error
        tensor = mi.TensorXf(np.ascontiguousarray(values, dtype=np.float32))
        self.texture = mi.Texture2f(tensor, use_accel=False, migrate=False,
                                    filter_mode=dr.FilterMode.Linear,
                                    wrap_mode=dr.WrapMode.Clamp)

    @property
    def texels(self) -> int:
        return self.nu * self.nv

    def lookup(self, cos_i, n0, n_exit, wavelengths, active=True):
        """``[R]`` or ``[R, T]`` as spectra: one bilinear lookup per wavelength.

        ``cos_i`` (>= 0) is a Float; ``n0``, ``n_exit`` (real parts) and
        ``wavelengths`` are ``mi.Spectrum``.
        """
        import mitsuba as mi

        cos_i = dr.clip(cos_i, 0.0, 1.0)
        sin_i = dr.safe_sqrt((1.0 - cos_i) * (1.0 + cos_i))
        out = [[] for _ in range(self.channels)]
        if self.kind == "plain":
            u = (u_texel(cos_i, sin_i, 1.0, 1.0, "plain", self.nu) + 0.5) * (1.0 / self.nu)
        for i in range(len(wavelengths)):
            if self.kind != "plain":
                u = (u_texel(cos_i, sin_i, n0[i], n_exit[i], self.kind, self.nu) + 0.5) \
                    * (1.0 / self.nu)
            v = (v_texel(wavelengths[i], self.nv) + 0.5) * (1.0 / self.nv)
            res = self.texture.eval(mi.Point2f(u, v), active)
            for c in range(self.channels):
                out[c].append(res[c])
        return [mi.Spectrum(*vals) for vals in out]


def _evaluate(side: SideData, cos0: np.ndarray, wl: np.ndarray) -> np.ndarray:
    """Exact float64 R [, T] on a grid: ``cos0`` of shape (len wl, M), one row per
    wavelength of ``wl``; returns shape (len wl, M, channels). The indices are
    evaluated once per wavelength and repeated along the row."""
    from drjit.llvm import Float64

    cols = cos0.shape[1]

    def real(values):
        return Float64(np.repeat(np.asarray(values, np.float64), cols))

    def cx(values):
        values = np.repeat(np.asarray(values, np.complex128), cols)
        return Cx(Float64(np.ascontiguousarray(values.real)), Float64(np.ascontiguousarray(values.imag)))

    films = []
    for n, d in side.films:
        thickness = Float64(float(d))
        dr.make_opaque(thickness)
        films.append((cx(n(wl)), thickness))
    res = side.rt(real(side.n0(wl)), Float64(np.ascontiguousarray(cos0, np.float64).ravel()),
                  films, cx(side.n_exit(wl)), real(wl), side.transmission)
    res = res if side.transmission else (res,)
    dr.eval(*res)
    return np.stack([np.array(r, dtype=np.float64) for r in res], axis=-1).reshape(
        len(wl), cols, -1)


def _grid(side: SideData, kind: str, s: np.ndarray, t: np.ndarray, nu: int, nv: int,
          with_cos: bool = False):
    """Exact values at texel coordinates ``s`` (u, 1-D) x ``t`` (v, 1-D): (len t, len s, C)
    (and the cosines of incidence, (len t, len s), if ``with_cos``)."""
    wl = _v_nodes_wl(t, nv)
    n0 = side.n0(wl)[:, None]
    ne = side.n_exit(wl).real[:, None]
    cos0 = np.broadcast_to(_u_nodes_cos(s[None, :], n0, ne, kind, nu), (len(t), len(s)))
    vals = _evaluate(side, cos0, wl)
    return (vals, cos0) if with_cos else vals


def build_table(side: SideData, error: float, wavelengths: np.ndarray,
                max_texels: int = MAX_TEXELS, start: tuple[int, int] | None = None) -> Table | None:
    """Build and verify a table for one side, or ``None`` if the target cannot be
    met within ``max_texels`` (or the exit medium's critical angle depends on λ).

    Verification: the exact values midway between neighbouring nodes along u
    (on every other v row) and along v (on every other u column) are compared
    with the interpolated ones; the sum of the two maxima (for incidence
    outside the grazing sliver, :data:`GRAZING_COS`) must be within ``error``. The cell across the critical angle of a split axis has zero
    width in angle and is skipped. ``start`` (the resolution of the previous
    table of the same stack) is used instead of the estimate when it is finer:
    a table whose shape does not change reuses the render kernel.
    """
    kind = tir_kind(side.n0(wavelengths), side.n_exit(wavelengths))
    if kind is None:
        return None
    nu, nv = table_resolution(side, error, wavelengths)
    if start is not None:
        nu, nv = max(nu, start[0]), max(nv, start[1])
    spent = 0
    for _ in range(MAX_ROUNDS + 1):
        if kind == "tir":
            nu += nu % 2
        spent += 2 * nu * nv   # the nodes, and half as many points along each axis
        if nu > MAX_U or nv > MAX_V or nu * nv > max_texels or spent > MAX_BUILD_POINTS:
            return None
        su = np.arange(nu, dtype=np.float64)
        tv = np.arange(nv, dtype=np.float64)
        nodes = _grid(side, kind, su, tv, nu, nv)
        mu = su[:-1] + 0.5
        if kind == "tir":
            mu = mu[mu != nu // 2 - 0.5]
        lo = np.floor(mu).astype(int)
        rows = nodes[::2]
        mid_u, cos_u = _grid(side, kind, mu, tv[::2], nu, nv, with_cos=True)
        dev = np.abs(mid_u - 0.5 * (rows[:, lo] + rows[:, lo + 1])).max(axis=-1)
        err_u = float(np.max(np.where(cos_u >= GRAZING_COS, dev, 0.0)))
        cols = nodes[:, ::2]
        mid_v, cos_v = _grid(side, kind, su[::2], tv[:-1] + 0.5, nu, nv, with_cos=True)
        dev = np.abs(mid_v - 0.5 * (cols[:-1] + cols[1:])).max(axis=-1)
        err_v = float(np.max(np.where(cos_v >= GRAZING_COS, dev, 0.0)))
        if err_u + err_v <= error:
            return Table(nodes, kind, err_u + err_v, nodes.shape[-1])
        # Interpolation error goes as h^2 once fringes are resolved: refine the
        # offending axis (10% margin, at most 3x a round: far from convergence
        # the h^2 law overshoots).
        fu = 1.1 * math.sqrt(err_u / (0.5 * error)) if err_u > 0.5 * error else 1.0
        fv = 1.1 * math.sqrt(err_v / (0.5 * error)) if err_v > 0.5 * error else 1.0
        if nu * nv * fu * fv > 4 * max_texels:
            return None   # hopeless within the budget: do not spend the time
        nu = int(math.ceil((nu - 1) * min(3.0, fu))) + 1
        nv = int(math.ceil((nv - 1) * min(3.0, fv))) + 1
    return None
