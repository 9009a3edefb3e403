"""Band-limited tables: a stack's ``R`` and ``T`` convolved along the spectrum, for
stacks whose exact values no table resolves (no plugin classes here).

Ten or more films on a metal form cavities with resonances ~0.1 nm wide and
narrower: a cubic table of the exact ``R`` would need millions of texels. But a
spectral render integrates ``R(λ)`` against smooth emitter x colour-matching
curves, and no real light is monochromatic, so a resonance narrower than the
light's bandwidth changes an image only by its area. A band-limited table holds

    R_σ(ν) = ∫ R(ν') G_σ(ν - ν') dν'        (and T_σ likewise)

with ``ν = 1/λ`` the wavenumber and ``G_σ`` a Gaussian of standard deviation
``σ_ν = spectral_resolution / 560²`` (nm⁻¹): ``spectral_resolution`` nm at
560 nm, 0.41x that at 360 nm and 2.2x at 830 nm. A Gaussian in wavenumber is
light of finite coherence: it multiplies every interference term of optical
path difference ``p`` by ``exp(-2 π² σ_ν² p²)``, so paths longer than the
coherence length ``1 / (2 π σ_ν)`` (~50 µm at the default 1 nm) stop
interfering, shorter ones are untouched. It is also uniform on the tables'
wavelength axis (uniform in ``ν``): ``R_σ`` needs the same node spacing
everywhere, half the nodes a Gaussian of constant width in λ would need.

**How ``R_σ`` is computed.** Per angle row (a node coordinate of the table's
angle axis), the exact ``R`` (float64) is integrated by adaptive Simpson along
``ν`` into bins of width ``w`` (:data:`KNOT_SHARE` σ_ν) with cubic B-spline
weights, ``I_b = ∫ R(ν) B((ν - ν_b) / w) dν``:

* the first level samples the amplitudes ``N``, ``D`` of the recursion
  (``R = |N|²/|D|²``, :func:`band_rows.amplitudes`) 32 times per interference fringe
  of the whole stack (:func:`first_step`); ``N`` and ``D`` are smooth where
  ``R`` has resonances, so every resonance shows as a zero of ``D`` near the
  real axis, found on the cubic through four samples (:func:`near_zeros`),
  however narrow it is;
* a panel is halved (two new exact values) until Simpson's error estimate is
  within :data:`TOLERANCE` times its width *and* it is no wider than
  :data:`GRADING` times its distance to the nearest zero of ``D``, down to
  :data:`MIN_PANEL` (~1e-4 nm);
* each accepted panel stands for the quadratic through its three values,
  integrated exactly against the B-splines (3-point Gauss-Legendre on each bin
  interval it covers);

then ``R_σ = Σ_b G_σ'(ν - ν_b) I_b`` with ``σ'² = σ_ν² - w²/3`` (the
B-spline's variance; the Gaussian of ``σ'`` times the B-spline is the Gaussian
of ``σ_ν`` to its fourth cumulant), one FFT per row.
``tests/tabulate/test_band_rows.py`` checks ``R_σ`` against a brute-force convolution
of exact values on a 0.0005 nm grid (measured within 1e-5).

**The table** is the cubic B-spline of :mod:`thinfilm_mi.tabulate.exact` (same lookup;
the angle axis warped to put more nodes at mid angles,
:data:`~thinfilm_mi.tabulate.axes.BAND`, where ``R_σ``'s features move fastest with the angle),
its error ``table_error`` still the interpolation error, now against ``R_σ``,
verified outside the same grazing sliver; the angle rows are refined until the
spline through them predicts the midpoint rows within the target. Lit from the
ambient, its v axis is sheared (:mod:`thinfilm_mi.tabulate.shear`): ``ν' = ν
P(sin²θ)`` follows the films' fringes as the angle grows, so 65 rows do where the
plain axis needed 385 (the 30-film benchmark stack: one round, 0.3-0.4 s instead
of 0.8-1.4 s, a 4x smaller table); its nodes' values are the Gaussian summed over the
bins at ``ν'_t / P`` (:meth:`band_rows.Rows.sample`), the bins spanning every
wavenumber a row's nodes reach. Lit from inside a denser medium (a split axis) the
v nodes sit on every other bin (their midpoints on the others), so a row gives
the whole spectrum. The build also checks the colour: the colour of ``R_σ`` against
that of ``R`` under D65, illuminant A and the line spectrum F11, per row and
channel, must be within :data:`COLOUR_TOLERANCE` (CIEDE2000); otherwise no
table is built (``tabulate="auto"`` then evaluates exactly).
"""
from __future__ import annotations

