"""Bad input never crashes or corrupts: the complete matrix.

Every case is loaded through ``mi.load_dict`` *and* ``mi.load_string`` (XML), for
every plugin of :data:`thinfilm_mi.plugins.PLUGINS` that takes the parameter
(decided by loading the plugin with a *valid* value of that parameter: a plugin
that reports it as an unreferenced property does not take it, and the case is
skipped for that plugin with that reason). Each must raise at scene load a
Python exception whose text names the parameter and the offending value --
Mitsuba's parser wraps exceptions from Python plugin constructors in a
``RuntimeError`` whose text contains ours, so the text is what is asserted --
and afterwards a valid scene must still load and evaluate in the same process.

Plugin-specific inputs (``model``, ``reflectance`` of ``thinfilm_diffuse``,
...) are tested with their plugins; the LLVM guard of the numpy API is tested in
tests/test_llvm.py, and here only through scene loading in a subprocess.
"""
from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
from xml.sax.saxutils import quoteattr

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins)
from tests.support.plugin_modules import REQUIRED, import_error, plugin_dict
from thinfilm_mi.plugins import PLUGINS

VARIANT = "llvm_ad_spectral"
HOW = ["dict", "xml"]


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant(VARIANT)
    yield
    mi.set_variant(VARIANT)


# ---------------------------------------------------------------------------
# Loading through both front ends
# ---------------------------------------------------------------------------
def _xml_value(name: str, v) -> str:
    if isinstance(v, bool):
        return f'<boolean name="{name}" value="{str(v).lower()}"/>'
    if isinstance(v, str):
        return f'<string name="{name}" value={quoteattr(v)}/>'
    if isinstance(v, (int, float)):
        return f'<float name="{name}" value="{float(v)!r}"/>'
    if isinstance(v, dict):
        body = "".join(_xml_value(k, x) for k, x in v.items() if k != "type")
        tag = "bsdf" if name == "bsdf" else "texture"  # a nested BSDF (thinfilm_coating's base)
        return f'<{tag} name="{name}" type="{v["type"]}">{body}</{tag}>'
    raise TypeError(v)


def to_xml(plugin: str, props: dict) -> str:
    body = "".join(_xml_value(k, v) for k, v in {**REQUIRED.get(plugin, {}), **props}.items())
    return f'<scene version="3.0.0"><bsdf type="{plugin}" id="b">{body}</bsdf></scene>'


def load(plugin: str, props: dict, how: str):
    if how == "dict":
        return mi.load_dict(plugin_dict(plugin, **props))
    return mi.load_string(to_xml(plugin, props))


_takes: dict = {}


def takes(plugin: str, props: dict) -> bool:
    """Whether ``plugin`` loads with these *valid* ``props`` (i.e. takes the parameters)."""
    key = (plugin, repr(sorted(props.items())))
    if key not in _takes:
        try:
            load(plugin, props, "dict")
            _takes[key] = True
        except Exception as e:  # noqa: BLE001
            if "unreferenced propert" not in str(e):
                raise AssertionError(f"valid {props!r} fails to load in {plugin}: {e}") from None
            _takes[key] = False
    return _takes[key]


def still_works(plugin: str) -> None:
    """A valid scene loads and a BSDF of the same plugin evaluates, in this process."""
    bsdf = load(plugin, {"layers": "0.4+2.5j 15"}, "dict")
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.Spectrum([400.0, 500.0, 600.0, 700.0])
    si.wi = mi.Vector3f(0.6, 0.0, 0.8)
    bs, w = bsdf.sample(mi.BSDFContext(), si, 0.3, mi.Point2f(0.4, 0.6))
    w = np.array(w, dtype=np.float64)
    assert np.all(np.isfinite(w)) and np.all(w >= 0), w
    scene = mi.load_string(to_xml(plugin, {}))
    assert "ThinFilm" in str(scene)


def check_raises(plugin: str, props: dict, how: str, needles: list[str]) -> None:
    with pytest.raises(Exception) as err:
        load(plugin, props, how)
    text = str(err.value)
    for needle in needles:
        assert needle in text, f"{needle!r} not in the error text:\n{text}"
    still_works(plugin)


# ---------------------------------------------------------------------------
# The matrix: (id, bad props, needles in the message, valid props that show the
# plugin takes the parameter)
# ---------------------------------------------------------------------------
LAYERS_OK = {"layers": "1.46 100"}
SHORTHAND_OK = {"thin_film_ior": 1.46, "thin_film_thickness": 100.0}

