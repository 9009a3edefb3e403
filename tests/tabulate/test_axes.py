"""thinfilm_mi.tabulate.axes: every registered angle axis, its lookup coordinate against
its node positions, its rows against its nodes, and the lookup by name.

Reference: each axis's own inverse. ``texel`` (the coordinate a render kernel computes
from a direction, Dr.Jit math) must give back the node coordinate ``s`` of the
direction ``nodes_cos`` places there (the builds' float64 numpy): both are written
independently from the axis's definition, so a mistake in either shows as a mismatch.
In float64 the round trip is exact to rounding: 1e-9 nodes is ~1e6 ulps of the
coordinate at these sizes, far below any error that would move a lookup.
"""
from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.llvm import Float64

from thinfilm_mi.tabulate import axes
from thinfilm_mi.tabulate.base import Table

#: the indices of a split axis: lit from glass (1.52) over an exit medium of 1.0
N0, N_EXIT = 1.52, 1.0
NU = 64


def _texel(axis, cos):
    cos = np.asarray(cos, np.float64)
    sin = np.sqrt(np.maximum(1.0 - cos * cos, 0.0))
    x = axis.texel(Float64(cos), Float64(sin), Float64(np.full(cos.shape, N0)),
                   Float64(np.full(cos.shape, N_EXIT)), NU)
    dr.eval(x)
    return np.array(x, np.float64)


@pytest.mark.parametrize("name", sorted(axes.AXES))
def test_texel_inverts_the_node_positions(name):
    """``texel(nodes_cos(s)) = s`` over each segment of every axis (a split axis's
    critical node excluded: the cell across the critical angle has zero width, its
    two sides map to the two segments)."""
    axis = axes.AXES[name]
    m = NU // axis.segments
    s = np.concatenate([np.linspace(k * m, k * m + m - 1, 41)[:-1 if k == 0 and axis.split else None]
                        for k in range(axis.segments)])
    cos = axis.nodes_cos(s, np.float64(N0), np.float64(N_EXIT), NU)
    assert np.all((cos >= 0.0) & (cos <= 1.0))
    # At grazing incidence w = 1 - sqrt(x) has an infinite slope: an angle known to
    # float64's ~2e-16 rad (band's nodes come from a bisection) moves the coordinate by
    # up to (nu - 1) sqrt(4 eps) ~ 2e-6 nodes there; everywhere else 1e-9.
    tol = np.where(cos < 1e-6, (NU - 1) * np.sqrt(4 * np.finfo(np.float64).eps), 1e-9)
    err = np.abs(_texel(axis, cos) - s)
    assert np.all(err <= tol), (s[err > tol], err[err > tol])


@pytest.mark.parametrize("axis", [axes.BAND, axes.TIR])
def test_rows_are_at_the_nodes(axis):
    """The band-limited build's rows (``rows``, ``row_cos``) lie at the same angles as
    the table's nodes (``nodes_cos``): a row coordinate is the node coordinate over the
    segment's intervals (plus 2 for a split axis's second segment)."""
    nodes, mids = axis.rows(NU)
    g = axes.GHOST
    if axis.split:
        m = NU // 2
        s = np.where(nodes < 1.5, nodes * (m - 1), m + (nodes - 2.0) * (m - 1))
    else:
        s = np.arange(-g, NU + g, dtype=np.float64)
    np.testing.assert_allclose(axis.row_cos(nodes, np.float64(N0), np.float64(N_EXIT)),
                               axis.nodes_cos(s, np.float64(N0), np.float64(N_EXIT), NU),
                               rtol=0, atol=1e-12)
    assert mids.size == NU - axis.segments      # one midpoint per cell of each segment


def test_axis_for_the_exit_medium():
    """A real exit medium of lower index at every wavelength splits the axis, one that
    absorbs or is denser does not, and one that crosses ``n0`` has no axis."""
    n0 = np.full(5, 1.52)
    assert axes.axis_for(n0, np.full(5, 1.0 + 0j)) is axes.TIR
    assert axes.axis_for(n0, np.full(5, 0.2 + 3.1j)) is axes.PLAIN
    assert axes.axis_for(n0, np.full(5, 1.8 + 0j)) is axes.PLAIN
    assert axes.axis_for(n0, np.linspace(1.4, 1.6, 5) + 0j) is None
    assert axes.PLAIN.band_limited is axes.BAND and axes.TIR.band_limited is axes.TIR


def test_lookup_by_name():
    """Every axis is registered under its name (what the table store keeps); another
    name is refused with the name in the message."""
    for name, axis in axes.AXES.items():
        assert axes.angle_axis(name) is axis and axis.name == name
    with pytest.raises(ValueError, match="'split'"):
        axes.angle_axis("split")


@pytest.mark.parametrize("axis", [axes.PLAIN, axes.TIR])
def test_table_shape_follows_the_segments(axis):
    """A table's node counts come from its texture's shape less the ghosts of every
    segment (a split axis stores two segments side by side, each with its ghosts)."""
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    g, nu, nv = axes.GHOST, 20, 12
    values = np.zeros((nv + 2 * g, nu + 2 * g * axis.segments, 1), np.float32)
    table = Table(values, axis, 0.0, 1)
    assert (table.nu, table.nv, table.axis) == (nu, nv, axis)