import math

import numpy as np

from thinfilm_mi.tabulate import base as tabulate_base
from thinfilm_mi.tabulate import exact as _tables
from thinfilm_mi.tabulate.axes import BAND, GHOST, AngleAxis, axis_for, band_cos
from thinfilm_mi.tabulate.band_rows import ILLUMINANTS, V_SPACING, Rows, sigma_nu
from thinfilm_mi.tabulate.base import (
    GRAZING_COS,
    MAX_U,
    MAX_V,
    SIGMA_MAX,
    SIGMA_MIN,
    BuildReport,
    SideData,
    Table,
    bspline_coefficients,
    bspline_midpoints,
    build_work,
    side_indices,
    with_ghosts,
)
from thinfilm_mi.tabulate.refine import Budget, convergence_factor
from thinfilm_mi.tabulate.shear import REFERENCE_WAVELENGTH, Shear

__all__ = ["COLOUR_TOLERANCE", "EXPECTED_TOTAL", "FIRST_NU", "FIRST_ORDER", "KNOT_SHARE",
           "MAX_ROUNDS", "SAMPLE_ROWS", "build_band_table", "build_table"]

#: Bins are half a v-node spacing wide, 0.3 σ_ν: the bins' B-spline departs
#: from a Gaussian by its fourth cumulant, ~1e-6 of ``R_σ``.
KNOT_SHARE = 0.5 * V_SPACING
#: Largest CIEDE2000 between the colours of ``R`` and ``R_σ`` (and ``T``,
#: ``T_σ``) over the angle rows under D65, A and F11 a table may show. F11's
#: lines (as tabulated by the CIE, every 5 nm) are what a band-limited table
#: shifts most: 0.27 for the 30-film benchmark stack at 1 nm, D65 0.009.
COLOUR_TOLERANCE = 0.5
#: Angle nodes of the first round (a plain axis; a split one: per segment, half).
FIRST_NU = 65
#: Convergence order assumed for the first refinement of the angle axis (then
#: the order observed between rounds): ``R_σ``'s resonances are still sharp at
#: the first round's spacing, so the cubic's h^4 is not reached yet (measured
#: ~3.4 from 65 to 254 nodes for the 10-film benchmark stack).
FIRST_ORDER = 3.5
#: Rounds after the first (each sized from the last's error).
MAX_ROUNDS = 4
#: A build's expected exact evaluations over a lower bound of its first round's
#: (its rows' first-level samples): the adaptive panels and the later rounds.
#: Measured on the sheared axis (one round up to 60 films): 1.5 for the 10-film,
#: 2.3 for the 30-film, 3.0 for the 60-film and 7.9 for the 100-film benchmark
#: stack (two rounds). A build whose expected total exceeds
#: :data:`~thinfilm_mi.tabulate.base.MAX_BUILD_WORK` is not started (milliseconds
#: instead of seconds for 70-1000 films); one that passes is checked again on
#: :data:`SAMPLE_ROWS` rows before the rest of its first round.
EXPECTED_TOTAL = 4.0
#: Rows of the first round computed first, to measure the cost per row.
SAMPLE_ROWS = 8


def build_table(side: SideData, error: float, wavelengths: np.ndarray,
                max_texels: int = tabulate_base.MAX_TEXELS, resolution: float = 0.0,
                report: BuildReport | None = None, budget_scale: float = 1.0) -> Table | None:
    """The table of one side: of the exact values (:func:`tables.build_table`) if
    one resolves them within ``error`` (1-3 films: unchanged by band-limiting),
    else, if ``resolution`` > 0, of ``R_σ`` (:func:`build_band_table`); ``None``
    if neither can be built. What the build did is written into ``report`` (a
    :class:`~thinfilm_mi.tabulate.base.BuildReport`; the exact attempt's report
    under ``"exact_attempt"`` when a band-limited table was tried after it).
    ``budget_scale`` multiplies the evaluations and work both builds may spend
    (:meth:`~thinfilm_mi.tabulate.refine.Budget.scaled`)."""
    report = report if report is not None else BuildReport()
    exact = BuildReport()
    table = _tables.build_table(side, error, wavelengths, max_texels, report=exact,
                                budget_scale=budget_scale)
    if table is not None or resolution <= 0:
        report.update(exact)
        return table
    table = build_band_table(side, error, wavelengths, max_texels, resolution, report=report,
                             budget_scale=budget_scale)
    report["exact_attempt"] = exact
    return table