CASES = [
    # negative, NaN and infinite thicknesses
    ("layers-negative-thickness", {"layers": "1.46 -5"}, ["layers[0]", "-5"], LAYERS_OK),
    ("layers-nan-thickness", {"layers": "1.46 nan"}, ["layers[0]", "nan"], LAYERS_OK),
    ("layers-inf-thickness-2nd", {"layers": "1.46 100; 2.0 inf"}, ["layers[1]", "inf"],
     LAYERS_OK),
    ("layers-non-numeric-thickness", {"layers": "1.46 abc"}, ["layers[0]", "abc"], LAYERS_OK),
    ("shorthand-negative-thickness", {"thin_film_ior": 1.46, "thin_film_thickness": -3.0},
     ["thin_film_thickness", "-3.0"], SHORTHAND_OK),
    ("shorthand-nan-thickness", {"thin_film_ior": 1.46, "thin_film_thickness": float("nan")},
     ["thin_film_thickness", "nan"], SHORTHAND_OK),
    # unknown materials, with suggestions
    ("layers-unknown-material", {"layers": "SiO3 100"},
     ["layers[0]", "'SiO3'", "did you mean", "'SiO2'"], LAYERS_OK),
    ("layers-unknown-name-2nd", {"layers": "SiO2 100; unobtainium 20"},
     ["layers[1]", "'unobtainium'"], LAYERS_OK),
    ("shorthand-unknown-material", {"thin_film_ior": "Gld", "thin_film_thickness": 10.0},
     ["thin_film_ior", "'Gld'", "did you mean", "'Au'"], SHORTHAND_OK),
    ("material-unknown", {"material": "Aux"}, ["material", "'Aux'", "did you mean", "'Au'"],
     {"material": "Au"}),
    ("ext_ior-unknown", {"ext_ior": "watr"}, ["ext_ior", "'watr'", "did you mean", "'water'"],
     {"ext_ior": "water"}),
    ("int_ior-unknown", {"int_ior": "BK8"}, ["int_ior", "'BK8'", "did you mean", "'BK7'"],
     {"int_ior": "BK7"}),
    # malformed `layers`
    ("layers-missing-thickness", {"layers": "1.46"}, ["layers[0]", "'1.46'", "missing thickness"],
     LAYERS_OK),
    ("layers-missing-thickness-2nd", {"layers": "1.46 100; Au"}, ["layers[1]", "'Au'",
                                                                   "missing thickness"], LAYERS_OK),
    ("layers-extra-token", {"layers": "1.46 100 7"}, ["layers[0]", "'1.46 100 7'", "3 tokens"],
     LAYERS_OK),
    ("layers-comma-separator", {"layers": "1.46 100, 2.0 50"},
     ["layers[0]", "'1.46 100, 2.0 50'", "4 tokens", "';'"], LAYERS_OK),
    ("layers-pipe-separator", {"layers": "1.46 100 | 2.0 50"}, ["layers[0]", "5 tokens"],
     LAYERS_OK),
    ("layers-comma-inside", {"layers": "1.46,100"}, ["layers[0]", "'1.46,100'",
                                                     "missing thickness"], LAYERS_OK),
    # a file name cut at ';' or a space: the message says to quote it (issue 39)
    ("layers-unquoted-path-with-semicolon", {"layers": "films/a;b.csv 100"},
     ["layers[0]", "'films/a'", "missing thickness", "goes in quotes"], LAYERS_OK),
    ("layers-unquoted-path-with-space", {"layers": "my films/a.csv 100"},
     ["layers[0]", "3 tokens", "goes in quotes"], LAYERS_OK),
    ("layers-unclosed-quote", {"layers": '"films/a.csv 100'}, ["layers", "unclosed quote", "goes in quotes"],
     LAYERS_OK),
    ("layers-empty-layer", {"layers": "1.46 100;; 2.0 50"}, ["layers[1]", "empty layer"],
     LAYERS_OK),
    ("layers-and-shorthand", {"layers": "1.46 100", "thin_film_ior": 1.4,
                              "thin_film_thickness": 5.0},
     ["'layers'", "'thin_film_ior'", "not both"], LAYERS_OK),
    ("shorthand-without-thickness", {"thin_film_ior": 1.4}, ["'thin_film_thickness'", "missing"],
     SHORTHAND_OK),
    # k < 0 (gain) wherever an index is given
    ("layers-negative-k", {"layers": "1.5-0.2j 100"}, ["layers[0]", "k", "-0.2"], LAYERS_OK),
    ("shorthand-negative-k", {"thin_film_ior": "1.5-0.2j", "thin_film_thickness": 10.0},
     ["thin_film_ior", "k", "-0.2"], SHORTHAND_OK),
    ("material-negative-k", {"material": "0.2-3j"}, ["material", "k", "-3"],
     {"material": "0.2+3j"}),
    ("k-negative-float", {"eta": 0.2, "k": -2.0}, ["'k'", "-2.0"], {"eta": 0.2, "k": 3.0}),
    ("k-negative-spectrum", {"eta": 0.2, "k": {"type": "uniform", "value": -2.0}},
     ["'k'", "-2.0"], {"eta": 0.2, "k": 3.0}),
    ("eta-non-positive-float", {"eta": 0.0, "k": 2.0}, ["'eta'", "0.0"], {"eta": 0.2, "k": 3.0}),
    # a spectrum over 400-700 nm only is 0 elsewhere: refused, saying what it covers (issue 39)
    ("eta-spectrum-not-covering", {"eta": {"type": "irregular", "wavelengths": "400, 550, 700",
                                           "values": "0.3, 0.2, 0.1"}, "k": 3.0},
     ["'eta'", "400-700 nm", "does not cover", "360-830 nm"], {"eta": 0.2, "k": 3.0}),
    ("k-spectrum-not-covering", {"eta": 0.2, "k": {"type": "irregular", "wavelengths": "400, 550, 700",
                                                   "values": "0.1, 0.3, 0.2"}},
     ["'k'", "400-700 nm", "does not cover", "360-830 nm"], {"eta": 0.2, "k": 3.0}),
    ("eta-negative-spectrum", {"eta": {"type": "uniform", "value": -1.5}, "k": 2.0},
     ["'eta'", "-1.5"], {"eta": 0.2, "k": 3.0}),
    ("eta-nan", {"eta": float("nan"), "k": 2.0}, ["'eta'", "nan"], {"eta": 0.2, "k": 3.0}),
    # absorbing or non-positive ext_ior
    ("ext_ior-absorbing-number", {"ext_ior": "1.2+0.1j"}, ["ext_ior", "(1.2+0.1j)"],
     {"ext_ior": 1.33}),
    ("ext_ior-absorbing-material", {"ext_ior": "Au"}, ["ext_ior", "'Au'", "non-absorbing"],
     {"ext_ior": 1.33}),
    ("ext_ior-negative", {"ext_ior": -1.0}, ["ext_ior", "-1.0"], {"ext_ior": 1.33}),
    ("ext_ior-zero", {"ext_ior": 0.0}, ["ext_ior", "0.0"], {"ext_ior": 1.33}),
    ("ext_ior-nan", {"ext_ior": float("nan")}, ["ext_ior", "nan"], {"ext_ior": 1.33}),
    # int_ior must be a real, positive index
    ("int_ior-complex", {"int_ior": "1.5+0.01j"}, ["int_ior", "(1.5+0.01j)"], {"int_ior": 1.6}),
    ("int_ior-metal", {"int_ior": "Au"}, ["int_ior", "'Au'", "non-absorbing"], {"int_ior": 1.6}),
    ("int_ior-negative", {"int_ior": -1.5}, ["int_ior", "-1.5"], {"int_ior": 1.6}),
    ("int_ior-zero", {"int_ior": 0.0}, ["int_ior", "0.0"], {"int_ior": 1.6}),
    # both ways of giving the substrate
    ("material-and-eta-k", {"material": "Au", "eta": 1.0, "k": 2.0},
     ["'material'", "'Au'", "'eta'", "not both"], {"material": "Au"}),
    ("eta-without-k", {"eta": 1.0}, ["'eta'", "'k'", "together"], {"eta": 0.2, "k": 3.0}),
    # unreferenced / misspelled parameters, named with their values as Mitsuba does
    ("misspelled-layers", {"layrs": "1.4 10"}, ["unreferenced propert", "'layrs'", "'1.4 10'"],
     {}),
    ("misspelled-ext_ior", {"ext_iorr": 1.5}, ["unreferenced propert", "'ext_iorr'", "1.5"], {}),
    ("two-unreferenced", {"layers": "1.4 10", "thicknes": 2.0, "colour": "red"},
     ["unreferenced properties", "'thicknes'", "2.0", "'colour'", "'red'"], {}),
    # the `thickness` scale texture must not go below 0
    ("thickness-negative-number", {"thickness": -1.0}, ["'thickness'", "-1.0"],
     {"thickness": 0.5}),
    ("thickness-nan", {"thickness": float("nan")}, ["'thickness'", "nan"], {"thickness": 0.5}),
    ("thickness-negative-uniform", {"thickness": {"type": "uniform", "value": -2.0}},
     ["'thickness'", "-2.0"], {"thickness": 0.5}),
    ("thickness-negative-checkerboard",
     {"thickness": {"type": "checkerboard", "color0": -0.25, "color1": 1.0}},
     ["'thickness'", "-0.25"], {"thickness": 0.5}),
    # non-finite or out-of-range values that used to load and render black or NaN
    ("eta-inf", {"eta": float("inf"), "k": 2.0}, ["'eta'", "inf"], {"eta": 0.2, "k": 3.0}),
    ("k-inf", {"eta": 0.2, "k": float("inf")}, ["'k'", "inf"], {"eta": 0.2, "k": 3.0}),
    ("k-nan-spectrum", {"eta": 0.2, "k": {"type": "uniform", "value": float("nan")}},
     ["'k'", "nan"], {"eta": 0.2, "k": 3.0}),
    ("eta-huge", {"eta": 1e10, "k": 0.0}, ["'eta'", "10000000000.0", "1000"],
     {"eta": 0.2, "k": 3.0}),
    ("specular_reflectance-inf", {"specular_reflectance": float("inf")},
     ["'specular_reflectance'", "inf"], {"specular_reflectance": 0.9}),
    ("specular_reflectance-nan", {"specular_reflectance": float("nan")},
     ["'specular_reflectance'", "nan"], {"specular_reflectance": 0.9}),
    ("specular_reflectance-negative", {"specular_reflectance": -0.5},
     ["'specular_reflectance'", "-0.5"], {"specular_reflectance": 0.9}),
    ("specular_reflectance-negative-spectrum",
     {"specular_reflectance": {"type": "uniform", "value": -0.25}},
     ["'specular_reflectance'", "-0.25"], {"specular_reflectance": 0.9}),
    ("specular_transmittance-inf", {"specular_transmittance": float("inf")},
     ["'specular_transmittance'", "inf"], {"specular_transmittance": 0.9}),
    ("specular_transmittance-negative", {"specular_transmittance": -1.0},
     ["'specular_transmittance'", "-1.0"], {"specular_transmittance": 0.9}),
    ("thickness-inf", {"thickness": float("inf")}, ["'thickness'", "inf"], {"thickness": 0.5}),
    ("thickness-inf-uniform", {"thickness": {"type": "uniform", "value": float("inf")}},
     ["'thickness'", "inf"], {"thickness": 0.5}),
    ("int_ior-huge", {"int_ior": 1e30}, ["int_ior", "1e+30", "1000"], {"int_ior": 1.6}),
    ("ext_ior-huge", {"ext_ior": 1e30}, ["ext_ior", "1e+30", "1000"], {"ext_ior": 1.33}),
    ("ext_ior-inf", {"ext_ior": float("inf")}, ["ext_ior", "inf"], {"ext_ior": 1.33}),
    ("layers-huge-k", {"layers": "1.5+1e10j 100"}, ["layers[0]", "10000000000j", "1000"], LAYERS_OK),
    ("layers-tiny-n", {"layers": "1e-12 100"}, ["layers[0]", "1e-12", "0.001"], LAYERS_OK),
    ("shorthand-huge-n", {"thin_film_ior": 1e10, "thin_film_thickness": 10.0},
     ["thin_film_ior", "10000000000"], SHORTHAND_OK),
    ("alpha-huge", {"alpha": 1e30}, ["'alpha'", "1e+30", "100"], {"alpha": 0.2}),
    ("alpha-inf", {"alpha": float("inf")}, ["'alpha'", "inf"], {"alpha": 0.2}),
    ("alpha-negative-texture", {"alpha": {"type": "uniform", "value": -0.1}},
     ["'alpha'", "-0.1"], {"alpha": 0.2}),
    ("too-many-films", {"layers": "; ".join(["1.5 10"] * 1001)},
     ["layers", "1001 films", "at most 1000"], LAYERS_OK),
]


