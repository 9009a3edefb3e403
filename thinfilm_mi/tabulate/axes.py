"""The angle axes of the tables: one object per kind of axis, registered in :data:`AXES`.

A table's angle axis maps an incidence direction to a continuous node coordinate
(:meth:`AngleAxis.texel`, Dr.Jit math traced into the render kernels) and back
(:meth:`AngleAxis.nodes_cos`, float64 numpy for the builds). Each kind keeps all of
its own code here:

* :data:`PLAIN` (``"plain"``): uniform in ``w = 1 - sqrt(1 - θ / (π/2))``, one
  segment whose :data:`GHOST` nodes beyond either end are evaluated (the stack's
  analytic continuation); used where the exit medium cannot totally reflect.
* :data:`TIR` (``"tir"``): split at the critical angle of an exit medium of lower
  (real) index: the transmit segment uniform in the refraction angle ``θ_t``, the
  total-reflection segment in the same ``w`` of ``φ = atan(|q_exit| / q_0)``; each
  segment a spline of its own, its ghosts mirrored or extrapolated
  (:data:`SPLIT_ENDS`). Its coordinate depends on the indices at the lookup's
  wavelength (:attr:`AngleAxis.needs_n_exit`).
* :data:`BAND` (``"band"``): the plain axis blended with a warp that puts more nodes
  at mid angles (:func:`band_warp`), for band-limited tables
  (:mod:`thinfilm_mi.tabulate.band`).

:func:`axis_for` picks the axis of a lit side from its indices; :func:`angle_axis`
looks one up by name (the name is what the table store keeps on disk). A new kind
of axis is one class and one entry in :data:`AXES`.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod

import drjit as dr
import numpy as np

__all__ = ["AXES", "BAND", "BAND_MID", "BAND_WARP", "EXTRAPOLATE", "GHOST", "HALF_PI", "MIRROR",
           "PLAIN", "SPLIT_ENDS", "TIR", "AngleAxis", "BandAxis", "ExtrapolateEnd", "GhostEnd",
           "MirrorEnd", "PlainAxis", "TirAxis", "angle_axis", "axis_for", "band_cos", "band_warp"]

HALF_PI = 0.5 * math.pi
#: Nodes beyond each end of a segment of a cubic table's axis (evaluated exactly,
#: outside the tabulated range): the spline's end conditions perturb it by a factor
#: (2 - sqrt 3) = 0.27 less per node inwards, 2 % at the first real node.
GHOST = 3


class GhostEnd(ABC):
    """How the ghost nodes beyond one end of a segment are made from its own nodes
    (:func:`~thinfilm_mi.tabulate.base.with_ghosts`); an end whose ghosts are evaluated
    (the stack's analytic continuation) has no such object."""

    @abstractmethod
    def outwards(self, inner: np.ndarray, g: int) -> np.ndarray:
        """The ghosts at ``-1, -2, ..., -g`` of the nodes ``inner[0], inner[1], ...``
        (axis 0, from the end inwards)."""


class MirrorEnd(GhostEnd):
    """The function is even about the end node: ``f(-k) = f(k)``."""

    def outwards(self, inner, g):
        return inner[1:g + 1]


class ExtrapolateEnd(GhostEnd):
    """The cubic through the four nodes nearest the end, where no continuation can be
    evaluated (at a critical angle)."""

    def outwards(self, inner, g):
        f0, f1, f2, f3 = inner[0], inner[1], inner[2], inner[3]
        return np.stack([4 * f0 - 6 * f1 + 4 * f2 - f3,
                         10 * f0 - 20 * f1 + 15 * f2 - 4 * f3,
                         20 * f0 - 45 * f1 + 36 * f2 - 10 * f3][:g])


MIRROR, EXTRAPOLATE = MirrorEnd(), ExtrapolateEnd()
#: How each end of a segment of a split axis gets its ghost nodes: the transmit
#: segment is even about normal incidence (uniform in the refraction angle), the
#: total-reflection segment about grazing incidence (``w = 1``), and both are
#: extrapolated at the critical angle, beyond which they do not continue.
SPLIT_ENDS = ((MIRROR, EXTRAPOLATE), (EXTRAPOLATE, MIRROR))
#: Share of the mid-angle term ``S`` in the angle axis of band-limited tables
#: (:meth:`BandAxis.texel`), and the share of ``sin²(2a)`` in its density. Chosen from
#: the interpolation error of ``R_σ`` per 5° of incidence on the plain axis (10-film
#: benchmark stack, 129 nodes: 8e-5 at 80-85°, 2.5e-2 at 45-50°): the blend that
#: equalises it needs ~0.6x the nodes.
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


class AngleAxis(ABC):
    """One kind of angle axis (see the module). Attributes:

    * ``name``: the key in :data:`AXES` (kept by the table store and the build reports);
    * ``segments``: splines side by side along the axis (2 where it is split at a
      critical angle, each with its own ghost nodes);
    * ``needs_n_exit``: whether the coordinate depends on the real indices ``n0``,
      ``n_exit`` at the lookup's wavelength (else it is one per direction);
    * ``ghosts_evaluated``: whether the ghost nodes beyond the ends are evaluated (the
      stack's analytic continuation) rather than made from the segment's values
      (:attr:`ends`);
    * ``mirror``: whether the linear tables' 4-point rule may continue the values
      evenly beyond both ends (:func:`~thinfilm_mi.tabulate.refine.midpoints4`);
    * ``band_limited``: the axis a band-limited table of a side with this axis uses.
    """
    name = ""
    segments = 1
    needs_n_exit = False
    ghosts_evaluated = True
    mirror = True
    #: per segment, how the ghosts at its two ends are made (:class:`GhostEnd`; ``None``:
    #: evaluated)
    ends: tuple = ((None, None),)

    @property
    def split(self) -> bool:
        """Whether the axis has more than one segment."""
        return self.segments > 1

    @property
    def band_limited(self) -> "AngleAxis":
        return self

    @abstractmethod
    def texel(self, cos_i, sin_i, n0, n_exit, nu):
        """The continuous node coordinate (0 .. nu-1) of an incidence direction
        (Dr.Jit math, or numpy). ``n0`` and ``n_exit`` are the real indices at the
        lookup's wavelength (read only where :attr:`needs_n_exit`); ``nu`` (the number
        of angle nodes) may be a Python number or an opaque Float, so that the kernel
        does not depend on the table's shape."""

    @abstractmethod
    def nodes_cos(self, s: np.ndarray, n0: np.ndarray, n_exit: np.ndarray, nu: int,
                  ghost: int = GHOST) -> np.ndarray:
        """Inverse of :meth:`texel` (float64 numpy): cos(θ_i) at node coordinates ``s``
        (any shape broadcasting with the per-λ ``n0``, ``n_exit``), up to ``ghost``
        nodes beyond the ends where :attr:`ghosts_evaluated`."""

    def __repr__(self) -> str:
        return f"AXES[{self.name!r}]"


def _w(cos_i, sin_i):
    """``x = (π/2 - θ) / (π/2)`` and ``w = 1 - sqrt(x)`` of a direction (``atan2``:
    free of cancellation)."""
    x = (1.0 / HALF_PI) * dr.atan2(cos_i, sin_i)
    return x, 1.0 - dr.sqrt(x)


class PlainAxis(AngleAxis):
    """Uniform in ``w = 1 - sqrt(x)``, ``x = (π/2 - θ) / (π/2)``: ``w`` is analytic at
    both ends (``R`` is even in the angle at normal incidence) and puts nodes
    quadratically closer towards grazing incidence, where coated metals show their
    sharp pseudo-Brewster dip and the rise to ``R = 1``."""
    name = "plain"

    @property
    def band_limited(self) -> AngleAxis:
        return BAND   # more nodes at mid angles, where R_σ's features move fastest

    def texel(self, cos_i, sin_i, n0, n_exit, nu):
        _, w = _w(cos_i, sin_i)
        return (nu - 1) * w

    def nodes_cos(self, s, n0, n_exit, nu, ghost=GHOST):
        """``w < 0`` continues to negative angles (``cos`` of ``|θ|``) and ``w > 1``
        mirrors about grazing incidence (``cos = sin((1 - w)^2 π/2)`` is even about
        ``w = 1``), both the analytic continuation of ``R(w)``."""
        w = np.clip(s / (nu - 1), -ghost / (nu - 1), 1.0 + ghost / (nu - 1))
        return np.sin((1.0 - w) ** 2 * HALF_PI)

    @staticmethod
    def probe_columns(ref: int, w_graz: float) -> np.ndarray:
        """u node coordinates (on a reference axis of ``ref`` nodes) of the exact
        build's probe lines along v: normal incidence, two oblique ones and the edge of
        the grazing sliver (at ``w_graz``)."""
        return np.array([0.0, 0.5, 1.0 - math.sqrt(math.asin(0.1) / HALF_PI), w_graz]) * (ref - 1)


class BandAxis(PlainAxis):
    """The plain ``w`` blended with ``S = 2a/π - (m sin(4a)/2 + (1 - m) sin(2a)) / π``
    (``m`` = :data:`BAND_MID`), whose node density ``∝ m sin²(2a) + (1 - m) sin²(a)``
    rises to mid and high angles: ``BAND_WARP S + (1 - BAND_WARP) w``. A band-limited
    ``R``'s features move along λ as the angle changes, fastest between 30° and 75°,
    where ``w`` alone is sparsest. Its rows are at ``s / (nu - 1)`` in
    :func:`band_warp`'s coordinate, ghosts included (evaluated)."""
    name = "band"

    @property
    def band_limited(self) -> AngleAxis:
        return self

    def texel(self, cos_i, sin_i, n0, n_exit, nu):
        x, w = _w(cos_i, sin_i)
        sin2 = 2.0 * sin_i * cos_i
        sin4 = 2.0 * sin2 * (cos_i * cos_i - sin_i * sin_i)
        S = (1.0 - x) - (0.5 * BAND_MID * sin4 + (1.0 - BAND_MID) * sin2) * (0.5 / HALF_PI)
        w = BAND_WARP * S + (1.0 - BAND_WARP) * w
        return (nu - 1) * w

    def nodes_cos(self, s, n0, n_exit, nu, ghost=GHOST):
        return band_cos(np.clip(s, -ghost, nu - 1 + ghost) / (nu - 1))

    @staticmethod
    def rows(nu: int):
        """Row coordinates (of :meth:`row_cos`) of a band-limited table with ``nu``
        angle nodes: ``(nodes, mids)``, the nodes with their ghosts."""
        s = np.arange(-GHOST, nu + GHOST, dtype=np.float64)
        return s / (nu - 1), (np.arange(nu - 1) + 0.5) / (nu - 1)

    @staticmethod
    def row_cos(x: np.ndarray, n0, n_exit) -> np.ndarray:
        """cos θ_i of rows at ``x`` (:func:`band_cos`: ghosts beyond [0, 1]; the
        indices are not read)."""
        return band_cos(x)


class TirAxis(AngleAxis):
    """Split at the critical angle, which sits exactly on a node at every wavelength:
    nodes ``0 .. m-1`` (``m = nu / 2``) uniform in ``θ_t`` up to the critical angle,
    nodes ``m .. nu-1`` uniform in ``w`` of ``φ`` beyond it; ``R`` and ``T`` are
    analytic in both. A split table has an even ``nu``."""
    name = "tir"
    segments = 2
    needs_n_exit = True
    ghosts_evaluated = False
    mirror = False
    ends = SPLIT_ENDS

    def texel(self, cos_i, sin_i, n0, n_exit, nu):
        m = 0.5 * nu            # split tables have an even nu: nodes 0..m-1 | m..nu-1
        beta = n0 * sin_i
        d2 = (n_exit - beta) * (n_exit + beta)            # q_exit^2
        q_exit = dr.sqrt(dr.maximum(d2, 0.0))
        a = dr.sqrt(dr.maximum(-d2, 0.0))                 # |q_exit| beyond the critical angle
        theta_t = dr.atan2(beta, q_exit)
        x = (1.0 / HALF_PI) * dr.atan2(n0 * cos_i, a)     # 1 - phi / (pi/2)
        return dr.select(d2 > 0, (m - 1) * (1.0 / HALF_PI) * theta_t,
                         m + (m - 1) * (1.0 - dr.sqrt(x)))

    def nodes_cos(self, s, n0, n_exit, nu, ghost=GHOST):
        m = nu // 2
        t = np.clip(s / (m - 1), 0.0, 1.0) * HALF_PI          # transmit segment: theta_t
        beta = n_exit * np.sin(t)
        cos_t = np.sqrt(np.maximum(1.0 - (beta / n0) ** 2, 0.0))
        rho = np.sqrt(np.maximum(n0 * n0 - n_exit * n_exit, 0.0))
        w = np.clip((s - m) / (m - 1), 0.0, 1.0)             # TIR segment
        cos_p = rho * np.sin((1.0 - w) ** 2 * HALF_PI) / n0
        return np.where(s < m - 0.5, cos_t, cos_p)

    @staticmethod
    def probe_columns(ref: int, w_graz: float) -> np.ndarray:
        """The exact build's probe columns on a reference axis of ``2 ref`` nodes: more
        on both sides of the critical angle, just beyond which (the surface plasmon,
        and where ``R`` follows the ambient's index most steeply) tables err most."""
        return np.concatenate([np.array([0.0, 0.5, 0.8, 0.95]) * (ref - 1),
                               ref + np.array([0.05, 0.15, 0.3, 0.5, w_graz]) * (ref - 1)])

    @staticmethod
    def rows(nu: int):
        """Row coordinates (of :meth:`row_cos`) of a band-limited table with ``nu``
        angle nodes: ``(nodes, mids)``; the ghosts are not evaluated and the critical
        cell has no midpoint."""
        m = nu // 2
        seg = np.arange(m, dtype=np.float64) / (m - 1)
        mid = (np.arange(m - 1) + 0.5) / (m - 1)
        return np.concatenate([seg, 2.0 + seg]), np.concatenate([mid, 2.0 + mid])

    @staticmethod
    def row_cos(x: np.ndarray, n0: np.ndarray, n_exit: np.ndarray) -> np.ndarray:
        """cos θ_i of rows at ``x`` (broadcasting with the real indices): the transmit
        segment at ``x`` in [0, 1] (fraction of θ_t's quarter turn), the
        total-reflection segment at ``2 + w``."""
        t = np.clip(x, 0.0, 1.0) * HALF_PI
        cos_t = np.sqrt(np.maximum(1.0 - (n_exit * np.sin(t) / n0) ** 2, 0.0))
        rho = np.sqrt(np.maximum(n0 * n0 - n_exit * n_exit, 0.0))
        w = np.clip(x - 2.0, 0.0, 1.0)
        return np.where(x < 1.5, cos_t, rho * np.sin((1.0 - w) ** 2 * HALF_PI) / n0)


PLAIN, TIR, BAND = PlainAxis(), TirAxis(), BandAxis()
#: Every kind of angle axis by name (stateless objects, shared).
AXES = {axis.name: axis for axis in (PLAIN, TIR, BAND)}


def angle_axis(name: str) -> AngleAxis:
    """The axis registered as ``name`` (a stored table's ``kind``)."""
    try:
        return AXES[name]
    except (KeyError, TypeError):
        raise ValueError(f"angle axis: expected one of {sorted(AXES)}, got {name!r}") from None


def axis_for(n0: np.ndarray, n_exit: np.ndarray) -> AngleAxis | None:
    """:data:`TIR` if the exit medium is real and of lower index than ``n0`` at every
    node wavelength, :data:`PLAIN` if it never is, ``None`` if it changes with λ (not
    tabulated: the kink would cross nodes)."""
    real = np.all(np.abs(n_exit.imag) <= 1e-6)
    lower = n_exit.real < n0
    if real and np.all(lower):
        return TIR
    if not real or not np.any(lower):
        return PLAIN
    return None
