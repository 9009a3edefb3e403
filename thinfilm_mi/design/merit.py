"""The merit of a design: weighted residuals of every target and their Jacobian.

Each target point gives a residual ``e = (achieved - wanted) / tolerance``
(``<=`` targets count only ``e > 0``, ``>=`` only ``e < 0``); a colour target
gives, per angle, three residuals whose squares sum to ``(dE00 / tolerance)^2``
(two for ``xy``: the components of the distance). The merit is the root mean
square over the target points::

    merit = sqrt(sum(e^2) / points)

so a design whose every point is at its tolerance has merit 1. The Jacobian of
``e`` with respect to the thicknesses (nm) and the free indices is exact
(:mod:`.matrices`, :mod:`.colourmath`); the needle function is the derivative of
``sum(e^2)`` with respect to the thickness of a film inserted at each depth.

All (wavelength, angle, side) points of all targets are gathered into one
array per (side, angle), evaluated once per polarisation component that some
target needs. Each target's residuals are its quantity's
(:meth:`thinfilm_mi.design.target_quantities.TargetQuantity.residuals`); the colour
targets of one colour space are evaluated together.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from thinfilm_mi.design.colourmath import colour_weights
from thinfilm_mi.design.matrices import Response, needle_response, stack_response
from thinfilm_mi.design.options import Side, as_side
from thinfilm_mi.design.target_quantities import Colour
from thinfilm_mi.design.targets import Problem, Target
from thinfilm_mi.optics.polarization import Component, Polarization, as_polarization

__all__ = ["Design", "Merit", "TargetValues"]


@dataclass
class Design:
    """A stack being designed: the material (an index into ``Problem.materials``)
    and the thickness (nm) of each film from the ambient side, and the values of
    the free real indices (in the order of :attr:`Merit.free`)."""

    films: list[int]
    d: np.ndarray
    n: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def copy(self) -> "Design":
        return Design(list(self.films), np.array(self.d, dtype=np.float64), np.array(self.n, dtype=np.float64))


@dataclass
class TargetValues:
    """What a design achieves for one target at each of its angles: ``achieved``
    (angles, wavelengths) for R/T/A, (angles,) for Y, (angles, 3 or 2) Lab / xy for
    colour; ``error`` the deviation in the target's unit (``|achieved - wanted|``
    beyond the kind's side, ΔE2000 or xy distance), same leading shape;
    ``residual_sq`` the target's share of ``sum(e^2)``."""

    target: Target
    achieved: np.ndarray
    error: np.ndarray
    residual_sq: float | np.ndarray

    @property
    def within(self) -> np.ndarray:
        """Boolean per point: within tolerance."""
        return self.error <= self.target.tolerance * (1 + 1e-9)


class _Group:
    """The points of one (side, angle): wavelengths, media and film indices."""

    def __init__(self, problem: Problem, side: Side, angle: float, wl: np.ndarray):
        self.side, self.angle, self.wl = side, angle, wl
        self.n_in, self.n_out = side.media(problem.ambient.index(wl), problem.substrate.index(wl))
        self.beta2 = (self.n_in * np.sin(np.radians(angle))) ** 2
        self.index = [None if m.free else m.material.index(wl).astype(np.complex128)
                      for m in problem.materials]
        self.pols: set[Component] = set()