def _params(cases):
    """The (plugin, case, front end) combinations where the plugin takes the parameter;
    decided at collection time, so the matrix holds no skips but for plugins whose
    module does not import yet."""
    mi.set_variant(VARIANT)
    out = []
    for plugin in PLUGINS:
        why = import_error(plugin, VARIANT)
        if why:
            out.append(pytest.param(plugin, {}, [], {}, "dict", id=f"{plugin}-not-importable",
                                    marks=pytest.mark.skip(reason=why)))
            continue
        for case in cases:
            if case[3] and not takes(plugin, case[3]):
                continue
            for how in HOW:
                out.append(pytest.param(plugin, *case[1:], how, id=f"{plugin}-{case[0]}-{how}"))
    return out


def _skip_unless_takes(plugin: str, valid: dict) -> None:
    why = import_error(plugin, VARIANT)
    if why:
        pytest.skip(why)
    if valid and not takes(plugin, valid):
        pytest.skip(f"{plugin} does not take {sorted(valid)} (reports it as unreferenced)")


@pytest.mark.parametrize("plugin, props, needles, valid, how", _params(CASES))
def test_bad_parameter_raises_and_process_stays_usable(plugin, props, needles, valid, how):
    _skip_unless_takes(plugin, valid)
    check_raises(plugin, props, how, needles)


