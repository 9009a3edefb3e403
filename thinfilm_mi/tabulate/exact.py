"""Tables of a stack's reflectance and transmittance over (angle, wavelength).

Hirayama et al. (sec. 4) precompute ``k_r`` and ``k_t`` at sampled incidence
angles and wavelengths and interpolate linearly, which they found 6x faster than
the recursion at every hit. Here a table is a ``Texture2f`` (Dr.Jit's texture,
float32) whose channels are the unpolarized ``R`` and, where a BSDF needs it,
``T`` of one lighting side of the stack. It is built in float64 with the optics
core (:func:`thinfilm_mi.optics.unpolarized.unpolarized_rt` on ``drjit.llvm.Float64``) and
looked up in the render kernel, where its cost does not depend on the number of
films.

Interpolation: the texture holds the coefficients of the interpolating cubic
B-spline (``Texture2f.eval_cubic``, 16 texels a lookup): its error falls as
h^4, so a fringe needs 4-5x fewer nodes per axis than with the paper's linear
interpolation (h^2) for the same error, and a table ~20x fewer texels. The
coefficients are solved for (a tridiagonal system per axis) on a grid extended
by :data:`GHOST` nodes beyond each edge, at which the stack is evaluated too
(its analytic continuation), so the spline's end conditions do not reach the
tabulated range. (A render reads most spectral tables of the powers resampled from
this spline for bilinear lookups, which are cheaper in a kernel:
:mod:`thinfilm_mi.tabulate.bilinear`.) Where the exit medium totally reflects, ``R`` has a
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
  mid angles: :data:`~thinfilm_mi.tabulate.axes.BAND`).
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
:data:`~thinfilm_mi.tabulate.policy.MAX_TEXELS` texels even with the whole target on each axis (deep stacks
on metals, with cavity resonances ~0.1 nm wide) is rejected at this point, for
~5·10^4 evaluations. The table is then *verified*: the exact values at the
midpoints between nodes along each axis are compared with the interpolated
ones, and the axis whose error is too large is refined until the sum of both
axes' maximum errors is within the target (default 1e-3 in ``R`` and ``T``).
A stack that would need more than :data:`~thinfilm_mi.tabulate.policy.MAX_TEXELS` texels, or more than
:data:`~thinfilm_mi.tabulate.policy.MAX_BUILD_POINTS` exact evaluations, is not tabulated.

The lookup's scale and offset constants are opaque JIT variables, so a new
table of another shape (a thickness sweep) reuses the compiled render kernel.
"""
from __future__ import annotations

import math

import numpy as np

from thinfilm_mi.tabulate.axes import GHOST, HALF_PI, AngleAxis, axis_for
from thinfilm_mi.tabulate.base import (
    GRAZING_COS,
    MAX_ROUNDS,
    MAX_U,
    MAX_V,
    MIN_U,
    MIN_V,
    REFINE_SHARE,
    SIGMA_MAX,
    SIGMA_MIN,
    BuildReport,
    SideData,
    Table,
    bspline_at,
    bspline_coefficients,
    bspline_midpoints,
    evaluate_side,
    side_indices,
    unique_wavelengths,
    v_nodes_wl,
    v_texel,
    with_ghosts,
)
from thinfilm_mi.tabulate.policy import MAX_BUILD_WORK, MAX_TEXELS
from thinfilm_mi.tabulate.refine import Budget, build_work, convergence_factor

__all__ = ["MAX_PROBE_WORK", "PROBE_HOT_LINES", "PROBE_POINTS", "PROBE_SHARE", "PROBE_U",
           "PROBE_U_FINE", "PROBE_V", "PROBE_V_FINE", "build_exact_table", "ghost_count", "line_levels",
           "table_resolution"]


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
    is then verified and refined by :func:`build_exact_table`.
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


