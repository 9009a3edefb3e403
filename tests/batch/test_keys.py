"""The key a sweep's -P names (thinfilm_mi/batch/keys.py): a key, the end of one key, a
shape's path to a BSDF with its own id; an object without an id is said to have none."""
from __future__ import annotations

import re

import mitsuba as mi
import pytest

from tests.support import ROOT
from thinfilm_mi.batch import scene as tf_scene
from thinfilm_mi.batch.keys import ParameterNames, is_generated_name, parameter_names, resolve_all
from thinfilm_mi.errors import UsageError

#: a scene without ids (a PLYMesh, a rectangle) and one whose shapes refer to BSDFs by id
NO_IDS = ParameterNames(["object_140671453362112.bsdf.layers.0.thickness",
                         "object_140671453362112.bsdf.layers.0.eta.values",
                         "object_94354819496784.bsdf.reflectance.value", "allow_thread_reordering"],
                        holders={"object_140671453362112": ("PLYMesh", "shape"),
                                 "object_94354819496784": ("Rectangle", "shape")})
SHARED = ParameterNames(["gold.layers.0.thickness", "silver.layers.0.thickness", "copper.layers.0.thickness",
                         "teapot.to_world"],
                        shapes=[("teapot", "silver"), ("sphere", "gold"), ("cap", "copper"), ("", "floor")])


def test_a_key_is_taken_whole_or_by_its_end():
    key = "object_140671453362112.bsdf.layers.0.thickness"
    assert NO_IDS.resolve(key) == (key, None)
    chosen, note = NO_IDS.resolve("bsdf.layers.0.thickness")
    assert chosen == key
    assert note.startswith(f"-P bsdf.layers.0.thickness: taken as {key}, the only parameter ending so "
                           "(object_140671453362112 is a PLYMesh without an id, named anew at every load: "
                           "give it one in the scene's XML, <shape ... id=\"NAME\">, and name the parameter "
                           "NAME.bsdf.layers.0.thickness)")
    assert NO_IDS.resolve("thickness")[0] == key
    with pytest.raises(UsageError, match="not a parameter of the scene"):
        NO_IDS.resolve("ickness")           # whole components only
    with pytest.raises(UsageError, match=r"-P layers.0.thickness: 3 parameters of the scene end so "
                                         r"\(copper.layers.0.thickness, gold.layers.0.thickness, "
                                         r"silver.layers.0.thickness\); give more of the key$"):
        SHARED.resolve("layers.0.thickness")


def test_a_shape_names_the_bsdf_it_refers_to():
    assert SHARED.resolve("teapot.bsdf.layers.0.thickness") == (
        "silver.layers.0.thickness", "-P teapot.bsdf.layers.0.thickness: taken as silver.layers.0.thickness "
        "(the shape's BSDF has its own id, silver, which names it in mi.traverse)")
    assert SHARED.resolve("cap.bsdf.layers.0.thickness")[0] == "copper.layers.0.thickness"
    with pytest.raises(UsageError, match="did you mean teapot.bsdf.layers.0.thickness"):
        SHARED.resolve("teapot.layers.0.thickness")
    with pytest.raises(UsageError, match="-P teapot.bsdf.layers.0.thickness and -P silver.layers.0.thickness "
                                         "both name silver.layers.0.thickness"):
        resolve_all(SHARED, ["teapot.bsdf.layers.0.thickness", "silver.layers.0.thickness"])


def test_a_key_that_names_nothing_says_what_comes_close():
    # the case: a made-up id for a shape that has none
    with pytest.raises(UsageError) as err:
        NO_IDS.resolve("shape_0.bsdf.layers.0.thickness")
    text = str(err.value)
    assert ("no object has the id 'shape_0'; did you mean bsdf.layers.0.thickness? (object_140671453362112 is a "
            "PLYMesh without an id, named anew at every load: give it one in the scene's XML") in text, text
    with pytest.raises(UsageError, match=r"did you mean bsdf.layers.0.thickness\b"):
        NO_IDS.resolve("bsdf.layers.0.thicknes")
    with pytest.raises(UsageError) as err:
        NO_IDS.resolve("bsdf.layers.0.thicknes")
    assert "object_140671453362112.bsdf" not in str(err.value).split("(")[0]  # never suggests a made-up name
    assert is_generated_name("object_140671453362112") and is_generated_name("object_12_1")
    assert not is_generated_name("teapot") and not is_generated_name("object_teapot")


def test_the_guides_key_names_a_film_on_every_shipped_scene():
    """Every film of every shipped scene has a name that lasts (its shape's or its BSDF's id),
    and the sweeps guide's -P key names a film on each (costs ~7 s: it loads the 15 scenes)."""
    guide = (ROOT / "docs" / "guides" / "sweeps.md").read_text()
    teapot, slab = "teapot.bsdf.layers.0.thickness", "coated_slab.bsdf.layers.0.thickness"
    assert f"-P {teapot}=" in guide and f"`{slab}`" in guide
    scenes = sorted((ROOT / "scenes").glob("*.xml"))
    assert len(scenes) >= 15
    previous = mi.variant()
    try:
        for path in scenes:
            variant, _ = tf_scene.scene_variant(path, {}, tf_scene.DEFAULT_VARIANT)
            tf_scene.setup_variant(variant)
            loaded = tf_scene.load_scene(path, size=(8, 8), spp=1)
            params = mi.traverse(loaded)
            films = [k for k in params.keys() if re.search(r"\.layers\.\d+\.thickness$", k)]
            assert films and not [k for k in films if is_generated_name(k.split(".")[0])], (path.name, films)
            key = slab if path.name == "polarized_brewster.xml" else teapot
            assert parameter_names(loaded, params).resolve(key)[0] in films, path.name
    finally:
        mi.set_variant(previous or tf_scene.DEFAULT_VARIANT)