def test_mitsuba_reports_its_own_unreferenced_properties_alike():
    """Our report of a misspelled parameter carries what Mitsuba's does for its own
    plugins: the words 'unreferenced property', the plugin, the name and the value."""
    with pytest.raises(Exception) as theirs:
        mi.load_dict({"type": "conductor", "materal": "Au"})
    with pytest.raises(Exception) as ours:
        mi.load_dict({"type": "thinfilm_conductor", "materal": "Au"})
    for text, plugin in ((str(theirs.value), "conductor"), (str(ours.value), "thinfilm_conductor")):
        assert "unreferenced property" in text and plugin in text
        assert "materal" in text and "Au" in text
    still_works("thinfilm_conductor")


# ---------------------------------------------------------------------------
# Datasets that do not cover Mitsuba's spectral range
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def narrow_files(tmp_path_factory):
    """A csv (nm) and a refractiveindex.info yml (um) material covering 400-700 nm only."""
    d = tmp_path_factory.mktemp("narrow")
    csv = d / "narrow_glass.csv"
    csv.write_text("wavelength,n,k\n" + "".join(f"{w},{1.5 + 1e-4 * (w - 400)},0\n"
                                                for w in range(400, 701, 10)))
    yml = d / "narrow_metal.yml"
    yml.write_text("DATA:\n  - type: tabulated nk\n    data: |\n"
                   "        0.40 0.5 3.0\n        0.55 0.4 3.5\n        0.70 0.3 4.0\n")
    return {"csv": str(csv), "yml": str(yml)}


