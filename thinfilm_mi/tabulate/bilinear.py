"""Tables for bilinear lookups, resampled from a verified cubic-spline table.

A cubic lookup (:class:`~thinfilm_mi.tabulate.base.CubicSpline`) reads 16 texels per
wavelength, a bilinear one 4: in a spectral render (4 wavelengths a lookup, at
random wavelengths) a side's table of ``R`` [, ``T``] costs about a third as much read
bilinearly (render times: the generated benchmark pages). Linear interpolation needs more nodes for the same error (its
error falls as h^2, the spline's as h^4), so the table is made from the spline, not
from more exact evaluations:

1. the builders make and verify the spline within :data:`SPLINE_SHARE` of the target
   (:func:`~thinfilm_mi.tabulate.band.build_table`);
2. :func:`resample` evaluates the spline ``(ku, kv)`` times finer along the angle
   and the wavelength (uniform in each axis's node coordinate; a split axis per
   segment), choosing the factors from the spline's own linear-interpolation error
   (``∝ 1/k^2``), and verifies the result against the spline halfway between the
   fine nodes along each axis and at the cells' centres (outside the grazing sliver,
   :data:`~thinfilm_mi.tabulate.base.GRAZING_COS`, as the builds verify); the
   table's ``error`` is the spline's plus this;
3. a table that would need more than the caller's ``max_floats`` stays a spline.

No exact evaluation is spent: resampling and verifying is numpy over the fine table, its
texels in float64 and the checks in float32 (their rounding, ~1e-7, is far below a table's
error), against the float32 texels a lookup reads.
"""
from __future__ import annotations

import math

import numpy as np

from thinfilm_mi.tabulate.base import (
    BILINEAR,
    CUBIC,
    GHOST,
    GRAZING_COS,
    SideData,
    Table,
    bspline_weights,
    side_indices,
    v_nodes_wl,
)

__all__ = ["MAX_FACTOR", "SPLINE_SHARE", "resample"]

#: The share of a table's target error the spline is built to where the table is to be
#: read bilinearly; the resampling gets the rest. Halving the spline's target costs its
#: build 2^(1/4) = 1.19x the nodes per axis (1.4x the exact evaluations); a smaller share
#: would leave the resampling more and its table fewer texels, at a costlier build.
SPLINE_SHARE = 0.5
#: The largest resampling factor per axis (beyond it the table stays a spline).
MAX_FACTOR = 32
#: Resampling rounds: the factors from the spline's error at its own nodes, then raised
#: where the verification finds more (the error estimate ∝ 1/k^2 is asymptotic).
_ROUNDS = 4
#: The first factors aim each axis at this share of the resampling's budget.
_AIM = 0.8


def _along(coeffs: np.ndarray, n: int, k: int, half: bool) -> np.ndarray:
    """The spline with ``coeffs`` along axis 0 (``n`` real nodes after :data:`GHOST`
    ghosts) at the node coordinates ``j / k`` (``j = 0 .. k (n - 1)``), or with ``half``
    ``(j + 1/2) / k`` (``j = 0 .. k (n - 1) - 1``): as :func:`~thinfilm_mi.tabulate.base.bspline_at`
    does, one fraction of a cell at a time over every cell (array slices, no gathers)."""
    g, cells = GHOST, n - 1
    out = np.empty((cells * k + (0 if half else 1),) + coeffs.shape[1:], coeffs.dtype)
    taps = [coeffs[g - 1 + t:g - 1 + t + cells] for t in range(4)]
    for p in range(k):
        w = bspline_weights((p + (0.5 if half else 0.0)) / k)
        out[p::k][:cells] = w[0] * taps[0] + w[1] * taps[1] + w[2] * taps[2] + w[3] * taps[3]
    if not half:    # the last node (fraction 0 of the cell beyond it)
        w = bspline_weights(0.0)
        out[-1] = sum(w[t] * coeffs[g - 1 + cells + t] for t in range(3))
    return out


def _resampled(coeffs: np.ndarray, axis, nu: int, nv: int, ku: int, kv: int) -> dict:
    """The spline of ``coeffs`` (a :class:`~thinfilm_mi.tabulate.base.CubicSpline`
    texture, float64) at the fine nodes (``"nodes"``, float64: the table's texels),
    halfway between them along the angle (``"u"``), along the wavelength (``"v"``) and at
    the fine cells' centres (``"c"``; float32, as the checks need: its rounding, ~1e-7,
    is far below any table's error): each of shape ``(wavelength coordinates, segments x
    angle coordinates, channels)``, a split axis's segments side by side."""
    g, m = GHOST, nu // axis.segments
    rows = {False: [], True: []}
    for s in range(axis.segments):
        part = np.swapaxes(coeffs[:, s * (m + 2 * g):(s + 1) * (m + 2 * g)], 0, 1)
        rows[False].append(np.swapaxes(_along(part, m, ku, False), 0, 1))
        rows[True].append(np.swapaxes(_along(part.astype(np.float32), m, ku, True), 0, 1))
    nodes_u, mids_u = (_side_by_side(rows[h]) for h in (False, True))
    nodes_u32 = nodes_u.astype(np.float32)
    return {"nodes": _along(nodes_u, nv, kv, False), "u": _along(mids_u, nv, kv, False),
            "v": _along(nodes_u32, nv, kv, True), "c": _along(mids_u, nv, kv, True)}