class _Points:
    """Point sets (node coordinates ``s`` along u x ``t`` along v, for a table of
    ``nu x nv`` nodes) gathered into one :func:`evaluate_side` call."""

    def __init__(self, side: SideData, axis: AngleAxis):
        self.side, self.axis = side, axis
        self.sets = []   # (t, s, nu, nv, ghost): the product t x s

    def add(self, s, t, nu: int, nv: int, ghost: int = GHOST) -> None:
        """The points ``t x s``; a u axis whose ghosts are evaluated reaches ``ghost``
        nodes beyond its ends."""
        self.sets.append((np.asarray(t, np.float64), np.asarray(s, np.float64), nu, nv, ghost))

    @property
    def size(self) -> int:
        return sum(t.size * s.size for t, s, *_ in self.sets)

    def evaluate(self):
        """``[(values (len t, len s, C), cos0 (len t, len s))]`` for every set."""
        wl = np.concatenate([v_nodes_wl(t, nv) for t, _, _, nv, _ in self.sets])
        wl, inverse = unique_wavelengths(wl)
        if wl.size == 1:   # Dr.Jit traces a 1-element buffer as a scalar: another kernel
            wl = np.repeat(wl, 2)
        indices = side_indices(self.side, wl)
        n0 = np.asarray(indices[0], np.float64)
        ne = np.asarray(indices[2]).real
        cos, rows, start = [], [], 0
        for t, s, nu, _, ghost in self.sets:
            r = inverse[start:start + t.size]
            start += t.size
            c = self.axis.nodes_cos(s[None, :], n0[r][:, None], ne[r][:, None], nu, ghost)
            cos.append(np.broadcast_to(c, (t.size, s.size)))
            rows.append(np.broadcast_to(r[:, None], (t.size, s.size)))
        vals = evaluate_side(self.side, np.concatenate([c.ravel() for c in cos]),
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
#: Exact evaluations of a probe: its lines with their ghosts on a plain axis, with a
#: margin for lines probed again finer.
PROBE_POINTS = 60_000
#: The probe runs only where :data:`PROBE_POINTS` cost at most this
#: (:func:`~thinfilm_mi.tabulate.refine.build_work`): a deeper stack is not probed, as no
#: exact table resolves its fringes; its band-limited build decides alone.
MAX_PROBE_WORK = MAX_BUILD_WORK // 10


def line_levels(f: np.ndarray, ok: np.ndarray, intervals: int, min_nodes: int,
                 ends=(None, None)) -> list:
    """For fine lines ``f`` (shape ``(values, lines, channels)``, ``intervals``
    intervals each), per line: ``[(k, err, at)]`` for ``k`` = 2, 4, 8, ...: the
    largest error at the allowed (``ok``, shape ``(values, lines)``) midpoints
    of the interpolating cubic spline through every ``k``-th value (at least
    ``min_nodes`` nodes), and where it is (fine node coordinate, 0 ..
    intervals). Each subsampling gets :data:`GHOST` ghost nodes as the table
    would (:func:`with_ghosts`): an end ``None`` reads them from the
    :func:`ghost_count` fine values the line holds beyond it."""
    ext = (f.shape[0] - 1 - intervals) // 2
    g = GHOST
    levels, k = [], 2
    while intervals // k + 1 >= min_nodes:
        n = intervals // k + 1
        mid = slice(ext + k // 2, ext + intervals, k)
        left = f[ext - g * k:ext:k] if ends[0] is None else ends[0]
        right = f[ext + intervals + k:ext + intervals + g * k + 1:k] \
            if ends[1] is None else ends[1]
        c = with_ghosts(f[ext:ext + intervals + 1:k], left, right)
        approx = bspline_midpoints(bspline_coefficients(c, axis=0), 0, g, n)
        dev = np.where(ok[mid], np.abs(approx - f[mid]).max(axis=-1), 0.0)
        i = np.argmax(dev, axis=0)
        levels.append((k, dev[i, np.arange(dev.shape[1])], k // 2 + k * i))
        k *= 2
    return [[(k, float(e[line]), int(at[line])) for k, e, at in levels]
            for line in range(f.shape[1])]


def ghost_count(intervals: int, min_nodes: int) -> int:
    """Fine intervals a probe line extends beyond an end whose ghost nodes are
    evaluated: :data:`GHOST` nodes of its coarsest subsampling."""
    return GHOST * (1 << int(math.log2(intervals // (min_nodes - 1))))


def _nodes_for(levels: list, intervals: int, target: float, order: int) -> tuple:
    """Nodes a line of ``intervals`` fine intervals needs for an error ``target``,
    from its :func:`line_levels`, interpolated in log-log between the finest
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


def _probe_columns(axis: AngleAxis) -> np.ndarray:
    """u node coordinates (on a reference axis of :data:`_REF` nodes, twice that
    for a split axis) of the probe's lines along v (the axis's ``probe_columns``)."""
    # (just inside the verified range: the sliver's edge itself may round out of it)
    w_graz = 1.0 - math.sqrt(math.asin(1.001 * GRAZING_COS) / HALF_PI)
    return axis.probe_columns(_REF, w_graz)


class _Curves:
    """The error curves of an axis's probe lines (:func:`line_levels`): how many
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


def _probe(side: SideData, angle: AngleAxis, error: float, along_v: bool, lines: np.ndarray,
           intervals: int, curves: _Curves, stats: dict, fine: bool = False) -> tuple:
    """Fine 1-D lines of exact values along v (``along_v``: at the u node
    coordinates ``lines`` of a reference axis of :data:`_REF` nodes, twice that
    if split) or along the angle axis ``angle`` (at the v coordinates ``lines`` of
    such an axis), each
    subsampled by 2, 4, 8, ...: a subsampling is a 1-D table whose error at its
    midpoints is known exactly (:func:`line_levels`). The lines' error curves
    are added to ``curves``, the points evaluated to ``stats["probe_points"]``.

    Returns ``hot`` (``[(nodes, coordinate)]``: where on the other axis's
    reference each line errs most, for the lines that fail :data:`PROBE_SHARE`
    of ``error``, with the nodes they need for it) and the line that needs most
    ``(nodes, line, resolved)``.
    """
    min_nodes = 65 if fine else 17
    ext = ghost_count(intervals, min_nodes)
    pts = _Points(side, angle)
    if along_v:
        pts.add(lines, np.arange(-ext, intervals + ext + 1.0), angle.segments * _REF,
                intervals + 1)
    elif angle.ghosts_evaluated:
        pts.add(np.arange(-ext, intervals + ext + 1.0), lines, intervals + 1, _REF, ghost=ext)
    else:
        n = angle.segments * (intervals + 1)
        pts.add(np.arange(float(n)), lines, n, _REF)
    ((vals, cos),) = pts.evaluate()
    stats["probe_points"] += pts.size
    if along_v:
        parts = [(vals, cos, (None, None))]
    else:   # (lines, values, C) -> (values, lines, C): per segment, its ghosts' ends
        vals, cos = np.swapaxes(vals, 0, 1), cos.T
        m = vals.shape[0] // angle.segments   # a split axis: intervals + 1 nodes each
        parts = [(vals[i * m:(i + 1) * m], cos[i * m:(i + 1) * m], ends)
                 for i, ends in enumerate(angle.ends)]
    hot, worst = [], (-1.0, None, True)
    for segment, (f, c, ends) in enumerate(parts):
        for i, levels in enumerate(line_levels(f, c >= GRAZING_COS, intervals, min_nodes,
                                                ends)):
            curves.lines.append((levels, intervals, fine))
            n, resolved, at = _nodes_for(levels, intervals, PROBE_SHARE * error, curves.order)
            if n > worst[0]:
                worst = (n, lines[i], resolved)
            if at is not None:
                hot.append((n, segment * _REF + at / intervals * (_REF - 1)))
    return hot, worst


def _estimate(side: SideData, angle: AngleAxis, error: float, max_texels: int, stats: dict):
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
    cu, cv = _Curves(4, angle.segments), _Curves(4, 1)

    def hot(found):
        return [c for _, c in sorted(found, reverse=True)[:PROBE_HOT_LINES]]

    u_rows = np.linspace(0.0, _REF - 1.0, 5)
    hot_u, worst_u = _probe(side, angle, error, False, u_rows, PROBE_U, cu, stats)
    cols = np.unique(np.concatenate([_probe_columns(angle), hot(hot_u)]))
    hot_v, worst_v = _probe(side, angle, error, True, cols, PROBE_V, cv, stats)
    if hot_v:
        _, w = _probe(side, angle, error, False, np.unique(hot(hot_v)), PROBE_U, cu, stats)
        worst_u = max(worst_u, w, key=lambda x: x[0])
    for along_v, (_, line, resolved), curves, fine in ((True, worst_v, cv, PROBE_V_FINE),
                                                       (False, worst_u, cu, PROBE_U_FINE)):
        if not resolved:
            _probe(side, angle, error, along_v, np.array([line]), fine, curves, stats, fine=True)
    if cu.need(error) > MAX_U or cv.need(error) > MAX_V \
            or cu.need(error) * cv.need(error) > max_texels:
        return None, None
    budget = 2.0 * PROBE_SHARE * error
    splits = [(cu.need(a * budget) * cv.need((1.0 - a) * budget), a)
              for a in np.linspace(0.1, 0.9, 17)]
    a = min(splits)[1]
    return cu.need(a * budget), cv.need((1.0 - a) * budget)


def build_exact_table(side: SideData, error: float, wavelengths: np.ndarray,
                max_texels: int = MAX_TEXELS, report: BuildReport | None = None,
                budget_scale: float = 1.0) -> Table | None:
    """Build and verify a table of the exact values of one side, or ``None`` if
    the target cannot be met within ``max_texels`` texels,
    :data:`~thinfilm_mi.tabulate.policy.MAX_BUILD_POINTS` evaluations and
    :data:`~thinfilm_mi.tabulate.policy.MAX_BUILD_WORK` (or the exit
    medium's critical angle depends on λ; or the probe alone would cost more than
    :data:`MAX_PROBE_WORK`: then nothing is evaluated). (Band-limited tables, for stacks this rejects:
    :func:`thinfilm_mi.tabulate.band.build_table`.)

    The table holds the coefficients of the interpolating cubic B-spline, on a
    plain u axis or on each segment of a split one (total internal
    reflection), whose ghost nodes come from its axis's ``ends``. The first
    resolution is the larger of :func:`table_resolution`'s (from the optical
    thickness) and the probe's (:func:`_estimate`, which also rejects hopeless
    stacks early). Verification: the exact values midway between neighbouring
    nodes along u (on every other v row) and along v (on every other u column)
    are compared with the interpolated ones; the sum of the two maxima (for
    incidence outside the grazing sliver, :data:`GRAZING_COS`) must be within
    ``error``. The cell across the critical angle of a split axis has zero
    width in angle and is skipped. Otherwise the axis that exceeds its share
    is refined, at the convergence order observed between rounds.

    What the build did is written into ``report`` (a :class:`BuildReport`).
    ``budget_scale`` multiplies the evaluations and work allowed (the probe's too).
    """
    axis = axis_for(side.n0(wavelengths), side.n_exit(wavelengths))
    stats = report if report is not None else BuildReport()
    stats.update({"kind": axis.name if axis is not None else None, "probe_points": 0,
                  "rounds": 0, "points": 0, "result": "critical angle varies",
                  "resolution": 0.0})
    if axis is None:
        return None
    g = GHOST
    split = axis.split
    first = _first_resolution(side, axis, error, wavelengths, max_texels, budget_scale, stats)
    if first is None:
        return None
    nu, nv, budget = first
    stats["result"] = "over budget"
    history = {}
    for _ in range(MAX_ROUNDS + 1):
        if split:
            nu += nu % 2
        # the nodes (a split axis's ghosts are not evaluated), and the checks
        points = (nu + (0 if split else 2 * g)) * (nv + 2 * g) + nu * nv \
            + len(side.kinks) * (nu // 2)
        if nu > MAX_U or nv > MAX_V or not budget.allows(points, nu * nv):
            return None
        budget.spend(points)
        stats["points"] = budget.spent
        stats["rounds"] += 1
        nodes, coeffs, err_u, err_v = _fit_and_check(side, axis, nu, nv)
        stats.setdefault("errors", []).append((nu, nv, err_u, err_v))
        if err_u + err_v <= error:
            stats["result"] = "table"
            return Table(coeffs, axis, err_u + err_v, nodes.shape[-1])
        factors = _refinement(nu, nv, err_u, err_v, error, history)
        if not budget.allows(texels=nu * nv * factors["u"] * factors["v"] / 4):
            return None   # hopeless within the budget: do not spend the time
        nu = int(math.ceil((nu - 1) * factors["u"])) + 1
        nv = int(math.ceil((nv - 1) * factors["v"])) + 1
    return None


def _first_resolution(side: SideData, axis, error: float, wavelengths: np.ndarray,
                      max_texels: int, budget_scale: float, stats: BuildReport):
    """``(nu, nv, budget)`` of :func:`build_exact_table`'s first round: the larger of
    :func:`table_resolution`'s and the probe's resolutions, and the budget with the
    probe's evaluations spent; ``None`` where the probe would cost too much or rejects
    the stack (``stats["result"]`` says which)."""
    side.set_absorbing(wavelengths)
    if build_work(side, PROBE_POINTS) > MAX_PROBE_WORK * budget_scale:
        stats["result"] = "probe over budget"
        return None
    nu, nv = table_resolution(side, error, wavelengths)
    budget = Budget.scaled(budget_scale, texels=max_texels, point_work=build_work(side, 1))
    pu, pv = _estimate(side, axis, error, max_texels, stats)
    budget.spend(stats["probe_points"])
    stats["points"] = budget.spent
    if pu is None:
        stats["result"] = "rejected by the probe"
        return None
    nu = min(max(nu, int(math.ceil(1.05 * pu))), MAX_U)
    nv = min(max(nv, int(math.ceil(1.05 * pv))), MAX_V)
    return nu, nv, budget


def _fit_and_check(side: SideData, axis, nu: int, nv: int):
    """One round of :func:`build_exact_table` at ``nu x nv`` nodes: the exact values at
    the nodes and midway between them, the B-spline coefficients through the nodes, and
    the largest deviations of the spline from the midway values along u and along v
    (incidence outside the grazing sliver): ``(nodes, coeffs, err_u, err_v)``."""
    g = GHOST
    split = axis.split
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
    pts = _Points(side, axis)
    pts.add(su, tv, nu, nv)
    pts.add(mu, tv[rows], nu, nv)
    pts.add(cols.astype(np.float64), np.concatenate([np.arange(nv - 1) + 0.5, kinks]),
            nu, nv)
    (nodes, _), (mid_u, cos_u), (mid_v, cos_v) = pts.evaluate()
    # Spline coefficients along u, per segment with its ghosts, then along v.
    if split:
        segs = [np.moveaxis(with_ghosts(np.moveaxis(part, 1, 0), *ends), 0, 1)
                for part, ends in zip((nodes[:, :m], nodes[:, m:]), axis.ends)]
        cu = [bspline_coefficients(seg, axis=1) for seg in segs]
        approx_u = np.concatenate([bspline_midpoints(c[rows], 1, g, m) for c in cu],
                                  axis=1)
        cu = np.concatenate(cu, axis=1)
        texel = cols + g + np.where(cols >= m, 2 * g, 0)
    else:
        cu = bspline_coefficients(nodes, axis=1)
        approx_u = bspline_midpoints(cu[rows], 1, g, nu)
        texel = cols + g
    coeffs = bspline_coefficients(cu, axis=0)
    # The spline along v through node column j has the coefficients
    # B_u coeffs (B_u: the u spline's (1, 4, 1) / 6 at its nodes).
    cv = (coeffs[:, texel - 1] + 4.0 * coeffs[:, texel] + coeffs[:, texel + 1]) / 6.0
    approx_v = np.concatenate([bspline_midpoints(cv, 0, g, nv), bspline_at(cv, kinks, g)])
    dev = np.abs(mid_u - approx_u).max(axis=-1)
    err_u = float(np.max(np.where(cos_u >= GRAZING_COS, dev, 0.0)))
    dev = np.abs(mid_v - approx_v).max(axis=-1)
    err_v = float(np.max(np.where(cos_v >= GRAZING_COS, dev, 0.0)))
    return nodes, coeffs, err_u, err_v


def _refinement(nu: int, nv: int, err_u: float, err_v: float, error: float,
                history: dict) -> dict:
    """``{"u": factor, "v": factor}`` by which :func:`build_exact_table` multiplies its
    resolution after a round that missed ``error``, at the convergence order observed
    between rounds (``history``, updated)."""
    order = 4   # a cubic spline's error falls as h^4
    # Refine: aim at REFINE_SHARE of the target; an axis already within
    # half of that keeps its nodes and leaves the rest to the other.
    aim = REFINE_SHARE * error
    if err_u <= 0.5 * aim:
        goal = {"u": err_u, "v": aim - err_u}
    elif err_v <= 0.5 * aim:
        goal = {"u": aim - err_v, "v": err_v}
    else:
        goal = {"u": 0.5 * aim, "v": 0.5 * aim}
    factors = {}
    for along, n, err in (("u", nu, err_u), ("v", nv, err_v)):
        if err <= goal[along]:
            factors[along] = 1.0
            continue
        factors[along] = convergence_factor(n, err, goal[along], history.get(along), order,
                                           margin=1.05, cap=3.0)
        history[along] = (n, err)
    return factors
