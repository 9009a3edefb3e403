"""One planned side at a hit (thinfilm_mi/render/side_eval.py): ``R`` and ``T`` of a side
evaluated exactly (films unrolled from their textures, or read from their buffers), of
a side below an optically opaque film, and of a side read from its table.

Reference: tmm's ``coh_tmm`` (float64, s and p averaged). Tolerances: the float32
recursion, ``F32_TOL`` (tests/support/specular.py); a table adds its verified error
(``table.error``, at most ``table_error``), 1.5x as in tests/support/tables.py."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest
import tmm

from tests.support.specular import F32_TOL, WLS, interaction
from thinfilm_mi.render.film_stack import FilmStack, stack_facts
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.side_eval import side_response
from thinfilm_mi.render.stack_build import build_plan
from thinfilm_mi.render.stack_plan import StackOptions, plan_sides

pytestmark = pytest.mark.usefixtures("llvm")
FILM, METAL = complex(2.0, 0.1), complex(0.5, 3.0)


def _stack(films, substrate) -> FilmStack:
    return FilmStack([(SpectralIndex.from_material(n, str(n)), d) for n, d in films],
                     SpectralIndex.from_material(1.0, "air"),
                     SpectralIndex.from_material(substrate, "substrate"))


def _tmm(n_list, d_list, cos):
    out = {q: np.zeros(len(WLS)) for q in "RT"}
    for i, wl in enumerate(WLS):
        for pol in "sp":
            r = tmm.coh_tmm(pol, n_list, d_list, float(np.arccos(cos)), wl)
            out["R"][i] += 0.5 * r["R"]
            out["T"][i] += 0.5 * r["T"]
    return out["R"], out["T"]


def _rt(side, cos, transmission=True):
    out = side_response(side, interaction(cos), mi.Float(cos), True, transmission, None)
    if not transmission:
        return np.array(out).ravel()
    return tuple(np.array(x).ravel() for x in out)


@pytest.mark.parametrize("cos", [1.0, 0.6, 0.2])
def test_an_exact_side_unrolled_or_from_buffers_is_tmms(cos):
    stack = _stack([(FILM, 120.0), (1.46, 80.0)], 1.5)
    options = StackOptions(tabulate=False, sides={False: True})
    unrolled = plan_sides(stack_facts(stack), options).sides[False]
    buffered = build_plan(plan_sides(stack_facts(stack), options)).sides[False]
    assert unrolled.loop is None and buffered.loop is not None
    R, T = _tmm([1.0, FILM, 1.46, 1.5], [np.inf, 120.0, 80.0, np.inf], cos)
    for side in (unrolled, buffered):
        r, t = _rt(side, cos)
        assert np.max(np.abs(r - R)) < F32_TOL and np.max(np.abs(t - T)) < F32_TOL


def test_below_an_opaque_film_nothing_is_evaluated():
    """The side ends at the metal (its exit medium): ``R`` is that of the film over
    a metal half-space, ``T`` exactly 0."""
    stack = _stack([(1.46, 100.0), (METAL, 1500.0), (FILM, 50.0)], 1.5)
    options = StackOptions(tabulate=False, sides={False: True})
    side = plan_sides(stack_facts(stack), options).sides[False]
    assert side.opaque and side.exit is stack.indices[1]
    r, t = _rt(side, 0.7)
    R, _ = _tmm([1.0, 1.46, METAL], [np.inf, 100.0, np.inf], 0.7)
    assert np.max(np.abs(r - R)) < F32_TOL and np.all(t == 0.0)


def test_a_side_read_from_its_table():
    stack = _stack([(1.46, 150.0), (2.3, 60.0)], METAL)
    side = build_plan(plan_sides(stack_facts(stack), StackOptions(tabulate=True))).sides[False]
    assert side.table is not None
    for cos in (0.95, 0.5):
        R, _ = _tmm([1.0, 1.46, 2.3, METAL], [np.inf, 150.0, 60.0, np.inf], cos)
        r = _rt(side, cos, transmission=False)
        assert np.max(np.abs(r - R)) < 1.5 * side.table.error + F32_TOL
