"""What a stack is (thinfilm_mi/render/film_stack.py): its films as ``to_string`` and
``mi.traverse`` show them (loaded from XML too), an edit's checks, its facts for a plan
(each medium on the grid, which absorb, which films are opaque), and what a hit asks of
it (the thickness texture's scale, whether a parameter carries gradients).

Reference for the opacity threshold: the amplitude of light crossing a film once at
normal incidence, ``exp(-2 pi k d / lambda)``, at its largest over 360-830 nm."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins)
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.film_stack import (
    OPAQUE_AMPLITUDE,
    FilmStack,
    on_grid,
    optically_opaque,
    stack_facts,
)
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.textures import GRID

pytestmark = pytest.mark.usefixtures("llvm")


def _stack(*films, texture=None) -> FilmStack:
    return FilmStack([(SpectralIndex.from_material(n, str(n)), d) for n, d in films],
                     SpectralIndex.from_material(1.0, "air"),
                     SpectralIndex.from_material(1.5, "glass"), texture, "a plugin")


def test_load_from_xml_and_to_string(tmp_path):
    xml = tmp_path / "bsdf.xml"
    xml.write_text("""<scene version="3.0.0">
  <bsdf type="thinfilm_dielectric" id="glass">
    <float name="int_ior" value="1.6"/>
    <string name="layers" value="1.46 500; 0.42+2.47j 20; 1.2+7j 10"/>
  </bsdf>
  <bsdf type="thinfilm_conductor" id="si">
    <float name="thin_film_ior" value="1.46"/>
    <float name="thin_film_thickness" value="500"/>
    <spectrum name="eta" value="4.08"/>
    <spectrum name="k" value="0.03"/>
  </bsdf>
</scene>""")
    scene = mi.load_file(str(xml))
    text = str(scene)
    assert "ThinFilmDielectric" in text or "glass" in text
    glass = mi.load_dict({"type": "thinfilm_dielectric", "int_ior": 1.6,
                          "layers": "1.46 500; 0.42+2.47j 20"})
    desc = str(glass)
    assert "1.46 500 nm" in desc and "0.42+2.47j 20 nm" in desc and "1.6" in desc


def test_films_media_and_parameters():
    stack = _stack((1.46, 500), (2.3, 80))
    assert len(stack) == 2 and stack.describe() == "[1.46 500 nm; 2.3 80 nm]"
    assert _stack().describe() == "[no films]"
    assert stack.media() == [stack.ambient, stack.substrate] + stack.indices
    assert stack.thickness_values() == [500.0, 80.0]
    params = mi.traverse(mi.load_dict({"type": "thinfilm_conductor", "material": "Al",
                                       "layers": "1.46 500; 2.3 80"}))
    assert {"layers.0.thickness", "layers.1.thickness"} <= set(params.keys())


def test_an_edit_is_checked_and_every_thickness_kept_opaque():
    """A literal thickness would be baked into the kernel (an edit would recompile
    it): after an edit every thickness is an opaque variable. A bad value raises an
    error naming the parameter and the value."""
    stack = _stack((1.46, 500), (2.3, 80))
    stack.thickness[1] = mi.Float(120.0)
    assert stack.thickness[1].state == dr.VarState.Literal
    stack.parameters_changed()
    assert stack.thickness[1].state != dr.VarState.Literal
    assert stack.thickness_values() == [500.0, 120.0]
    for bad in (float("nan"), float("inf"), -3.0):
        stack.thickness[0] = mi.Float(bad)
        with pytest.raises(ThinFilmError, match=rf"a plugin: layers\.0\.thickness .* got {bad!r}"):
            stack.parameters_changed()


def test_what_a_hit_asks():
    stack = _stack((1.46, 500))
    si = dr.zeros(mi.SurfaceInteraction3f)
    assert stack.thickness_scale_at(si) is None
    assert not stack.differentiating() and not stack.colour_gradients(si)
    dr.enable_grad(stack.thickness[0])
    assert stack.differentiating() and stack.colour_gradients(si)
    textured = _stack((1.46, 500), texture=mi.load_dict({"type": "uniform", "value": -0.5}))
    assert dr.all(textured.thickness_scale_at(si) == 0.0)   # clamped to >= 0


def test_an_opaque_film_is_where_light_crossing_it_once_is_below_the_threshold():
    k = 2.0
    d = -math.log(OPAQUE_AMPLITUDE) * 830.0 / (2 * math.pi * k)   # the threshold at 830 nm
    n = on_grid(SpectralIndex.from_material(complex(1.5, k), "film"))
    assert optically_opaque(n, 1.01 * d, textured=False)
    assert not optically_opaque(n, 0.99 * d, textured=False)
    assert not optically_opaque(n, 10 * d, textured=True)   # a texture may thin it
    assert not optically_opaque(None, 10 * d, textured=False)   # no one spectrum: never


def test_the_facts_a_plan_reads_are_the_stack_as_it_is_now():
    """Each medium on the grid once (as the kernel reads it), which absorb, which films
    hide what lies beneath; read again after an edit (a thinner metal lets light through)."""
    stack = _stack((1.46, 100), (complex(1.5, 20.0), 1000), (2.3, 0))
    facts = stack_facts(stack)
    assert facts.stack is stack and facts.thickness == [100.0, 1000.0, 0.0]
    assert set(facts.grid) == {id(ix) for ix in stack.media()}
    np.testing.assert_array_equal(facts.grid[id(stack.substrate)], np.full(GRID.size, 1.5 + 0j))
    assert [facts.real[id(ix)] for ix in stack.indices] == [True, False, True]
    assert facts.opaque == [False, True, False] and not facts.differentiating
    stack.thickness[1] = mi.Float(10.0)
    stack.parameters_changed()
    assert stack_facts(stack).opaque == [False, False, False]
    assert stack_facts(_stack((complex(1.5, 20.0), 1000), texture=mi.load_dict(
        {"type": "checkerboard"}))).opaque == [False]   # a texture may thin it
    varying = SpectralIndex.from_textures(mi.load_dict({"type": "checkerboard"}),
                                          mi.load_dict({"type": "uniform", "value": 0.0}), "eta")
    assert on_grid(varying) is None   # varies over the surface: no one spectrum
