"""The sweep's frame worker (thinfilm_mi/batch/worker.py): traversed values are checked on
the loaded scene."""
from __future__ import annotations

import mitsuba as mi
import pytest

from thinfilm_mi.batch import scene as tf_scene
from thinfilm_mi.batch import worker
from thinfilm_mi.errors import UsageError


def test_traverse_values_are_checked_on_the_scene(scene):
    mi.set_variant(tf_scene.DEFAULT_VARIANT)
    loaded = tf_scene.load_scene(scene)
    with pytest.raises(UsageError, match="did you mean sphere.bsdf.layers.0.thickness"):
        worker.set_parameters(loaded, None, [("sphere.bsdf.layers.0.thicknes", "3")])
    with pytest.raises(UsageError, match="single numbers"):
        worker.set_parameters(loaded, None, [("sphere.bsdf.layers.0.eta.values", "1.5")])
    with pytest.raises(UsageError, match="-P sphere.bsdf.layers.0.thickness and -P layers.0.thickness both "
                                         "name sphere.bsdf.layers.0.thickness"):
        worker.set_parameters(loaded, None, [("sphere.bsdf.layers.0.thickness", "3"), ("layers.0.thickness", "4")])
    params, notes = worker.set_parameters(loaded, None, [("layers.0.thickness", "250")])
    assert params["sphere.bsdf.layers.0.thickness"] == 250
    assert notes == ["-P layers.0.thickness: taken as sphere.bsdf.layers.0.thickness, the only parameter ending so"]
