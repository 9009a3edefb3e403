"""How a stack is planned (thinfilm_mi/render/stack_plan.py), nothing built: the skips
of each lit side (films of zero thickness, what lies below an optically opaque film,
incoherent films), the lossless sides and the mirrored plan, the route of the
planned sides, and which sides a table pays for or read their films from buffers.

Reference for the opacity threshold: the amplitude of light crossing a film once at
normal incidence, ``exp(-2 pi k d / lambda)``, at its largest over 360-830 nm."""
from __future__ import annotations

import math

import mitsuba as mi
import pytest

from thinfilm_mi.render import stack_plan
from thinfilm_mi.render.film_stack import FilmStack
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.stack_plan import (
    OPAQUE_AMPLITUDE,
    StackOptions,
    StackPlan,
    few_films,
    full_plan,
    optically_opaque,
    plan_sides,
    reads_buffers,
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


def test_an_opaque_film_is_where_light_crossing_it_once_is_below_the_threshold():
    k = 2.0
    d = -math.log(OPAQUE_AMPLITUDE) * 830.0 / (2 * math.pi * k)   # the threshold at 830 nm
    film = SpectralIndex.from_material(complex(1.5, k), "film")
    assert optically_opaque(film, 1.01 * d, textured=False)
    assert not optically_opaque(film, 0.99 * d, textured=False)
    assert not optically_opaque(film, 10 * d, textured=True)   # a texture may thin it


def test_each_side_skips_what_it_does_not_need():
    """Ambient | 1.46 (0 nm) | 1.46 100 | opaque metal | 2.3 6000 | glass, lit from both
    sides: the zero film is dropped, each side stops at the metal (its exit medium,
    ``T = 0``), the thick film is incoherent."""
    metal = complex(1.5, 20.0)
    stack = _stack((1.46, 0.0), (1.46, 100.0), (metal, 1000.0), (2.3, 6000.0))
    plan = plan_sides(stack, StackOptions(sides=BOTH, coherence_thickness=5000.0))
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
    plan = plan_sides(_stack((1.46, 100.0), (2.3, 60.0)), StackOptions(sides=BOTH))
    assert plan.mirrored
    assert all(s.lossless and not s.transmission for s in plan.sides.values())
    assert plan.sides[True].exit_real and not plan.sides[False].exit_real
    down = plan_sides(_stack((1.46, 100.0), ambient=1.5, substrate=1.0), StackOptions(sides=BOTH))
    assert not down.mirrored   # the ambient side would totally reflect
    one = plan_sides(_stack((1.46, 100.0)), StackOptions(sides={False: True}))
    assert not one.mirrored and one.sides[False].lossless
    absorbing = plan_sides(_stack((complex(1.46, 0.1), 100.0)), StackOptions(sides=BOTH))
    assert not absorbing.mirrored and all(s.transmission for s in absorbing.sides.values())


def test_the_route_and_the_mirrored_table():
    plan = plan_sides(_stack((1.46, 100.0)), StackOptions(sides=BOTH))
    table = object()
    tabled = StackPlan({False: plan.sides[False].with_(table=table), True: plan.sides[True]}, True)
    assert tabled.mirror_table(tabled.sides[True]) is table and tabled.route() == "table"
    assert tabled.mirror_table(tabled.sides[False]) is None
    apart = StackPlan(tabled.sides, False)
    assert apart.mirror_table(apart.sides[True]) is None and apart.route() == "mixed"
    assert StackPlan(plan.sides, False).route() == "exact"
    assert plan.sides[False].table is None   # with_ returns a new plan


def test_which_sides_a_table_pays_for():
    def few(stack, options, side=False, quantity=POWERS):
        plan = plan_sides(stack, options)
        return few_films(stack, options, plan.sides[side], plan.mirrored, quantity)
    metal = _stack((1.46, 100.0), substrate="Al")
    assert not few(metal, StackOptions())                     # R: from AUTO_MIN_FILMS (1)
    lossy, n = [(complex(1.46, 0.01), 100.0)], policy.RT_AUTO_MIN_FILMS   # R and T
    assert few(_stack(*lossy * (n - 1)), StackOptions(sides={False: True}))
    assert not few(_stack(*lossy * n), StackOptions(sides={False: True}))
    assert few(_stack(*lossy * n), StackOptions(sides={False: True}, rt_min_films=n + 1))
    mirrored = _stack(*[(1.46, 100.0)] * (policy.MIRROR_AUTO_MIN_FILMS - 1))
    assert few(mirrored, StackOptions(sides=BOTH))
    plan = plan_sides(metal, StackOptions())
    assert wants_tables(metal, StackOptions(), plan, POWERS)
    assert not wants_tables(metal, StackOptions(tabulate=False), plan, POWERS)
    textured = _stack((1.46, 100.0), substrate="Al", texture=mi.load_dict({"type": "checkerboard"}))
    assert not wants_tables(textured, StackOptions(), plan_sides(textured, StackOptions()), POWERS)
    assert wants_tables(_stack(), StackOptions(tabulate=True), plan, POWERS)


def test_which_sides_read_their_films_from_buffers(monkeypatch):
    stack = _stack((1.46, 100.0), (2.3, 6000.0), substrate="Al")
    plan = plan_sides(stack, StackOptions(coherence_thickness=1e4))
    side = plan.sides[False]
    assert reads_buffers(plan, side, 1)
    assert not reads_buffers(plan, side.with_(table=type("T", (), {"channels": 1})()), 1)
    incoherent = plan_sides(stack, StackOptions(coherence_thickness=5000.0))
    assert not reads_buffers(incoherent, incoherent.sides[False], 1)
    monkeypatch.setattr(stack_plan, "BUFFERED_MIN_FILMS", 3)
    assert not reads_buffers(plan, side, 1)
