"""How a stack is planned from what it is (thinfilm_mi/render/stack_plan.py), nothing
built: the skips of each lit side (films of zero thickness, what lies below an
optically opaque film, incoherent films), the lossless sides and the mirrored plan, the
route of the planned sides, and the plan's answers for the build: whether tables are
built, which sides a table pays for, which read their films from buffers."""
from __future__ import annotations

from dataclasses import replace

import drjit as dr
import mitsuba as mi
import pytest

from thinfilm_mi.render import stack_plan
from thinfilm_mi.render.film_stack import FilmStack, stack_facts
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.stack_plan import (
    StackOptions,
    StackPlan,
    buffered,
    few_films,
    full_plan,
    plan_sides,
    wants_tables,
)
from thinfilm_mi.tabulate import policy
from thinfilm_mi.tabulate.quantities import POWERS

pytestmark = pytest.mark.usefixtures("llvm")
BOTH = {False: True, True: True}


def _stack(*films, ambient=1.0, substrate=1.5, texture=None) -> FilmStack:
    return FilmStack([(SpectralIndex.from_material(n, str(n)), d) for n, d in films],
                     SpectralIndex.from_material(ambient, "ambient"),
                     SpectralIndex.from_material(substrate, "substrate"), texture)


def _plan(stack: FilmStack, options: StackOptions, gave_up=frozenset()) -> StackPlan:
    return plan_sides(stack_facts(stack), options, gave_up)


def test_each_side_skips_what_it_does_not_need():
    """Ambient | 1.46 (0 nm) | 1.46 100 | opaque metal | 2.3 6000 | glass, lit from both
    sides: the zero film is dropped, each side stops at the metal (its exit medium,
    ``T = 0``), the thick film is incoherent."""
    metal = complex(1.5, 20.0)
    stack = _stack((1.46, 0.0), (1.46, 100.0), (metal, 1000.0), (2.3, 6000.0))
    plan = _plan(stack, StackOptions(sides=BOTH, coherence_thickness=5000.0))
    outside, inside = plan.sides[False], plan.sides[True]
    assert [ix for ix, _, _ in outside.films] == [stack.indices[1]]
    assert outside.exit is stack.indices[2] and outside.opaque and not outside.exit_real
    assert outside.n0 is stack.ambient and outside.incoherent == [False]
    assert [ix for ix, _, _ in inside.films] == [stack.indices[3]] and inside.incoherent == [True]
    assert inside.n0 is stack.substrate and inside.exit is stack.indices[2] and inside.opaque
    assert not plan.mirrored and plan.route() == "exact"
    every = full_plan(stack, False, True)   # gradients read every film, no skips
    assert [ix for ix, _, _ in every.films] == stack.indices and not every.opaque
    assert every.incoherent == [False] * 4 and every.exit is stack.substrate


def test_a_lossless_stack_lit_from_both_sides_is_mirrored():
    """Real films between real media, the substrate's index at least the ambient's:
    ``T = 1 - R`` on both sides (no ``T`` asked of a table), both read through the
    ambient side (render.mirror)."""
    plan = _plan(_stack((1.46, 100.0), (2.3, 60.0)), StackOptions(sides=BOTH))
    assert plan.mirrored
    assert all(s.lossless and not s.transmission for s in plan.sides.values())
    assert plan.sides[True].exit_real and not plan.sides[False].exit_real
    down = _plan(_stack((1.46, 100.0), ambient=1.5, substrate=1.0), StackOptions(sides=BOTH))
    assert not down.mirrored   # the ambient side would totally reflect
    one = _plan(_stack((1.46, 100.0)), StackOptions(sides={False: True}))
    assert not one.mirrored and one.sides[False].lossless
    absorbing = _plan(_stack((complex(1.46, 0.1), 100.0)), StackOptions(sides=BOTH))
    assert not absorbing.mirrored and all(s.transmission for s in absorbing.sides.values())


def test_the_route_and_the_mirrored_table():
    plan = _plan(_stack((1.46, 100.0)), StackOptions(sides=BOTH))
    table = object()
    tabled = StackPlan({False: replace(plan.sides[False], table=table), True: plan.sides[True]}, True)
    assert tabled.mirror_table(tabled.sides[True]) is table and tabled.route() == "table"
    assert tabled.mirror_table(tabled.sides[False]) is None
    apart = StackPlan(tabled.sides, False)
    assert apart.mirror_table(apart.sides[True]) is None and apart.route() == "mixed"
    assert StackPlan(plan.sides, False).route() == "exact"


