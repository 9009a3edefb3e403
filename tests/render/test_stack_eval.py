"""A planned stack at a hit (thinfilm_mi/render/stack_eval.py): Mitsuba's own plugins
without films, each lane of a mask on its own side (under a branch, or both sides
selected), a lossless stack read from the substrate through its ambient side
(mirrored, with total internal reflection), and the side that is evaluated now.

Reference: Mitsuba's ``conductor`` and ``dielectric`` (no films), tmm's ``coh_tmm``
(float64, s and p averaged; tolerance: the float32 recursion, ``F32_TOL``)."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tmm

from tests.support.specular import F32_TOL, WLS, lit_floor_scene
from thinfilm_mi.render import stack_eval
from thinfilm_mi.render.film_stack import FilmStack, stack_facts
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.stack_build import build_plan
from thinfilm_mi.render.stack_plan import StackOptions, plan_sides

pytestmark = pytest.mark.usefixtures("llvm")
BOTH = {False: True, True: True}


@pytest.mark.parametrize("kind", ["conductor", "dielectric"])
def test_no_films_renders_like_mitsuba(kind):
    import thinfilm_mi  # noqa: F401  (registers the plugins)
    if kind == "conductor":
        ref = {"type": "conductor", "eta": 0.2, "k": 3.1}
        ours = {"type": "thinfilm_conductor", "layers": "", "eta": 0.2, "k": 3.1}
    else:
        ref = {"type": "dielectric", "int_ior": 1.5}
        ours = {"type": "thinfilm_dielectric", "layers": "", "int_ior": 1.5}
    a = np.array(mi.render(lit_floor_scene(ref), seed=7))
    b = np.array(mi.render(lit_floor_scene(ours), seed=7))
    rel = np.abs(a - b).mean() / np.abs(a).mean()
    assert rel < 1e-4, rel


def _stack(films) -> FilmStack:
    return FilmStack([(SpectralIndex.from_material(n, str(n)), d) for n, d in films],
                     SpectralIndex.from_material(1.0, "air"),
                     SpectralIndex.from_material(1.5, "glass"))


def _tmm(films, cos, inside):
    """Per lane (``cos``, ``inside``): tmm's ``(R, T)`` at each wavelength of ``WLS``."""
    out = np.zeros((2, len(WLS), len(cos)))
    for j, (c, flag) in enumerate(zip(cos, inside)):
        n = [1.0] + [f for f, _ in films] + [1.5]
        d = [np.inf] + [t for _, t in films] + [np.inf]
        if flag:
            n, d = n[::-1], d[::-1]
        for i, wl in enumerate(WLS):
            for pol in "sp":
                r = tmm.coh_tmm(pol, n, d, complex(np.arccos(c)), wl)
                out[:, i, j] += 0.5 * np.real([r["R"], r["T"]])
    return out


def _lanes_agree(stack, plan, films, cos, inside, tol):
    """``(R, T)`` (numpy, wavelength x lane) of lanes at ``cos`` on the sides ``inside``
    (a mask), checked against tmm within ``tol``."""
    si = dr.zeros(mi.SurfaceInteraction3f, len(cos))
    si.wavelengths = mi.Spectrum(WLS)
    R, T = stack_eval.reflectance(stack, plan, si, mi.Float(cos), inside=mi.Bool(inside),
                                  transmission=True)
    R, T = np.array(R), np.array(T)
    ref = _tmm(films, cos, inside)
    assert np.max(np.abs(R - ref[0])) < tol and np.max(np.abs(T - ref[1])) < tol
    return R, T


@pytest.mark.parametrize("films", [[(complex(2.0, 0.1), 120.0), (1.46, 80.0)],
                                   [(1.46, 100.0), (complex(1.5, 20.0), 1500.0)]],
                         ids=["branched", "selected"])
def test_each_lane_of_a_mask_is_evaluated_on_its_side(films):
    """An absorbing stack (both sides evaluated under a branch), and one with an
    optically opaque film (both sides computed, then selected)."""
    stack = _stack(films)
    plan = build_plan(plan_sides(stack_facts(stack), StackOptions(tabulate=False, sides=BOTH)))
    assert not plan.mirrored
    _lanes_agree(stack, plan, films, [0.9, 0.9, 0.4, 0.6], [False, True, False, True], F32_TOL)


@pytest.mark.parametrize("tabulate", [False, True])
def test_a_lossless_stack_from_the_substrate_through_its_ambient_side(tabulate):
    """Mirrored (render.mirror): ``R`` from the glass at ``θ_s`` is the ambient side's at
    ``n_a sin θ_a = n_s sin θ_s`` (exactly, or from its table), ``T = 1 - R``; beyond
    the critical angle (cos 0.6 from glass: 1.5 sin θ_s = 1.2) ``R = 1`` and ``T = 0``."""
    films = [(1.46, 100.0), (2.3, 60.0)]
    stack = _stack(films)
    plan = build_plan(plan_sides(stack_facts(stack), StackOptions(tabulate=tabulate, sides=BOTH)))
    table = plan.sides[False].table
    assert plan.mirrored and (table is not None) == tabulate and plan.sides[True].table is None
    tol = F32_TOL + (1.5 * table.error if tabulate else 0.0)   # a table: tests/support/tables.py
    R, T = _lanes_agree(stack, plan, films, [0.9, 0.9, 0.6, 0.3], [True, False, True, False], tol)
    assert np.all(R[:, 2] == 1.0) and np.all(T[:, 2] == 0.0)


def test_the_side_evaluated_now():
    """The planned side, unless a thickness or an index carries gradients: then every
    film, without skips, table or buffers."""
    stack = _stack([(1.46, 0.0), (1.46, 100.0)])
    plan = build_plan(plan_sides(stack_facts(stack), StackOptions(tabulate=False)))
    assert stack_eval.current_side(stack, plan, False, False) is plan.sides[False]
    assert len(plan.sides[False].films) == 1 and plan.sides[False].loop is not None
    every = stack_eval.current_side(stack, plan, False, False, index_gradients=True)
    assert len(every.films) == 2 and every.loop is None
    dr.enable_grad(stack.thickness[1])
    assert stack_eval.current_side(stack, plan, False, False) is not plan.sides[False]
    unplanned = stack_eval.current_side(stack, plan, True, True)   # not asked for: every film
    assert len(unplanned.films) == 2 and unplanned.n0 is stack.substrate