NARROW = [  # (id, props from the file path, valid props)
    ("layers", lambda f: {"layers": f"1.46 100; {f} 20"}, ["layers[1]"], LAYERS_OK),
    ("thin_film_ior", lambda f: {"thin_film_ior": f, "thin_film_thickness": 20.0},
     ["thin_film_ior"], SHORTHAND_OK),
    ("material", lambda f: {"material": f}, ["material"], {"material": "Au"}),
    ("ext_ior", lambda f: {"ext_ior": f}, ["ext_ior"], {"ext_ior": 1.33}),
    ("int_ior", lambda f: {"int_ior": f}, ["int_ior"], {"int_ior": 1.6}),
]


def _narrow_params():
    out = []
    for p in _params(NARROW):
        plugin, make, needles, valid, how = p.values
        for fmt in ("csv", "yml"):
            out.append(pytest.param(plugin, make, needles, valid, fmt, how,
                                    id=p.id.replace("-dict", f"-{fmt}-dict").replace(
                                        "-xml", f"-{fmt}-xml"), marks=p.marks))
    return out


@pytest.mark.parametrize("plugin, make, needles, valid, fmt, how", _narrow_params())
def test_dataset_not_covering_360_830_is_refused(plugin, make, needles, valid, fmt, how,
                                                 narrow_files):
    _skip_unless_takes(plugin, valid)
    path = narrow_files[fmt]
    check_raises(plugin, make(path), how, [*needles, path, "400-700 nm", "360-830"])


@pytest.mark.parametrize("how", HOW)
def test_a_quoted_path_with_a_semicolon_and_a_space_loads_as_the_same_file(tmp_path, how):
    """issue 39: ``layers`` quotes a material path that holds ';' or white space."""
    plain = tmp_path / "glass.csv"
    plain.write_text("360,1.7,0\n830,1.6,0\n")
    odd = tmp_path / "my films" / "a;b.csv"
    odd.parent.mkdir()
    odd.write_text(plain.read_text())
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(0.6, 0.0, 0.8)
    si.wavelengths = mi.UnpolarizedSpectrum(450.0, 520.0, 600.0, 700.0)
    wo = mi.Vector3f(-0.6, 0.0, 0.8)
    values = []
    for layers in (f"SiO2 80; {plain} 120", f'SiO2 80; "{odd}" 120', f"SiO2 80; '{odd}' 120"):
        if how == "dict":
            bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "tabulate": "false"})
        else:   # the plugin alone, as a scene's <bsdf> element writes it
            bsdf = mi.load_string(f'<bsdf version="3.0.0" type="thinfilm_conductor">'
                                  f'{_xml_value("layers", layers)}{_xml_value("tabulate", "false")}</bsdf>')
        values.append(np.array(bsdf.eval(mi.BSDFContext(), si, wo)))
    np.testing.assert_array_equal(values[1], values[0])   # the same file, read the same way
    np.testing.assert_array_equal(values[2], values[0])


