"""The render kernel of the specular plugins (thinfilm_mi/render/kernel.py): Mitsuba
equivalence with no films and loading from XML, for thinfilm_conductor and
thinfilm_dielectric alike; and deep stacks and edits under the build budget (issue 32).

* A stack whose table cannot repay its build is evaluated exactly at once: the
  budget (``tabulate.policy.MAX_BUILD_WORK``) is decided before the work, so a
  100-film stack spends no exact evaluation on a band-limited table, a 300-film one
  none on the exact probe either.
* A thickness that carries gradients reads every film exactly, so planning builds
  no table for it (an optimisation loop spends no time in builds).
* The image does not depend on when or how a table arrived: built at load or taken
  from the cache, the same seed gives the same image, bit for bit (1 spp, box filter).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from tests.support.specular import lit_floor_scene


@pytest.mark.parametrize("kind", ["conductor", "dielectric"])
def test_no_films_renders_like_mitsuba(kind):
    mi.set_variant("llvm_ad_spectral")
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


def test_load_from_xml_and_to_string(tmp_path):
    mi.set_variant("llvm_ad_spectral")
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

import thinfilm_mi  # noqa: F401  (registers the plugins)
from tests.support.stacks import benchmark_layers, sphere_scene
from thinfilm_mi.render import kernel as K
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
    K.TABLE_CACHE.clear()
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
    K.TABLE_CACHE.clear()
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
    K.TABLE_CACHE.clear()
    again = mi.load_dict(_scene(10))
    assert again.shapes()[0].bsdf().stack.plan[False].build_report["result"] == "table"
    assert np.array_equal(_render(again), first)


def test_a_table_asked_for_may_take_longer_than_auto_waits():
    """70 films: ``auto`` expects 2e8 film units, over its budget (1e8), and
    evaluates exactly without spending any; ``tabulate=true`` may spend
    ``REQUESTED_BUDGET_SCALE`` times as much and gets a verified band-limited table
    (measured 1.35e6 evaluations, ~1.2 s)."""
    K.TABLE_CACHE.clear()
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
    K.TABLE_CACHE.clear()


def test_a_table_asked_for_beyond_even_that_is_refused_after_a_sample():
    """300 films: the band-limited build's expectation (8e8 film units) is within 10x
    the budget, but the first round's cost per row, measured on ``band.SAMPLE_ROWS``
    of its rows, is not (the resonances multiply the adaptive panels): the build
    stops there (~3 s, where the whole build took 175 s) and the warning says why."""
    K.TABLE_CACHE.clear()
    with pytest.warns(UserWarning, match=r"\(over budget\)"):
        b = mi.load_dict(dict(_bsdf(300), tabulate=True))
    assert b.stack.mode() == "exact"
    report = b.stack.plan[False].build_report
    assert report["rounds"] == 0 and 0 < report["points"]
    K.TABLE_CACHE.clear()