def _side_by_side(parts: list) -> np.ndarray:
    """Segments' arrays joined along the angle axis (axis 1; no copy for one segment)."""
    return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)


def _verified(spline: Table, side: SideData, grids) -> list:
    """Where the verification counts on each of ``grids``, pairs ``(su, tv)`` of fine
    angle coordinates of every segment and wavelength coordinates: incidence outside the
    grazing sliver (one row for every wavelength where the axis's angle does not depend
    on it)."""
    axis, m = spline.axis, spline.nu // spline.axis.segments
    out = []
    for su, tv in grids:
        s = np.concatenate([su + i * m for i in range(axis.segments)])[None, :]
        if axis.needs_n_exit:     # the coordinate's angle depends on the indices at λ
            n0, _, ne = side_indices(side, v_nodes_wl(tv, spline.nv))
            n0 = np.broadcast_to(np.asarray(n0, np.float64), tv.shape)
            ne = np.broadcast_to(np.asarray(ne).real, tv.shape)
            # one row of cosines per distinct pair of indices (media of constant index:
            # one for every wavelength), the same numbers as a row per wavelength
            pairs, row = np.unique(np.stack([n0, ne]), axis=1, return_inverse=True)
            cos = axis.nodes_cos(s, pairs[0][:, None], pairs[1][:, None], spline.nu,
                                 ghost=0)[row.ravel()]
        else:
            cos = axis.nodes_cos(s, 1.0, 1.0, spline.nu, ghost=0)
        out.append(cos >= GRAZING_COS)
    return out


def _errors(spline: Table, side: SideData, coeffs: np.ndarray, ku: int, kv: int):
    """``(fine values, error along u, along v, at the cells' centres)`` of the spline
    resampled ``(ku, kv)`` times finer: bilinear interpolation of the float32 texels
    against the spline."""
    m = spline.nu // spline.axis.segments
    su, tv = np.arange(ku * (m - 1) + 1) / ku, np.arange(kv * (spline.nv - 1) + 1) / kv
    mu, mv = (np.arange(su.size - 1) + 0.5) / ku, (np.arange(tv.size - 1) + 0.5) / kv
    at = _resampled(coeffs, spline.axis, spline.nu, spline.nv, ku, kv)
    fine, segs = at["nodes"], spline.axis.segments
    texels = fine.astype(np.float32)

    def cells(a):   # per segment, the values between neighbouring fine nodes along u
        parts = np.split(a, segs, axis=1) if segs > 1 else [a]
        return _side_by_side([0.5 * (p[:, 1:] + p[:, :-1]) for p in parts])

    def worst(exact, linear, ok):
        dev = np.abs(np.subtract(exact, linear, out=exact), out=exact)   # in place
        dev = dev[..., 0] if dev.shape[-1] == 1 else dev.max(axis=-1)
        return float(np.max(dev, where=ok, initial=0.0))

    between = 0.5 * (texels[1:] + texels[:-1])
    ok_u, ok_v, ok_c = _verified(spline, side, ((mu, tv), (su, mv), (mu, mv)))
    return (fine, worst(at["u"], cells(texels), ok_u), worst(at["v"], between, ok_v),
            worst(at["c"], cells(between), ok_c))


def resample(spline: Table, side: SideData, error: float, max_floats: int) -> Table | None:
    """``spline`` (a verified :class:`~thinfilm_mi.tabulate.base.CubicSpline` table of
    ``side``) as a :class:`~thinfilm_mi.tabulate.base.Bilinear` table whose error is
    within ``error`` in all (the spline's plus the resampling's), or ``None`` where that
    needs more than ``max_floats`` floats (texels x channels) or :data:`MAX_FACTOR`."""
    budget = error - spline.error
    if spline.interpolation is not CUBIC or budget <= 0.0:
        return None
    coeffs = spline.values().astype(np.float64)
    m = spline.nu // spline.axis.segments
    ku = kv = 1
    for r in range(_ROUNDS + 1):
        floats = ((kv * (spline.nv - 1) + 1) * spline.axis.segments * (ku * (m - 1) + 1)
                  * spline.channels)
        if max(ku, kv) > MAX_FACTOR or floats > max_floats:
            return None
        fine, eu, ev, ec = _errors(spline, side, coeffs, ku, kv)
        if r == 0:
            # the spline's own linear error (k = 1) gives the first factors: each axis's
            # error falls as 1 / k^2 (asymptotically; faster from k = 1); the cells'
            # centres err about as the worse axis does (measured: the 30-film benchmark
            # stack at k = 4, 2.4e-4 along u, 5.9e-4 along v, 6.1e-4 at the centres)
            ku = max(1, math.ceil(math.sqrt(eu / (_AIM * budget))))
            kv = max(1, math.ceil(math.sqrt(ev / (_AIM * budget))))
            continue
        err = max(eu, ev, ec)
        if err <= budget:
            return Table(fine.astype(np.float32), spline.axis, spline.error + err,
                         spline.channels, spline.resolution, shear=spline.shear,
                         interpolation=BILINEAR, factors=(ku, kv))
        # raise the axis that errs (the centre's error is both axes')
        grow = math.sqrt(err / budget) * 1.1
        ku = math.ceil(ku * grow) if eu >= 0.5 * ec or eu >= ev else ku
        kv = math.ceil(kv * grow) if ev >= 0.5 * ec or ev > eu else kv
    return None