class Merit:
    """Residuals, Jacobian and needle function of a :class:`Problem`."""

    def __init__(self, problem: Problem, colour_step: int = 1):
        self.problem = problem
        #: step (in 1 nm samples) of the colour integrals: 1 is exact, > 1 approximates (synthesis)
        self.colour_step = colour_step
        self.free = [i for i, m in enumerate(problem.materials) if m.free]
        wanted: dict[tuple[Side, float], list[np.ndarray]] = {}
        for t in problem.targets:
            for a in t.angles:
                wanted.setdefault((t.side, float(a)), []).append(self._grid(t))
        self.groups = {key: _Group(problem, key[0], key[1], np.unique(np.concatenate(v)))
                       for key, v in wanted.items()}
        self.terms = []         # per target: [(group key, indices into the group's wl)] per angle
        self.points = 0
        for t in problem.targets:
            rows = []
            for a in t.angles:
                g = self.groups[(t.side, float(a))]
                g.pols.update(t.polarization.components)
                rows.append(((t.side, float(a)), np.searchsorted(g.wl, self._grid(t))))
            self.terms.append(rows)
            self.points += t.angles.size * (t.wavelengths.size if t.wavelengths is not None else 1)
        all_wl = np.concatenate([g.wl for g in self.groups.values()])
        self.wl_min = float(all_wl.min())
        n_max = max(float(np.max(m.material.index(np.array([self.wl_min])).real)) if not m.free else m.free[1]
                    for m in problem.materials)
        #: spacing (nm) of the depths at which the needle function is evaluated:
        #: 40 samples per wave of the shortest wavelength in the densest material
        self.needle_step = self.wl_min / (40.0 * n_max)

    def _grid(self, t: Target) -> np.ndarray:
        return t.wavelengths if t.wavelengths is not None else \
            colour_weights(t.illuminant, t.observer, self.colour_step)[0]

    # -- optics --------------------------------------------------------------
    def initial_n(self, given: dict | None = None) -> np.ndarray:
        """The free indices' values: from ``given`` ({material index: n}), else as listed."""
        given = given or {}
        return np.array([given.get(i, self.problem.materials[i].n0.real) for i in self.free])

    def bounds_n(self) -> list[tuple[float, float]]:
        return [self.problem.materials[i].free for i in self.free]

    def _films(self, g: _Group, design: Design) -> list[np.ndarray]:
        out = []
        for m in design.films:
            if g.index[m] is None:
                value = design.n[self.free.index(m)] + 1j * self.problem.materials[m].n0.imag
                out.append(np.full(g.wl.shape, value, dtype=np.complex128))
            else:
                out.append(g.index[m])
        return out

    def _responses(self, design: Design, depths=None, jac: bool = True) -> dict:
        """{group key: {pol: Response}}; derivatives w.r.t. thicknesses and free
        indices, or (``depths`` given) w.r.t. needles, in the front order. With
        ``design.d`` of shape (L, B) (and no derivatives): B stacks, R and T (P, B)."""
        L = len(design.films)
        d = np.asarray(design.d, dtype=np.float64)
        pts = (lambda a: a[:, None]) if d.ndim == 2 else (lambda a: a)
        out = {}
        for key, g in self.groups.items():
            films = self._films(g, design)
            order = g.side.order(L)
            f_films = [pts(films[j]) for j in order]
            f_d = list(d[order])
            res = {}
            for pol in sorted(g.pols, key=lambda c: c.name):
                if depths is None:
                    groups = [[k for k, j in enumerate(order) if design.films[j] == m] for m in self.free]
                    r = stack_response(pts(g.n_in), pts(g.n_out), f_films, f_d, pts(g.wl), pts(g.beta2), pol,
                                       groups, derivatives=jac)
                    if L and jac:
                        cols = np.r_[np.argsort(order), np.arange(L, r.dR.shape[-1])]
                        r = Response(r.R, r.T, *g.side.front_order((r.dR, r.dT), cols, -1))
                else:
                    needle_idx = [m for m, dm in enumerate(self.problem.materials) if dm.needle]
                    needles = [self._films(g, Design([m], np.zeros(1), design.n))[0] for m in needle_idx]
                    z = [g.side.depths(depths[j], d[j]) for j in order] if L else [np.zeros(1)]
                    r = needle_response(g.n_in, g.n_out, f_films, f_d, g.wl, g.beta2, pol, z, needles)
                    if L:
                        sizes = [len(depths[j]) for j in range(L)]
                        starts = np.r_[0, np.cumsum([sizes[j] for j in order])[:-1]]
                        perm = np.concatenate([starts[order.index(j)] + np.arange(sizes[j]) for j in range(L)])
                        r = Response(r.R, r.T, *g.side.front_order((r.dR, r.dT), perm, 1))
                    P = g.wl.size
                    r = Response(r.R, r.T, r.dR.reshape(P, -1), r.dT.reshape(P, -1))
                res[pol] = r
            out[key] = res
        return out

    def spectrum(self, design: Design, wavelengths, angle: float, side: Side | str = "front",
                 polarization: Polarization | str = "unpolarized") -> tuple[np.ndarray, np.ndarray]:
        """``(R, T)`` of ``design`` at ``wavelengths`` (nm) and ``angle`` (degrees),
        lit from ``side`` in ``polarization`` (objects or their names)."""
        side = as_side(side)
        g = _Group(self.problem, side, float(angle), np.asarray(wavelengths, dtype=np.float64))
        films = self._films(g, design)
        order = side.order(len(films))
        pols = as_polarization(polarization).components
        res = [stack_response(g.n_in, g.n_out, [films[j] for j in order], [design.d[j] for j in order],
                              g.wl, g.beta2, p, derivatives=False) for p in pols]
        return sum(r.R for r in res) / len(res), sum(r.T for r in res) / len(res)

    # -- residuals -----------------------------------------------------------
    def evaluate(self, design: Design, jac: bool = True, depths=None, report: bool = False):
        """``(e, J)`` — residuals (N,) and their Jacobian (N, K) (``None`` without
        ``jac``); with ``report`` also the list of :class:`TargetValues`. For a
        batch (``design.d`` of shape (L, B)) ``e`` is (N, B) and ``J`` (N, B, K)."""
        resp = self._responses(design, depths, jac)
        parts: list = [None] * len(self.terms)      # per target: (e, de, achieved, error)
        pending: dict = {}                           # colour space: its targets, evaluated together
        for i, (t, rows) in enumerate(zip(self.problem.targets, self.terms)):
            spectral = t.quantity.spectral(t)
            pairs = [spectral.power(resp[key], t.polarization.components, idx, jac) for key, idx in rows]
            q = np.stack([p[0] for p in pairs])                      # (angles, n[, B])
            dq = np.stack([p[1] for p in pairs]) if jac else None    # (angles, n[, B], K)
            parts[i] = t.quantity.residuals(t, q, dq, self.colour_step, pending)
        index = {id(t): i for i, t in enumerate(self.problem.targets)}
        for space, items in pending.items():       # every colour target of a space in one pass
            for it, part in zip(items, Colour.evaluate(space, items)):
                parts[index[id(it[0])]] = part
        e_all, j_all, values = [], [], []
        for t, (e, de, achieved, error) in zip(self.problem.targets, parts):
            e = e.reshape((-1,) + e.shape[2:])
            e_all.append(e)
            if jac:
                j_all.append(de.reshape((-1,) + de.shape[2:]))
            if report:
                values.append(TargetValues(t, achieved, error, np.sum(e ** 2, axis=0)))
        e = np.concatenate(e_all)
        J = np.concatenate(j_all, axis=0) if jac else None
        return (e, J, values) if report else (e, J)

    def merit(self, design: Design) -> float:
        """``sqrt(sum(e^2) / points)``."""
        e, _ = self.evaluate(design, jac=False)
        return float(np.sqrt(np.sum(e * e) / self.points))

    def merits(self, films: list[int], d: np.ndarray, n: np.ndarray | None = None) -> np.ndarray:
        """The merits of B stacks of the same ``films`` at once, ``d`` (L, B) nm."""
        design = Design(list(films), np.asarray(d, dtype=np.float64), self.initial_n() if n is None else n)
        e, _ = self.evaluate(design, jac=False)
        return np.sqrt(np.sum(e * e, axis=0) / self.points)

    def merit_and_gradient(self, design: Design) -> tuple[float, np.ndarray]:
        """The merit and its gradient with respect to the thicknesses (nm) and the
        free indices (in that order)."""
        e, J = self.evaluate(design)
        s = float(np.sum(e * e))
        m = np.sqrt(s / self.points)
        grad = (J.T @ e) / (self.points * m) if m > 0 else np.zeros(J.shape[1])
        return float(m), grad

    def needle_depths(self, design: Design) -> list[np.ndarray]:
        """Depths (nm from each film's ambient side) at which needles are tried."""
        return [np.linspace(0.0, dj, max(2, int(np.ceil(dj / self.needle_step)) + 1)) for dj in design.d]

    def needle_function(self, design: Design, depths=None) -> tuple[list[np.ndarray], np.ndarray]:
        """``(depths, P)``: ``P`` (Z, M) the derivative of ``sum(e^2)`` with respect
        to the thickness of a needle of each needle material at each depth (films in
        order, then their depths; one row for a stack with no films). Negative where
        a needle would lower the merit."""
        if depths is None:
            depths = self.needle_depths(design)
        e, J = self.evaluate(design, depths=depths)
        m = sum(1 for dm in self.problem.materials if dm.needle)
        return depths, (2.0 * (e @ J)).reshape(-1, m)
