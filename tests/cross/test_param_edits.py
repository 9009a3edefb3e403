"""Edits through ``mi.traverse`` + ``params.update()``: the complete matrix of bad values.

Every plugin, exact and tabulated, every traversed parameter it has: a bad value
(NaN, inf, out of range, negative where it must not be) raises a ThinFilmError that
names the key and the value; the BSDF keeps its last valid state (its sample
weights are unchanged, bit for bit), and a valid edit afterwards takes effect. Before
the guard, such edits rendered black or NaN, tables failed with "cannot convert float
NaN to integer", and an index edited to 0 and back left three plugins broken.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from thinfilm_mi.errors import ThinFilmError  # noqa: E402

NAN, INF = float("nan"), float("inf")
PLUGINS = {
    "thinfilm_conductor": {"specular_reflectance": 0.9, "thickness": 1.0},
    "thinfilm_dielectric": {"specular_reflectance": 0.9, "specular_transmittance": 0.8,
                            "thickness": 1.0},
    "thinfilm_diffuse": {"reflectance": 0.6},
    "thinfilm_roughconductor": {"specular_reflectance": 0.9, "alpha": 0.2, "thickness": 1.0},
    "thinfilm_roughdielectric": {"specular_reflectance": 0.9, "specular_transmittance": 0.8,
                                 "alpha": 0.2, "thickness": 1.0},
    "thinfilm_coating": {"coat_sigma_a": 0.5, "coat_thickness": 1.0, "bsdf": {"type": "diffuse"}},
}
BAD = [
    ("layers.0.eta.value", [NAN, 0.0, INF, -1.5, 1e10, 1e-12]),
    ("layers.1.k.value", [-1.0, NAN, INF, 1e10]),
    ("layers.0.thickness", [NAN, INF, -1.0]),
    ("alpha.value", [0.0, -0.1, NAN, 1e30]),
    ("specular_reflectance.value", [NAN, -1.0, INF]),
    ("specular_transmittance.value", [NAN, -0.5, INF]),
    ("reflectance.value", [2.0, -1.0, NAN]),
    ("thickness.value", [INF, -1.0, NAN]),
    ("coat_sigma_a.value", [-1.0, NAN, INF]),
    ("coat_thickness", [-1.0, NAN, INF]),
]
LAYERS = "1.5 200; 0.4+2.5j 12"


def weights(bsdf):
    si = dr.zeros(mi.SurfaceInteraction3f, 3)
    si.wavelengths = mi.Spectrum(450.0, 520.0, 610.0, 700.0)
    si.wi = mi.Vector3f([0.3, 0.6, 0.0], [0.0, 0.1, 0.2], [0.95, 0.79, 0.98])
    _, w = bsdf.sample(mi.BSDFContext(), si, mi.Float([0.0, 0.6, 0.9]),  # lane 0 reflects
                       mi.Point2f([0.3, 0.7, 0.5], [0.4, 0.2, 0.8]))
    return np.array(w, dtype=np.float64)


def cases():
    out = []
    for plugin, extra in PLUGINS.items():
        for tabulate in (False, "auto"):
            for key, values in BAD:
                top = key.split(".")[0]
                if not key.startswith("layers") and top not in extra:
                    continue
                if top == "thickness" and tabulate == "auto":
                    continue  # a thickness texture forces exact evaluation
                for v in values:
                    out.append(pytest.param(plugin, tabulate, key, v,
                                            id=f"{plugin}-{tabulate}-{key}-{v!r}"))
    return out


def load(plugin, tabulate, key):
    extra = dict(PLUGINS[plugin])
    if key.split(".")[0] != "thickness":
        extra.pop("thickness", None)   # keeps tables possible for the other keys
    return mi.load_dict({"type": plugin, "layers": LAYERS, "tabulate": tabulate, **extra})


@pytest.mark.parametrize("plugin, tabulate, key, bad", cases())
def test_bad_edit_raises_naming_key_and_value_and_keeps_last_valid_state(plugin, tabulate,
                                                                          key, bad):
    bsdf = load(plugin, tabulate, key)
    before = weights(bsdf)
    assert np.all(np.isfinite(before))
    params = mi.traverse(bsdf)
    assert key in params, sorted(params.keys())
    good = float(np.ravel(np.array(params[key]))[0])
    with pytest.raises(ThinFilmError) as err:
        params[key] = bad
        params.update()
    text = str(err.value)
    assert key in text and f"{bad:.7g}" in text, text   # float32 values, 7 digits
    assert plugin in text
    np.testing.assert_array_equal(weights(bsdf), before)
    assert float(np.ravel(np.array(mi.traverse(bsdf)[key]))[0]) == good
    # a valid edit afterwards takes effect (finite, and for these keys it changes R)
    params = mi.traverse(bsdf)
    params[key] = good * 1.05 if good > 0 else 0.3
    params.update()
    after = weights(bsdf)
    assert np.all(np.isfinite(after)) and np.all(after >= 0)
    assert not np.array_equal(after, before)


@pytest.mark.parametrize("plugin", ["thinfilm_dielectric", "thinfilm_roughconductor",
                                    "thinfilm_roughdielectric", "thinfilm_conductor",
                                    "thinfilm_diffuse"])


def test_index_set_to_zero_then_back_renders_as_before(plugin):
    """The issue's sequence: eta = 0 (refused), then the original value set again."""
    bsdf = load(plugin, "auto", "layers")
    before = weights(bsdf)
    params = mi.traverse(bsdf)
    with pytest.raises(ThinFilmError):
        params["layers.0.eta.value"] = 0.0
        params.update()
    params = mi.traverse(bsdf)
    params["layers.0.eta.value"] = 1.6
    params.update()
    params["layers.0.eta.value"] = 1.5
    params.update()
    np.testing.assert_allclose(weights(bsdf), before, rtol=1e-6, atol=1e-7)


