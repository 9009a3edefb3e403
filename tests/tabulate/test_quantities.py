"""thinfilm_mi.tabulate.quantities: every registered quantity's two ways to its channels.

A quantity gives its channels two ways: the build's evaluator (``rt``, through
:func:`~thinfilm_mi.tabulate.base.evaluate_side`) and, for the band-limited build's first
level, the smooth amplitudes (``smooth_terms``) turned into channels by ``values``.
The two are written independently (the recursion's powers or Mueller components, and
the projective amplitudes ``N``, ``D`` divided out in numpy), so they check each other:
in float64 they agree to rounding (1e-9 is ~1e7 ulps of a power in [0, 1]; what they
compute differs only in the order of the operations).
"""
from __future__ import annotations

import numpy as np
import pytest

from thinfilm_mi.tabulate import quantities
from thinfilm_mi.tabulate.base import SideData, evaluate_side, side_indices


def _const(v):
    return lambda wl: np.full(np.shape(wl), v)


def _side(quantity, transmission: bool, exit_index: complex) -> SideData:
    films = [(_const(2.3 + 0j), 120.0), (_const(1.46 + 0j), 95.0), (_const(0.05 + 3.2j), 12.0)]
    side = SideData(n0=_const(1.0), films=films, n_exit=_const(exit_index),
                    transmission=transmission, rt=quantity.rt([False] * len(films)),
                    quantity=quantity, fringe_films=[0, 1, 2], rt_loop=quantity.rt_loop)
    wl = np.linspace(380.0, 800.0, 12)
    side.absorbing = (False, False, True, bool(np.imag(exit_index)))
    return side, wl


@pytest.mark.parametrize("transmission", [False, True])
@pytest.mark.parametrize("name", sorted(quantities.QUANTITIES))
def test_smooth_terms_give_the_evaluators_channels(name, transmission):
    """``values(smooth_terms(...))`` equals the evaluator's channels at the same points,
    for every quantity, with and without transmission (a glass exit, where ``T``
    exists; cos from grazing-free 0.05 to normal)."""
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    q = quantities.QUANTITIES[name]
    side, wl = _side(q, transmission, 1.5 + 0j)
    cos = np.tile(np.linspace(0.05, 1.0, 9), wl.size)
    rows = np.repeat(np.arange(wl.size), 9)
    idx = side_indices(side, wl)
    direct = evaluate_side(side, cos, rows, wl, idx)
    terms, exps = q.smooth_terms(side, cos, rows, wl, idx)
    assert direct.shape[-1] == q.channels(transmission) == q.grazing(transmission).size
    if not np.any(exps):   # exponents 0: the terms are the amplitudes themselves
        np.testing.assert_allclose(q.values(terms, transmission), direct, rtol=0, atol=1e-9)
    else:                  # undo the power-of-two rescaling (exact) before forming channels
        scale = np.exp2(exps)
        t = terms.copy()
        t[:, 0:4] *= scale[:, 0:1]
        t[:, 4:8] *= scale[:, 1:2]
        if q.squared_terms and t.shape[-1] > 8:
            t[:, 8:10] *= scale * scale
        np.testing.assert_allclose(q.values(t, transmission), direct, rtol=0, atol=1e-9)


def test_registry_names():
    """Each quantity is registered under its name (part of the table cache's key: the
    powers keep the name their tables were stored under)."""
    assert set(quantities.QUANTITIES) == {"powers", "mueller"}
    for name, q in quantities.QUANTITIES.items():
        assert q.name == name
    assert quantities.POWERS.channels(False) == 1 and quantities.POWERS.channels(True) == 2