# ---------------------------------------------------------------------------
# Extreme but valid thicknesses: finite, lit images at load and through edits
# ---------------------------------------------------------------------------
#: Film thicknesses (nm) valid however extreme: a film dropped, one far below a
#: wavelength, and ones whose phase no float holds (beyond coherence_thickness: averaged
#: incoherently).
EXTREME = [0.0, 1e-9, 1e9, 1e30]
#: The stack of each plugin, its first film's thickness varied. The reflective plugins take
#: the stack that rendered NaN from thinfilm_diffuse's factor table; the transmissive ones a
#: first film above their substrate's index (a lossless incoherent film of an index below
#: it puts a kink in T, at its critical angle, which tabulate=true's build does not resolve
#: within its budget: ~5-9 s, then a warning and the exact path; not what is tested here).
TRANSMISSIVE = ("thinfilm_dielectric", "thinfilm_roughdielectric", "thinfilm_coating")


def extreme_layers(plugin: str, thickness: float) -> str:
    return f"{'2.0' if plugin in TRANSMISSIVE else '1.46'} {thickness!r}; 0.4+2.5j 5"


#: Per variant family, the (plugin, tabulate) columns that reach every table kind: the
#: exact path (false), the stack's table (true: cubic or bilinear in spectral variants, of
#: the Mueller components in polarized ones), thinfilm_diffuse's factor table (spectral JIT
#: variants: "auto" without the coating's table, true with it), and the colour tables of
#: RGB variants (built whatever ``tabulate`` says).
EXTREME_COLUMNS = {
    "scalar_spectral": [(p, t) for p in PLUGINS for t in (False, True)],
    "llvm_ad_rgb": [(p, "auto") for p in PLUGINS],
    "llvm_ad_spectral": [(p, t) for p in PLUGINS for t in (False, True)]
    + [("thinfilm_diffuse", "auto")],
    # every exact path, and the Mueller tables of a reflecting, a transmitting and the
    # coated-diffuse stack (the rough plugins' and the coating's are the same tables read
    # at other angles, and each polarized BSDF costs ~1-3 s of kernel compilation)
    "llvm_ad_spectral_polarized": [(p, False) for p in PLUGINS]
    + [(p, True) for p in ("thinfilm_conductor", "thinfilm_dielectric", "thinfilm_diffuse")],
}
#: Per variant family, the thicknesses of its rows: every one of :data:`EXTREME`, but in
#: polarized variants those beyond ``coherence_thickness`` alone, where their own code
#: parts from the spectral variants' (the Mueller tables average the film incoherently, the
#: exact amplitudes keep it coherent); 0 and 1e-9 nm reach the stack's planning they share
#: with the spectral variants, and a polarized kernel costs ~1 s of compilation per BSDF.
EXTREME_ROWS = {variant: [d for d in EXTREME if d > 1.0 or not variant.endswith("_polarized")]
                for variant in EXTREME_COLUMNS}
#: Pixels per side of a sphere's tile (orthographic: every pixel hits its own sphere).
TILE = 4
#: A tile's mean below this is black: the constant emitter's radiance is 1, and the least
#: of the tiles' means measured in every variant of the matrix is 0.17 (thinfilm_coating
#: over its Lambertian base; the median 0.5).
LIT = 0.05


def extreme_scene(columns, thicknesses) -> dict:
    """A sphere per (column, thickness) on a grid, column ``i`` and row ``j`` of the
    image being the tile of shape ``s{i}_{j}``, under a constant emitter, at 1 spp
    with a box filter (deterministic: two renders of one state are equal bit for bit)."""
    w, h = len(columns), len(thicknesses)
    scene = {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
             "sensor": {"type": "orthographic",
                        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 10], target=[0, 0, 0],
                                                                   up=[0, 1, 0])
                        @ mi.ScalarTransform4f().scale([w, w, 1]),
                        "film": {"type": "hdrfilm", "width": TILE * w, "height": TILE * h,
                                 "rfilter": {"type": "box"}},
                        "sampler": {"type": "independent", "sample_count": 1}},
             "light": {"type": "constant"}}
    for i, (plugin, tabulate) in enumerate(columns):
        for j, d in enumerate(thicknesses):
            scene[f"s{i}_{j}"] = {"type": "sphere", "center": [1 - w + 2 * i, h - 1 - 2 * j, 0],
                                  "radius": 1.414, "bsdf": plugin_dict(
                                      plugin, layers=extreme_layers(plugin, d), tabulate=tabulate)}
    return scene