def test_several_keys_in_one_update_are_all_undone():
    bsdf = load("thinfilm_roughconductor", False, "layers")
    before = weights(bsdf)
    params = mi.traverse(bsdf)
    params["layers.0.thickness"] = 300.0          # valid
    params["alpha.value"] = math.nan               # invalid
    with pytest.raises(ThinFilmError, match="alpha.value"):
        params.update()
    np.testing.assert_array_equal(weights(bsdf), before)
    assert float(np.ravel(np.array(mi.traverse(bsdf)["layers.0.thickness"]))[0]) == 200.0


def test_textures_are_checked_on_their_values_not_their_stored_coefficients():
    """An RGB albedo is stored as spectral-upsampling coefficients (some negative):
    edits are judged on what the texture evaluates to. A bitmap thickness scale
    edited to hold an infinity is refused and undone."""
    bsdf = mi.load_dict({"type": "thinfilm_diffuse", "layers": LAYERS,
                         "reflectance": {"type": "rgb", "value": [0.5, 0.3, 0.2]}})
    params = mi.traverse(bsdf)
    params["layers.0.thickness"] = 220.0      # a valid edit beside the RGB texture
    params.update()
    data = np.full((4, 4, 1), 1.0, np.float32)
    cond = mi.load_dict({"type": "thinfilm_conductor", "layers": LAYERS,
                         "thickness": {"type": "bitmap", "bitmap": mi.Bitmap(data),
                                       "raw": True}})
    before = weights(cond)
    params = mi.traverse(cond)
    key = next(k for k in params.keys() if k.startswith("thickness."))
    bad = np.array(params[key])
    bad.ravel()[5] = np.inf
    with pytest.raises(ThinFilmError, match=rf"'{key}' \(a thickness scale\).*inf"):
        params[key] = type(params[key])(bad)
        params.update()
    np.testing.assert_array_equal(weights(cond), before)
    assert np.all(np.isfinite(np.array(mi.traverse(cond)[key])))
