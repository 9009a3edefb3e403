"""The stack the plugins evaluate (thinfilm_mi/render/kernel.py): ``KernelStack`` composes
what a stack is (``render.film_stack``), its options and plan (``render.stack_plan``),
what is built for the plan (``render.stack_build``) and its evaluation
(``render.stack_eval``), under the names the plugins and models call; each part is
tested in its own module (tests/render/test_film_stack.py, test_stack_plan.py,
test_stack_build.py, test_side_eval.py, test_stack_eval.py).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins)
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.kernel import KernelStack
from thinfilm_mi.render.media import SpectralIndex

pytestmark = pytest.mark.usefixtures("llvm")


def _stack(**options) -> KernelStack:
    films = [(SpectralIndex.from_material(1.46, "SiO2"), 150.0),
             (SpectralIndex.from_material("Au", "Au"), 20.0)]
    return KernelStack(films, SpectralIndex.from_material(1.0, "air"),
                       SpectralIndex.from_material(1.5, "glass"), **options)


def test_the_names_its_users_call_read_its_parts():
    stack = _stack(sides={False: True, True: True}, tabulate=False, table_error=2e-3)
    assert len(stack) == 2 and stack.describe() == "[1.46 150 nm; Au 20 nm]"
    assert stack.indices is stack.films.indices and stack.thickness is stack.films.thickness
    assert (stack.ambient, stack.substrate, stack.thickness_texture, stack.plugin) == (
        stack.films.ambient, stack.films.substrate, None, "thin-film BSDF")
    assert (stack.tabulate.name, stack.table_error, stack.sides) == ("false", 2e-3,
                                                                    {False: True, True: True})
    assert stack.plan is stack.planned.sides and stack.mirrored is stack.planned.mirrored
    assert stack.mode() == "exact" and stack.table_failed == []
    assert stack.current_plan(False, True) is stack.plan[False]


def test_an_edit_plans_the_stack_again():
    """Au 20 nm absorbs, so the stack is not mirrored; at 0 nm it is dropped, and the
    lossless film left is read from both sides through the ambient side (mirrored)."""
    stack = _stack(sides={False: True, True: True}, tabulate=False)
    before = stack.planned
    assert not stack.mirrored and len(stack.plan[False].films) == 2
    stack.thickness[1] = mi.Float(0.0)   # as mi.traverse sets it
    stack.parameters_changed()
    assert stack.planned is not before and len(stack.plan[False].films) == 1
    assert stack.mirrored
    stack.thickness[1] = mi.Float(-1.0)
    with pytest.raises(ThinFilmError, match=r"layers\.1\.thickness .* got -1\.0"):
        stack.parameters_changed()


def test_a_table_asked_for_under_a_thickness_texture_is_refused():
    texture = mi.load_dict({"type": "checkerboard"})
    with pytest.raises(ThinFilmError, match="'tabulate' is true but a 'thickness' texture"):
        _stack(tabulate=True, thickness_texture=texture)
    stack = _stack(thickness_texture=texture)   # "auto": evaluated exactly
    assert stack.mode() == "exact" and stack.thickness_texture is texture
    assert np.isfinite(stack.films.thickness_values()).all()


def test_an_edit_that_makes_a_film_opaque_plans_its_sides_again():
    """Au at 20 nm lets light through; at 3000 nm it hides the glass below it: each side
    then ends at the gold (``T = 0``), and at 20 nm again the plan is as before."""
    stack = _stack(sides={False: True, True: True}, tabulate=False)
    assert not any(s.opaque for s in stack.plan.values())
    stack.thickness[1] = mi.Float(3000.0)
    stack.parameters_changed()
    outside, inside = stack.plan[False], stack.plan[True]
    assert outside.opaque and outside.exit is stack.indices[1] and len(outside.films) == 1
    assert inside.opaque and inside.exit is stack.indices[1] and inside.films == []
    stack.thickness[1] = mi.Float(20.0)
    stack.parameters_changed()
    assert not any(s.opaque for s in stack.plan.values()) and len(stack.plan[False].films) == 2
