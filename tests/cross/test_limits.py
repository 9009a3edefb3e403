"""Documented limits: every plugin works at the film limit (``MAX_FILMS``) and refuses
one more."""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
from thinfilm_mi.materials.stack import MAX_FILMS  # noqa: E402

DEEP = "; ".join(f"{2.3 if i % 2 else 1.38} {60 + i % 7}" for i in range(MAX_FILMS))
PLUGINS = ["thinfilm_conductor", "thinfilm_dielectric", "thinfilm_diffuse",
           "thinfilm_roughconductor", "thinfilm_roughdielectric"]


@pytest.mark.parametrize("plugin", PLUGINS)
def test_every_plugin_works_at_the_film_limit_and_refuses_one_more(plugin):
    bsdf = mi.load_dict({"type": plugin, "layers": DEEP, "tabulate": False})
    si = dr.zeros(mi.SurfaceInteraction3f, 64)
    si.wavelengths = mi.Spectrum(450.0, 520.0, 610.0, 700.0)
    si.wi = mi.Vector3f(0.4, 0.0, float(np.sqrt(1 - 0.16)))
    rng = np.random.default_rng(3)
    _, w = bsdf.sample(mi.BSDFContext(), si, mi.Float(rng.random(64)),
                       mi.Point2f(rng.random((2, 64))))
    w = np.array(w)
    assert np.all(np.isfinite(w)) and np.all(w >= 0) and w.max() > 0
    with pytest.raises(Exception, match=f"{MAX_FILMS + 1} films given, at most {MAX_FILMS}"):
        mi.load_dict({"type": plugin, "layers": DEEP + "; 1.5 10", "tabulate": False})