def lit_tiles(scene, columns, thicknesses, what: str) -> np.ndarray:
    """The render's tiles ``(row, column, pixels)``, asserted finite and lit, each
    failing tile named by its plugin, ``tabulate`` and thickness."""
    h, w = len(thicknesses), len(columns)
    tiles = np.array(mi.render(scene)).reshape(h, TILE, w, TILE, -1).transpose(0, 2, 1, 3, 4)
    tiles = tiles.reshape(h, w, -1)
    bad = [f"{columns[i]} at {thicknesses[j]:g} nm: "
           f"{'non-finite' if not np.all(np.isfinite(tiles[j, i])) else 'black'}"
           for j in range(h) for i in range(w)
           if not (np.all(np.isfinite(tiles[j, i])) and tiles[j, i].mean() > LIT)]
    assert not bad, f"{what}: " + "; ".join(bad)
    return tiles


def table_kinds(bsdf) -> set:
    """What serves a BSDF's stack: ``"table"`` (a side's table of R, T or the Mueller
    components), ``"colour"``, ``"factors"`` (thinfilm_diffuse's factor table), ``"exact"``."""
    coated = getattr(bsdf, "coated", None)       # thinfilm_diffuse
    if coated is not None:
        stack = coated.coating
    else:                                        # thinfilm_coating's, or the plugin's own
        stack = bsdf.coating.stack if hasattr(bsdf, "coating") else bsdf.stack
    kinds = {"table" if s.table is not None else "colour" if getattr(s, "colour", None) is not None
             else "exact" for s in stack.plan.values() if s.films}
    if coated is not None and coated.table is not None:
        kinds.add("factors")
    return kinds


def expected_kinds(variant: str, plugin: str, tabulate) -> set:
    """What :func:`table_kinds` finds in a column of :data:`EXTREME_COLUMNS`, at every
    thickness: the matrix reaches the kinds it is for."""
    if variant.endswith("_rgb"):
        return {"colour"}
    kinds = {"table" if tabulate is True else "exact"}
    if plugin == "thinfilm_diffuse" and tabulate and not variant.startswith("scalar"):
        kinds.add("factors")
    return kinds


#: The edit of every row: the film's thickness swapped within the pairs (0, 1e-9) and
#: (1e9, 1e30), so that each value is reached through an edit from another.
SWAPPED = {0.0: 1e-9, 1e-9: 0.0, 1e9: 1e30, 1e30: 1e9}


@pytest.mark.slow
@pytest.mark.parametrize("variant", sorted(EXTREME_COLUMNS))
def test_extreme_thicknesses_render_finite_and_lit_at_load_and_through_edits(variant):
    """Every plugin and table kind, its first film 0, 1e-9, 1e9 and 1e30 nm thick
    (:data:`EXTREME_ROWS`), renders finite and lit tiles, loaded so and after a
    ``mi.traverse(scene)`` edit that swaps the thicknesses (:data:`SWAPPED`); edited back,
    the scene renders its loaded image bit for bit. A lossless film beyond
    ``coherence_thickness`` is averaged incoherently, so the tiles of 1e9 and of 1e30 nm are
    one BSDF's: the row loaded at 1e9 nm and edited to 1e30 renders as loaded (to the
    rounding its neighbours' 0 <-> 1e-9 nm swap sends over), but in polarized variants,
    whose exact path keeps such a film coherent in float32. (The factor table rendered 1647
    of 1728 values NaN at 1e30 nm, without it R_dh and T_hemi fell silently to 0; a
    polarized Mueller table took 62 s and 12 GB to fail.) Scalar variants cannot write a
    Python BSDF's float through ``mi.traverse`` (Mitsuba's "not a nanobind type"): loads
    only."""
    mi.set_variant(variant)
    columns, extreme = EXTREME_COLUMNS[variant], EXTREME_ROWS[variant]
    scene = mi.load_dict(extreme_scene(columns, extreme))
    gc.collect()   # a render traces every live BSDF instance: none of other scenes left
    loaded = lit_tiles(scene, columns, extreme, "loaded")
    bsdfs = {shape.id(): shape.bsdf() for shape in scene.shapes()}
    for i, (plugin, tabulate) in enumerate(columns):
        for j, d in enumerate(extreme):
            assert table_kinds(bsdfs[f"s{i}_{j}"]) == expected_kinds(variant, plugin, tabulate), \
                (plugin, tabulate, d)
    if variant.startswith("scalar"):
        return
    params = mi.traverse(scene)
    for rows in ([SWAPPED[d] for d in extreme], extreme):
        for i in range(len(columns)):
            for j, d in enumerate(rows):
                params[f"s{i}_{j}.bsdf.layers.0.thickness"] = d
        params.update()
        tiles = lit_tiles(scene, columns, rows, f"edited to {rows} nm")
        if rows != extreme and not variant.endswith("_polarized"):
            j = extreme.index(1e9)
            # (float32 rounding of the light the 0/1e-9 nm neighbours reflect onto it)
            np.testing.assert_allclose(tiles[j], loaded[j], rtol=1e-4, atol=1e-6,
                                       err_msg=f"1e9 -> 1e30 nm, columns {columns}")
    np.testing.assert_array_equal(tiles, loaded)