def test_which_sides_a_table_pays_for():
    def few(stack, options, side=False, quantity=POWERS):
        plan = _plan(stack, options)
        return few_films(stack, options, plan.sides[side], plan.mirrored, quantity)
    metal = _stack((1.46, 100.0), substrate="Al")
    assert not few(metal, StackOptions())                     # R: from AUTO_MIN_FILMS (1)
    lossy, n = [(complex(1.46, 0.01), 100.0)], policy.RT_AUTO_MIN_FILMS   # R and T
    assert few(_stack(*lossy * (n - 1)), StackOptions(sides={False: True}))
    assert not few(_stack(*lossy * n), StackOptions(sides={False: True}))
    assert few(_stack(*lossy * n), StackOptions(sides={False: True}, rt_min_films=n + 1))
    mirrored = _stack(*[(1.46, 100.0)] * (policy.MIRROR_AUTO_MIN_FILMS - 1))
    assert few(mirrored, StackOptions(sides=BOTH))
    plan = _plan(metal, StackOptions())
    assert wants_tables(metal, StackOptions(), plan.sides, plan.mirrored, POWERS)
    assert not wants_tables(metal, StackOptions(tabulate=False), plan.sides, plan.mirrored, POWERS)
    textured = _stack((1.46, 100.0), substrate="Al", texture=mi.load_dict({"type": "checkerboard"}))
    at = _plan(textured, StackOptions())
    assert not wants_tables(textured, StackOptions(), at.sides, at.mirrored, POWERS)
    assert wants_tables(_stack(), StackOptions(tabulate=True), plan.sides, plan.mirrored, POWERS)


def test_the_plan_says_which_sides_are_tabulated():
    """What the build reads: tables at all (not under a thickness texture, nor while a
    thickness carries gradients), and per side whether a table is built: not where
    ``"auto"`` gave up on it, and for the side lit from the substrate of a mirrored plan
    as if it were planned on its own (it is built only without the ambient side's)."""
    metal = _stack((1.46, 100.0), substrate="Al")
    plan = _plan(metal, StackOptions())
    assert plan.tables and plan.sides[False].tabulate and plan.quantity is POWERS
    assert not _plan(metal, StackOptions(), gave_up={False}).sides[False].tabulate
    assert _plan(metal, StackOptions(tabulate=True), gave_up={False}).sides[False].tabulate
    assert not _plan(metal, StackOptions(tabulate=False)).tables
    textured = _stack((1.46, 100.0), substrate="Al", texture=mi.load_dict({"type": "checkerboard"}))
    assert not _plan(textured, StackOptions()).sides[False].tabulate
    dr.enable_grad(metal.thickness[0])
    assert not _plan(metal, StackOptions(tabulate=True)).tables
    n = policy.MIRROR_AUTO_MIN_FILMS
    mirrored = _plan(_stack(*[(1.46, 100.0), (2.3, 60.0)] * n), StackOptions(sides=BOTH))
    assert mirrored.mirrored and mirrored.sides[False].tabulate and mirrored.sides[True].tabulate
    few = _plan(_stack(*[(1.46, 100.0)] * (n - 1)), StackOptions(sides=BOTH))
    assert few.mirrored and not few.sides[False].tabulate    # constant media: exact mirror


def test_which_sides_read_their_films_from_buffers(monkeypatch):
    """Where no table serves them (stack_build decides that from what it built):
    JIT variants, coherent films with knots, from :data:`BUFFERED_MIN_FILMS` films."""
    stack = _stack((1.46, 100.0), (2.3, 6000.0), substrate="Al")
    side = _plan(stack, StackOptions(coherence_thickness=1e4)).sides[False]
    assert side.buffered and buffered(side)
    incoherent = _plan(stack, StackOptions(coherence_thickness=5000.0)).sides[False]
    assert not incoherent.buffered
    monkeypatch.setattr(stack_plan, "BUFFERED_MIN_FILMS", 3)
    assert not buffered(side)
