"""Building a stack's plan (thinfilm_mi/render/stack_build.py): deep stacks and edits
under the build budget, and the tables and buffers returned with the sides.

* A stack whose table cannot repay its build is evaluated exactly at once: the
  budget (``tabulate.policy.MAX_BUILD_WORK``) is decided before the work, so a
  100-film stack spends no exact evaluation on a band-limited table, a 300-film one
  none on the exact probe either.
* A thickness that carries gradients reads every film exactly, so planning builds
  no table for it (an optimisation loop spends no time in builds).
* The image does not depend on when or how a table arrived: built at load or taken
  from the cache, the same seed gives the same image, bit for bit (1 spp, box filter).
* A build returns new sides (the plan it was given keeps none of its tables), and a
  mirrored plan whose ambient side has no table is planned side by side.
* An edit builds no table for a side of ``policy.EDIT_EXACT_MIN_FILMS`` films or more:
  it is evaluated exactly (within ``table_error`` of float64), from the cached kernel, and
  reads the load's table again once edited back.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.kernels import assert_edits_render_from_cache, interaction
from tests.support.stacks import benchmark_layers, benchmark_thicknesses, sphere_scene
from tests.support.tables import random_points, ref_R
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render import media, stack_build
from thinfilm_mi.tabulate import policy


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")
    import thinfilm_mi  # noqa: F401,F811
    yield


def _bsdf(films: int) -> dict:
    return {"type": "thinfilm_conductor", "material": "Al", "layers": benchmark_layers(films)}


@pytest.mark.parametrize("films, probe", [(100, "rejected by the probe"), (300, "probe over budget")])
def test_deep_stacks_are_rejected_before_the_work(films, probe):
    stack_build.TABLE_CACHE.clear()
    bsdf = mi.load_dict(_bsdf(films))
    report = bsdf.stack.plan[False].build_report
    assert bsdf.stack.mode() == "exact"
    assert report["result"] == "over budget (expected)" and report["points"] == 0
    assert report["exact_attempt"]["result"] == probe
    # the probe's 5.6e4 points of 104 film units are within its budget; 300 films' are not
    assert report["exact_attempt"]["points"] == (0 if films == 300 else report["exact_attempt"]["probe_points"])


def _scene(films: int) -> dict:
    return sphere_scene(_bsdf(films))


def _render(scene) -> np.ndarray:
    return np.array(mi.render(scene, seed=3))


def test_gradients_build_no_table_and_the_image_does_not_depend_on_the_build():
    stack_build.TABLE_CACHE.clear()
    scene = mi.load_dict(_scene(10))
    bsdf = scene.shapes()[0].bsdf()
    assert bsdf.stack.mode() == "table"          # built at load
    first = _render(scene)
    params = mi.traverse(scene)
    key = "ball.bsdf.layers.0.thickness"
    value = mi.Float(params[key])
    # an edit while gradients are enabled: no build, the films are read exactly
    dr.enable_grad(params[key])
    params.update()
    assert bsdf.stack.mode() == "exact" and bsdf.stack.plan[False].build_report is None
    # gradients off again: the table comes back from the cache, and with it the image
    params[key] = mi.Float(value)
    params.update()
    assert bsdf.stack.plan[False].build_report["result"] == "from the cache"
    assert np.array_equal(_render(scene), first)
    # a fresh build (empty cache) at a new load gives the same image too
    stack_build.TABLE_CACHE.clear()
    again = mi.load_dict(_scene(10))
    assert again.shapes()[0].bsdf().stack.plan[False].build_report["result"] == "table"
    assert np.array_equal(_render(again), first)


def test_an_edited_deep_side_is_evaluated_exactly_and_an_edit_back_reads_its_table():
    """Edits through ``mi.traverse(scene)`` of a stack of ``EDIT_EXACT_MIN_FILMS`` films
    on Al (``auto``: a table at load): the edited side reads its films from buffers, not
    given up on, within ``table_error`` of the float64 recursion of the edited stack
    (a stale table, 7 nm off, is not); a further edit renders from the cached kernel;
    the loaded value again reads the load's table from the cache; a bad value is refused
    naming the key and the value."""
    stack_build.TABLE_CACHE.clear()
    films = policy.EDIT_EXACT_MIN_FILMS
    scene = mi.load_dict(sphere_scene(_bsdf(films)))
    stack = scene.shapes()[0].bsdf().stack
    assert stack.mode() == "table"
    params = mi.traverse(scene)
    key = "ball.bsdf.layers.0.thickness"
    loaded = float(params[key][0])
    params[key] = loaded + 7.0
    params.update()
    side = stack.plan[False]
    assert stack.mode() == "exact" and side.loop is not None and stack.table_failed == []
    assert side.build_report["result"] == stack_build.NOT_REBUILT
    d = benchmark_thicknesses(films)
    d[0] += 7.0
    ref = tf.Stack(benchmark_layers(films).replace(repr(float(d[0] - 7.0)), repr(float(d[0]))),
                   substrate="Al", ambient=media.DEFAULT_EXT_IOR)
    cos, wls = random_points(4000)
    R = np.array(stack.reflectance(interaction(wls), mi.Float(cos.astype(np.float32))))
    err = max(np.max(np.abs(R[i] - ref_R(ref, cos, wls[i]))) for i in range(4))
    assert err <= stack.table_error, err
    assert_edits_render_from_cache(scene, params, {key: loaded + 19.0})
    params[key] = loaded
    params.update()
    assert stack.mode() == "table" and stack.plan[False].build_report["result"] == "from the cache"
    params[key] = -1.0
    with pytest.raises(ThinFilmError, match=r"'layers\.0\.thickness' .* got -1\b"):
        params.update()
    stack_build.TABLE_CACHE.clear()


def test_a_table_asked_for_may_take_longer_than_auto_waits():
    """70 films: ``auto`` expects 2e8 film units, over its budget (1e8), and
    evaluates exactly without spending any; ``tabulate=true`` may spend
    ``REQUESTED_BUDGET_SCALE`` times as much and gets a verified band-limited table
    (measured 1.35e6 evaluations, ~1.2 s)."""
    stack_build.TABLE_CACHE.clear()
    auto = mi.load_dict(_bsdf(70))
    report = auto.stack.plan[False].build_report
    assert auto.stack.mode() == "exact" and report["result"] == "over budget (expected)"
    assert report["expected_work"] > policy.MAX_BUILD_WORK and report["points"] == 0
    asked = mi.load_dict(dict(_bsdf(70), tabulate=True))
    report = asked.stack.plan[False].build_report
    assert asked.stack.mode() == "table" and report["result"] == "table"
    assert report["expected_work"] <= policy.REQUESTED_BUDGET_SCALE * policy.MAX_BUILD_WORK
    table = asked.stack.plan[False].table
    assert table.error <= 1e-3 and table.resolution == 1.0 and table.shear is not None
    stack_build.TABLE_CACHE.clear()


def test_a_table_asked_for_beyond_even_that_is_refused_after_a_sample():
    """300 films: the band-limited build's expectation (8e8 film units) is within 10x
    the budget, but the first round's cost per row, measured on ``band.SAMPLE_ROWS``
    of its rows, is not (the resonances multiply the adaptive panels): the build
    stops there (~3 s, where the whole build took 175 s) and the warning says why."""
    stack_build.TABLE_CACHE.clear()
    with pytest.warns(UserWarning, match=r"\(over budget\)"):
        b = mi.load_dict(dict(_bsdf(300), tabulate=True))
    assert b.stack.mode() == "exact"
    report = b.stack.plan[False].build_report
    assert report["rounds"] == 0 and 0 < report["points"]
    stack_build.TABLE_CACHE.clear()


def _films(*films, ambient=1.0, substrate=1.5):
    from thinfilm_mi.render.film_stack import FilmStack
    from thinfilm_mi.render.media import SpectralIndex
    return FilmStack([(SpectralIndex.from_material(n, f"film {i}"), d) for i, (n, d) in enumerate(films)],
                     SpectralIndex.from_material(ambient, "ambient"),
                     SpectralIndex.from_material(substrate, "substrate"))


def _plan(stack, options, gave_up=frozenset()):
    from thinfilm_mi.render.film_stack import stack_facts
    from thinfilm_mi.render.stack_plan import plan_sides
    return plan_sides(stack_facts(stack), options, gave_up)


def test_a_build_returns_new_sides_and_leaves_the_plan_it_was_given():
    from thinfilm_mi.render.stack_plan import StackOptions
    stack = _films((1.46, 150), (2.3, 60), substrate="Al")
    options = StackOptions(tabulate=True)
    plan = _plan(stack, options)
    built = stack_build.build_tables(plan)
    assert built.sides[False].table is not None and built.sides[False].build_report is not None
    assert plan.sides[False].table is None and plan.sides[False].build_report is None
    assert built.sides[False] is not plan.sides[False]
    # the same optics again: the same table, from the cache
    again = stack_build.build_tables(_plan(stack, options))
    assert again.sides[False].table is built.sides[False].table
    assert again.sides[False].build_report["result"] == "from the cache"


def test_a_table_serves_its_side_and_buffers_are_built_where_none_does():
    """The plan's ``buffered`` sides read their films from buffers unless a table serves
    them: a side's own table holds T wherever the side asks for it (the films absorb,
    so T is not 1 - R)."""
    from thinfilm_mi.render.stack_plan import StackOptions
    stack = _films((complex(1.46, 0.01), 150), (2.3, 60), substrate="Al")
    for sides in ({False: False}, {False: True}):
        tabled = stack_build.build_plan(_plan(stack, StackOptions(tabulate=True, sides=sides)))
        side = tabled.sides[False]
        assert side.buffered and side.table is not None and side.loop is None
        assert side.table.channels == (2 if sides[False] else 1)
        exact = stack_build.build_plan(_plan(stack, StackOptions(tabulate=False, sides=sides)))
        assert exact.sides[False].table is None and exact.sides[False].loop is not None


def test_a_mirrored_plan_without_the_ambient_sides_table_is_planned_side_by_side():
    """Four lossless films between constant media, lit from both sides: the side lit
    from the substrate reads the ambient side's table (mirrored). Where ``"auto"``
    gave up on the ambient side's table, that side is evaluated exactly and the other
    one gets a table of its own (of ``R``: lossless, ``T = 1 - R``)."""
    from thinfilm_mi.render.stack_plan import StackOptions
    stack = _films((1.46, 120), (2.3, 70), (1.46, 120), (2.3, 70))
    options = StackOptions(sides={False: True, True: True})
    plan = stack_build.build_plan(_plan(stack, options))
    assert plan.mirrored and plan.sides[True].table is None
    assert plan.mirror_table(plan.sides[True]) is plan.sides[False].table is not None
    assert plan.sides[False].loop is None and plan.sides[True].loop is None
    alone = stack_build.build_plan(_plan(stack, options, gave_up=frozenset({False})))
    assert not alone.mirrored and alone.sides[False].table is None
    assert alone.sides[True].table is not None and not alone.sides[True].transmission
    assert alone.sides[False].loop is not None and alone.sides[True].loop is None
    assert alone.gave_up == {False} and alone.failed == []


def test_a_side_that_cannot_be_tabulated_is_named_and_the_other_keeps_its_table(monkeypatch):
    """``tabulate=true`` over an absorbing stack on glass (the paper's Fig. 8c): where the
    side lit from the substrate cannot be tabulated (there, beyond the critical angle,
    the metal films' plasmon dip is narrower than a table within ``table_error`` in
    ``MAX_TEXELS`` can follow: ~2 s to find out, so its build is made to fail here), the
    warning names that side and the plan is mixed: the ambient side reads its table."""
    from thinfilm_mi.render.stack_plan import StackOptions
    real = stack_build.side_table

    def fail_inside(facts, options, side, quantity=None):
        if side.n0 is not facts.stack.ambient:
            return None, {"result": "over budget"}
        return real(facts, options, side) if quantity is None else real(facts, options, side, quantity)
    monkeypatch.setattr(stack_build, "side_table", fail_inside)
    stack = _films((1.46, 500), ("Au", 20), ("Al", 10), substrate=1.6)
    options = StackOptions(tabulate=True, sides={False: True, True: True})
    with pytest.warns(UserWarning, match=r"the side of the stack \[.*\] lit from the substrate "
                                         r"cannot be tabulated .*; that side is evaluated exactly"):
        plan = stack_build.build_tables(_plan(stack, options))
    assert plan.sides[False].table is not None and plan.sides[True].table is None
    assert plan.failed == [True]