def build_band_table(side: SideData, error: float, wavelengths: np.ndarray,
                     max_texels: int, resolution: float, report: BuildReport | None = None,
                     budget_scale: float = 1.0) -> Table | None:
    """A verified table of ``R_σ`` (see the module), or ``None`` if the colour
    check fails or the target needs more than ``max_texels`` texels,
    :data:`MAX_BUILD_POINTS` exact evaluations or :data:`MAX_BUILD_WORK` (the
    expected total, :data:`EXPECTED_TOTAL`, checked before any evaluation; then
    each round's before it runs), both times ``budget_scale``. Writes its account
    into ``report``.

    Rounds: the rows of the angle nodes (a plain axis's ghosts included) and of
    their midpoints are computed (each row: every bin, so the v nodes and their
    midpoints come with it); the spline through the node rows is compared with
    the midpoint rows (``err_u``) and, along v, with the bins between the nodes
    (``err_v``), outside the grazing sliver. If ``err_u + err_v`` exceeds
    ``error``, the angle nodes are multiplied by the factor the error's
    convergence order predicts (the v spacing is reduced instead, all rows
    computed again, where ``err_v`` alone exceeds half the target)."""
    axis = axis_for(side.n0(wavelengths), side.n_exit(wavelengths))
    stats = report if report is not None else BuildReport()
    stats.update({"kind": axis.name if axis is not None else None, "rounds": 0, "points": 0,
                  "result": "critical angle varies", "resolution": resolution,
                  "colour_error": None, "errors": []})
    if axis is None:
        return None
    side.set_absorbing(wavelengths)
    axis = axis.band_limited     # a plain axis: more nodes at mid angles
    split = axis.split
    # a quantity whose channels vary faster along v (tabulate.mueller) starts finer
    spacing = side.quantity.v_spacing
    # lit from the ambient (rows that do not depend on the indices): the v axis
    # follows the films' fringes (tabulate.shear)
    shear = None
    if not axis.needs_n_exit:
        shear = Shear.of([side.films[i] for i in side.fringe_films],
                         complex(np.asarray(side.n0(np.array([REFERENCE_WAVELENGTH])))[0]))
    rows = _rows(side, axis, resolution, spacing, shear)
    nu = 2 * FIRST_NU if split else FIRST_NU
    budget = Budget.scaled(budget_scale, texels=max_texels, point_work=build_work(side, 1))
    first = EXPECTED_TOTAL * sum(len(x) for x in axis.rows(nu)) * ((rows.nb - 1) / rows.step + 1)
    stats["expected_work"] = build_work(side, first)
    if not budget.allows(first):
        stats["result"] = "over budget (expected)"
        return None
    last, per_row = None, 0.0
    for _ in range(MAX_ROUNDS + 1):
        nv = rows.nv if shear is None else _sheared_nv(shear, rows.sigma, spacing)
        coords = np.concatenate(axis.rows(nu))
        if not per_row:
            # the cost per row measured on SAMPLE_ROWS of the first round's rows (then
            # part of it) before the rest is spent: the expectation is a bound from the
            # first level alone, and the adaptive panels grow with the resonances
            rows.compute(coords[np.linspace(0, coords.size - 1, SAMPLE_ROWS).round().astype(int)])
            per_row = rows.points / rows.computed
        # the round's new rows at the cost per row so far
        todo = rows.missing(coords)
        if nu > MAX_U or nv > MAX_V or not budget.allows(rows.points + todo * per_row, nu * nv):
            stats["result"] = "over budget"
            stats["points"] = budget.spent + rows.points
            return None
        table, err_u, err_v = (_round(rows, axis, nu) if shear is None
                               else _round_sheared(rows, shear, nu, nv))
        per_row = max(per_row, rows.points / rows.computed)
        stats["rounds"] += 1
        stats["points"] = budget.spent + rows.points
        stats["colour_error"] = rows.colour_error
        stats["colour_errors"] = dict(zip(ILLUMINANTS, rows.colour_errors.tolist()))
        stats["errors"].append((nu, nv, err_u, err_v))
        if rows.colour_error > COLOUR_TOLERANCE:
            stats["result"] = "colour check failed"
            return None
        if err_u + err_v <= error:
            stats["result"] = "table"
            return Table(table, axis, err_u + err_v, table.shape[-1], resolution, shear=shear)
        if not budget.allows(rows.points):
            break
        if err_v > 0.5 * error:      # a finer v axis (unsheared: every row again)
            spacing *= 0.75 * (0.5 * error / err_v) ** 0.25
            if shear is None:
                budget.spend(rows.points)
                rows = Rows(side, axis, resolution, spacing)
        if err_u > 0.5 * error or err_u + min(err_v, 0.5 * error) > error:
            goal = 0.8 * error - min(err_v, 0.4 * error)
            factor = convergence_factor(nu, err_u, goal, last, FIRST_ORDER, margin=1.1, cap=6.0,
                                        highest=4.0)
            last = (nu, err_u)
            if not split and factor <= 2.0:
                # halving the spacing reuses every row computed (the nodes and the
                # midpoints): 2 (nu - 1) new rows, never more than a smaller factor
                # would compute afresh
                factor = 2.0
            if split:
                nu = 2 * (int(math.ceil((nu // 2 - 1) * factor)) + 1)
            else:
                nu = int(math.ceil((nu - 1) * factor)) + 1
    stats["result"] = "over budget"
    return None


def _sheared_nv(shear: Shear, sigma: float, spacing: float) -> int:
    """v nodes of a sheared axis: ``spacing`` times the Gaussian's width in ``ν'``
    where it is narrowest (``σ P_min``)."""
    span = SIGMA_MAX - shear.low
    return max(int(math.ceil(span / (spacing * sigma * shear.min_factor))) + 1, 16)


def _rows(side: SideData, axis: AngleAxis, resolution: float, spacing: float,
          shear: Shear | None) -> Rows:
    """The rows of a build: on a sheared axis, bins over every wavenumber a node
    ``ν'_t / P`` of any row (ghosts included) can ask for."""
    if shear is None:
        return Rows(side, axis, resolution, spacing)
    dv = (SIGMA_MAX - shear.low) / (_sheared_nv(shear, sigma_nu(resolution), spacing) - 1)
    margin = (GHOST + 1) * dv
    return Rows(side, axis, resolution, spacing,
                extent=((shear.low - margin) / shear.max_factor, (SIGMA_MAX + margin) / shear.min_factor))


def _round_sheared(rows: Rows, shear: Shear, nu: int, nv: int):
    """:func:`_round` on a sheared v axis (:mod:`thinfilm_mi.tabulate.shear`): the
    rows sampled at their nodes' ``ν'_t / P(s)``; a midpoint counts where its
    wavelength is within a node of 360-830 nm (the lookups' range) and outside
    the grazing sliver."""
    g = GHOST
    xn, xm = BAND.rows(nu)
    pn = shear.factor_np(1.0 - band_cos(xn) ** 2)
    pm = shear.factor_np(1.0 - band_cos(xm) ** 2)
    t = np.arange(-g, nv + g, dtype=np.float64)
    nodes_v = shear.node_wavenumbers(t, nv)                       # ν' of every v node
    mids_v = shear.node_wavenumbers(np.arange(nv - 1) + 0.5, nv)
    dv = (SIGMA_MAX - shear.low) / (nv - 1)
    nodes = np.swapaxes(rows.sample(xn, nodes_v[None, :] / pn[:, None]), 0, 1)
    mid_u = np.swapaxes(rows.sample(xm, nodes_v[None, g:-g] / pm[:, None]), 0, 1)
    mid_v = np.swapaxes(rows.sample(xn[g:-g], mids_v[None, :] / pn[g:-g, None]), 0, 1)
    cu = bspline_coefficients(nodes, axis=1)
    approx_u = bspline_midpoints(cu[g:-g], 1, g, nu)
    coeffs = bspline_coefficients(cu, axis=0)

    def counted(v, p, x):      # (len v, len p): in the lookups' range, not grazing
        return ((v[:, None] >= p[None, :] * SIGMA_MIN - dv) & (v[:, None] <= p[None, :] * SIGMA_MAX + dv)
                & (band_cos(x) >= GRAZING_COS)[None, :])
    dev = np.abs(mid_u - approx_u).max(axis=-1)
    err_u = float(np.max(np.where(counted(nodes_v[g:-g], pm, xm), dev, 0.0)))
    cols = np.arange(nu) + g
    cv = (coeffs[:, cols - 1] + 4.0 * coeffs[:, cols] + coeffs[:, cols + 1]) / 6.0
    dev = np.abs(mid_v - bspline_midpoints(cv, 0, g, nv)).max(axis=-1)
    err_v = float(np.max(np.where(counted(mids_v, pn[g:-g], xn[g:-g]), dev, 0.0)))
    return coeffs, err_u, err_v


def _round(rows: Rows, axis: AngleAxis, nu: int):
    """The spline coefficients of a table with ``nu`` angle nodes and ``rows.nv``
    wavelength nodes, and its errors ``(coefficients, err_u, err_v)``."""
    g, split, nv, b0 = GHOST, axis.split, rows.nv, rows.b0
    xn, xm = axis.rows(nu)
    vn, vm = rows.values(xn), rows.values(xm)
    tv = b0 + 2 * np.arange(-g, nv + g)                      # the v nodes' bins
    nodes = np.swapaxes(vn[:, tv], 0, 1)                      # (nv + 2g, rows, C)
    mid_u = np.swapaxes(vm[:, tv[g:-g]], 0, 1)                # (nv, mids, C)
    mid_v = np.swapaxes(vn[:, tv[g:-g - 1] + 1], 0, 1)        # (nv - 1, rows, C)
    if split:
        m = nu // 2
        segs = [np.moveaxis(with_ghosts(np.moveaxis(part, 1, 0), *ends), 0, 1)
                for part, ends in zip((nodes[:, :m], nodes[:, m:]), axis.ends)]
        cu = [bspline_coefficients(s, axis=1) for s in segs]
        approx_u = np.concatenate([bspline_midpoints(c[g:-g], 1, g, m) for c in cu], axis=1)
        cu = np.concatenate(cu, axis=1)
        real = np.arange(nu)
        cols = real + g + np.where(real >= m, 2 * g, 0)
    else:
        cu = bspline_coefficients(nodes, axis=1)
        approx_u = bspline_midpoints(cu[g:-g], 1, g, nu)
        real = np.arange(nu) + g
        cols = np.arange(nu) + g
    coeffs = bspline_coefficients(cu, axis=0)
    cos_m = _node_cos(rows, xm, tv[g:-g])
    dev = np.abs(mid_u - approx_u).max(axis=-1)
    dev = np.where(cos_m >= GRAZING_COS, dev, 0.0)
    err_u = float(np.max(dev))
    # the spline along v through node column j: the u spline's (1, 4, 1) / 6 of
    # the coefficients
    cv = (coeffs[:, cols - 1] + 4.0 * coeffs[:, cols] + coeffs[:, cols + 1]) / 6.0
    dev = np.abs(mid_v[:, real] - bspline_midpoints(cv, 0, g, nv)).max(axis=-1)
    cos_n = _node_cos(rows, xn[real], tv[g:-g])
    keep = (cos_n[:-1] >= GRAZING_COS) & (cos_n[1:] >= GRAZING_COS)
    err_v = float(np.max(np.where(keep, dev, 0.0)))
    return coeffs, err_u, err_v


def _node_cos(rows: Rows, xs: np.ndarray, bins: np.ndarray) -> np.ndarray:
    """cos θ_i of rows ``xs`` at the bins ``bins``: shape ``(len bins, len xs)``."""
    wl = 1.0 / rows.wavenumbers[bins]
    idx = side_indices(rows.side, wl)
    cos = rows._cos(xs, np.tile(np.arange(xs.size), len(bins)), idx,
                    np.repeat(np.arange(len(bins)), xs.size))
    return cos.reshape(len(bins), xs.size)
