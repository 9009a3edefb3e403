"""Refinement shared by the table builders: what a build may spend, how fine it
starts, and how it decides where to add nodes.

* :class:`Budget`: the exact evaluations and texels a build may spend, decided
  before the work; every builder asks it before a round and records what the
  round cost (the account goes into the build's :class:`~thinfilm_mi.tabulate.base.BuildReport`);
  :func:`build_work` weighs evaluations by the stack's depth.
* :func:`optical_thickness` and :func:`power_of_two_step`: the first sample step
  from the stack's whole optical thickness ``Σ n_j d_j`` (its narrowest fringe),
  used along the wavelength by the colour integrals and along the wavenumber by
  the band-limited rows.
* :func:`convergence_factor`: by how much to multiply an axis's nodes to reach a
  target error, at the convergence order observed between two rounds (the
  cubic tables of :mod:`~thinfilm_mi.tabulate.exact` and :mod:`~thinfilm_mi.tabulate.band`).
* The 4-point rule of the linear tables (:mod:`~thinfilm_mi.tabulate.integrated`,
  :mod:`~thinfilm_mi.tabulate.diffuse`): :func:`midpoints4` predicts the values
  halfway between nodes, :func:`interleave` / :func:`subdivide` double an axis,
  :func:`linear_error` measures linear interpolation against the rule; and
  :class:`LinearAxis`, their angle axis (nodes uniform in the coordinate of an
  angle axis of :data:`~thinfilm_mi.tabulate.axes.AXES`, split at a critical angle).

The cubic tables' own spline fit and midpoint prediction are
:func:`~thinfilm_mi.tabulate.base.bspline_coefficients` and
:func:`~thinfilm_mi.tabulate.base.bspline_midpoints`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from thinfilm_mi.tabulate.axes import PLAIN, AngleAxis
from thinfilm_mi.tabulate.policy import MAX_BUILD_POINTS, MAX_BUILD_WORK, MAX_TEXELS

__all__ = ["Budget", "LinearAxis", "POINT_WORK", "build_work", "convergence_factor", "interleave",
           "linear_error", "midpoints4", "optical_thickness", "power_of_two_step", "subdivide"]


#: An exact evaluation's cost grows with the films (the recursion visits each):
#: :func:`build_work` weighs a point by its films plus this share of its own
#: (indices, angle, Fresnel terms, numpy bookkeeping).
POINT_WORK = 4


def build_work(side, points: float) -> float:
    """The cost of ``points`` exact evaluations of ``side`` (a
    :class:`~thinfilm_mi.tabulate.base.SideData`) in film units (:data:`POINT_WORK` per
    point on top of one per film)."""
    return float(points) * (len(side.films) + POINT_WORK)


@dataclass
class Budget:
    """What one build may spend: ``points`` exact evaluations in all (probe, nodes
    and checks of every round) and tables of at most ``texels`` texels (or, for
    the linear tables, floats). ``spent`` counts the evaluations so far. With a
    ``point_work`` (a point's cost in film units, :func:`build_work`), the
    evaluations' work must also stay within ``work``."""
    points: int = MAX_BUILD_POINTS
    texels: int = MAX_TEXELS
    spent: int = 0
    point_work: float = 0.0
    work: float = MAX_BUILD_WORK

    @classmethod
    def scaled(cls, scale: float = 1.0, **kw) -> "Budget":
        """A budget of ``scale`` times the default evaluations and work (a table asked
        for with ``tabulate=true`` may take longer than ``"auto"`` would wait)."""
        return cls(points=int(MAX_BUILD_POINTS * scale), work=MAX_BUILD_WORK * scale, **kw)

    def allows(self, points: float = 0, texels: float = 0) -> bool:
        """Whether a round of ``points`` more evaluations giving ``texels`` texels fits."""
        total = self.spent + points
        return total <= self.points and texels <= self.texels and total * self.point_work <= self.work

    def spend(self, points: int) -> None:
        self.spent += int(points)


def optical_thickness(films, wavelengths: np.ndarray, part=np.abs) -> float:
    """``Σ_j max_λ part(n_j(λ)) d_j`` (nm) over ``films``, pairs ``(index function,
    thickness)``, at ``wavelengths``: the stack's whole optical thickness, whose
    fringe has the period ``1 / (2 Σ n_j d_j)`` in wavenumber. ``part``: ``np.abs``
    (default) or ``np.real``."""
    return sum(float(np.max(part(n(wavelengths)))) * d for n, d in films)


def power_of_two_step(step: float, smallest: float, largest: float) -> float:
    """The largest ``smallest · 2^k`` (``k >= 0``) not above ``step``, at most ``largest``:
    first sample steps nest into the finer levels of an adaptive rule."""
    k = math.floor(math.log2(max(step, smallest) / smallest))
    return float(min(smallest * 2.0 ** k, largest))


def convergence_factor(n: int, err: float, goal: float, last: tuple | None, order: float,
                       margin: float, cap: float, highest: float | None = None) -> float:
    """The factor by which to multiply the ``n - 1`` intervals of an axis whose error is
    ``err`` to bring it to ``goal``, assuming the error falls as ``h^p``. ``p`` is the
    order observed since the last round ``last = (n, err)``, clipped to ``[1,
    highest]`` (default ``order``): before the fringes are resolved the error falls
    more slowly than the spline's order, and an error that did not fall gives 1, the
    most nodes; without a last round ``p = order``. ``margin`` > 1 aims a little
    finer; the factor is at most ``cap``."""
    p = order
    if last is not None and last[0] != n and last[1] > 0 and err > 0:
        p = min(max(math.log(last[1] / err) / math.log((n - 1) / (last[0] - 1)), 1.0),
                order if highest is None else highest)
    return min(margin * (err / goal) ** (1.0 / p), cap)


# -- the 4-point rule of the linear tables -----------------------------------------
def midpoints4(values: np.ndarray, axis: int, mirror: bool = False) -> np.ndarray:
    """Values halfway between uniform nodes along ``axis`` by the 4-point Lagrange
    rule ``(-f0 + 9 f1 + 9 f2 - f3) / 16`` (the Dubuc-Deslauriers interpolatory
    subdivision, exact for cubics). At the ends: the function continued as an
    even function about the end node (``mirror``: the plain angle axis, where
    ``R`` is even in ``w`` at normal and at grazing incidence), else 3-point rules."""
    if mirror and values.shape[axis] >= 2:
        f = np.moveaxis(values, axis, 0)
        ext = np.concatenate([f[1:2], f, f[-2:-1]], axis=0)
        mid = (-ext[:-3] + 9 * ext[1:-2] + 9 * ext[2:-1] - ext[3:]) / 16
        return np.moveaxis(mid, 0, axis)
    f = np.moveaxis(values, axis, 0)
    n = f.shape[0]
    if n < 3:
        mid = 0.5 * (f[:-1] + f[1:])
    else:
        mid = np.empty((n - 1,) + f.shape[1:])
        mid[0] = (3 * f[0] + 6 * f[1] - f[2]) / 8
        mid[-1] = (3 * f[-1] + 6 * f[-2] - f[-3]) / 8
        if n > 3:
            mid[1:-1] = (-f[:-3] + 9 * f[1:-2] + 9 * f[2:-1] - f[3:]) / 16
    return np.moveaxis(mid, 0, axis)


def interleave(coarse: np.ndarray, mid: np.ndarray, axis: int) -> np.ndarray:
    """``coarse`` nodes and the ``mid`` values between them, alternating along ``axis``."""
    shape = list(coarse.shape)
    shape[axis] = coarse.shape[axis] + mid.shape[axis]
    out = np.empty(shape, coarse.dtype)
    idx = [slice(None)] * len(shape)
    idx[axis] = slice(0, None, 2)
    out[tuple(idx)] = coarse
    idx[axis] = slice(1, None, 2)
    out[tuple(idx)] = mid
    return out


def subdivide(values: np.ndarray, axis: int, mirror: bool = False) -> np.ndarray:
    """The nodes along ``axis`` doubled by the 4-point rule (:func:`midpoints4`)."""
    return interleave(values, midpoints4(values, axis, mirror), axis)


def linear_error(values: np.ndarray, axis: int, mirror: bool = False) -> np.ndarray:
    """Linear interpolation between the nodes along ``axis`` minus the 4-point rule,
    at every midpoint (``axis`` moved first)."""
    f = np.moveaxis(values, axis, 0)
    return 0.5 * (f[:-1] + f[1:]) - np.moveaxis(midpoints4(values, axis, mirror), axis, 0)


@dataclass
class LinearAxis:
    """The angle axis of the linear tables: ``angle`` (:data:`~thinfilm_mi.tabulate.axes.PLAIN`,
    or :data:`~thinfilm_mi.tabulate.axes.TIR` split at the critical angle of the
    constant real indices ``n0 > n_exit``); nodes uniform in its coordinate,
    ``nodes / 2`` per segment of a split axis."""
    angle: AngleAxis = PLAIN
    n0: float = 1.0
    n_exit: float = 1.0

    @property
    def segments(self) -> int:
        return self.angle.segments

    @property
    def mirror(self) -> bool:
        """Whether :func:`midpoints4` may continue the values evenly beyond the ends."""
        return self.angle.mirror

    def cos(self, nodes: int) -> np.ndarray:
        """cos θ at the ``nodes`` nodes."""
        s = np.arange(nodes, dtype=np.float64)
        return self.angle.nodes_cos(s, np.float64(self.n0), np.float64(self.n_exit), nodes,
                                    ghost=0)

    def midpoints(self, nodes: int) -> np.ndarray:
        """cos θ halfway (in node coordinates) between the nodes of each segment."""
        fine = self.cos(self.refined(nodes))
        m = self.refined(nodes) // self.segments
        return np.concatenate([fine[i * m + 1:(i + 1) * m:2] for i in range(self.segments)])

    def refined(self, nodes: int) -> int:
        """The number of nodes once every segment's intervals are halved."""
        m = nodes // self.segments
        return (2 * m - 1) * self.segments

    def split(self, values: np.ndarray, axis: int = 1) -> list:
        """``values`` cut into its segments along ``axis``."""
        m = values.shape[axis] // self.segments
        return [np.take(values, np.arange(i * m, (i + 1) * m), axis=axis)
                for i in range(self.segments)]

    def interleave(self, values: np.ndarray, mid: np.ndarray, axis: int = 1) -> np.ndarray:
        """Nodes and the values between them interleaved along ``axis``, segment by segment."""
        return np.concatenate([interleave(a, b, axis) for a, b in
                               zip(self.split(values, axis), self.split(mid, axis))], axis=axis)

    def predicted(self, values: np.ndarray, axis: int = 1) -> np.ndarray:
        """:func:`midpoints4` of every segment along ``axis``."""
        return np.concatenate([midpoints4(a, axis, self.mirror) for a in self.split(values, axis)],
                              axis=axis)