# ---------------------------------------------------------------------------
# Unsupported variants
# ---------------------------------------------------------------------------
# RGB and mono variants are supported (colour tables, issue 19); polarized ones
# need wavelengths.
UNSUPPORTED = [v for v in ("llvm_ad_mono_polarized",)
               if v in mi.variants()]


@pytest.mark.parametrize("variant", UNSUPPORTED)
def test_unsupported_variant_is_refused_at_load(variant):
    """Every plugin, through both front ends (one variant switch per variant: a switch
    re-registers every plugin and costs ~0.5 s)."""
    plugins = [p for p in PLUGINS if import_error(p, VARIANT) is None]
    assert plugins
    mi.set_variant(variant)
    try:
        for plugin in plugins:
            for how in HOW:
                with pytest.raises(Exception) as err:
                    load(plugin, {"layers": "1.46 100"}, how)
                text = str(err.value)
                assert plugin in text and repr(variant) in text and "not supported" in text, text
                assert "_spectral" in text  # says what to use instead
    finally:
        mi.set_variant(VARIANT)
    for plugin in plugins:
        still_works(plugin)


# ---------------------------------------------------------------------------
# An LLVM that would abort the process: a clear error at scene load instead
# ---------------------------------------------------------------------------
from tests.support import LLVM15  # the same library as the numpy-API test in tests/test_llvm.py

_LLVM15_SCRIPT = r"""
import json
import sys
import mitsuba as mi
import thinfilm_mi
mi.set_variant("llvm_ad_spectral")
# every plugin as a dict and as XML, built by the test (load(), to_xml()): argv[1]
for plugin, (as_dict, as_xml) in json.loads(sys.argv[1]).items():
    for how in ("dict", "xml"):
        try:
            mi.load_dict(as_dict) if how == "dict" else mi.load_string(as_xml)
        except Exception as e:
            print("REFUSED", plugin, how, "LLVMVersionError" in str(e) and "15." in str(e)
                  and "libllvm19" in str(e) and "DRJIT_LIBLLVM_PATH" in str(e))
        else:
            print("LOADED", plugin, how)
# the process is still usable: a scalar variant needs no LLVM
mi.set_variant("scalar_spectral")
b = mi.load_dict({"type": "thinfilm_conductor", "material": "2+3j"})
si = mi.SurfaceInteraction3f()
si.wavelengths = mi.Spectrum(400.0, 500.0, 600.0, 700.0)
si.wi = mi.Vector3f(0.0, 0.0, 1.0)
bs, w = b.sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.5, 0.5))
print("SCALAR OK", all(0.0 < float(w[i]) < 1.0 for i in range(4)))
"""


@pytest.mark.skipif(not os.path.exists(LLVM15), reason="no libLLVM-15 on this machine")
def test_llvm15_refuses_every_plugin_at_scene_load_without_abort():
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=LLVM15)
    valid = {"layers": "1.46 100"}
    loads = {p: [plugin_dict(p, **valid), to_xml(p, valid)] for p in PLUGINS}
    proc = subprocess.run([sys.executable, "-c", _LLVM15_SCRIPT, json.dumps(loads)], env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-3000:])  # no abort, no signal
    lines = proc.stdout.splitlines()
    refused = [l for l in lines if l.startswith("REFUSED")]
    assert not [l for l in lines if l.startswith("LOADED")], proc.stdout
    assert len(refused) == 2 * len(PLUGINS), proc.stdout  # every plugin, both front ends
    assert all(l.endswith("True") for l in refused), proc.stdout
    assert "SCALAR OK True" in lines, proc.stdout + proc.stderr[-2000:]
