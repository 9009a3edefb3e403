"""The one reader of a plugin's properties (``render/reader.py``), on bare ``mi.Properties``.

Each getter gives the typed value or refuses a bad one with an error naming the property
and the value, and never the plugin (the plugin boundary adds it: ``tests/test_errors.py``);
the unqueried check sees exactly what no getter read. Through the plugins, every bad input
is covered by ``tests/cross/test_bad_input.py``.
"""
from __future__ import annotations

import math

import mitsuba as mi
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins)
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.choices import choose
from thinfilm_mi.render.orennayar import ROUGHNESS_MODELS
from thinfilm_mi.render.reader import PluginProperties, finite_number


@pytest.fixture(autouse=True)
def _spectral(llvm):
    """Every test reads in ``llvm_ad_spectral`` (textures need a variant)."""


def reader(**values) -> PluginProperties:
    props = mi.Properties("thinfilm_conductor")
    for k, v in values.items():
        props[k] = v
    return PluginProperties(props)


@pytest.mark.parametrize("value", [-1.0, 0.0, math.nan, math.inf, 0.75, "0.1", True])
def test_number_refuses_what_is_not_a_finite_number_in_range(value):
    read = reader(table_error=value)
    with pytest.raises(ThinFilmError) as err:
        read.number("table_error", 1e-3, 0.0, 0.5, strict=True)
    assert str(err.value) == f"'table_error' must be a finite number > 0 and <= 0.5, got {value!r}"


def test_number_default_bounds_and_required():
    assert reader().number("table_error", 1e-3, 0.0, 0.5, strict=True) == 1e-3
    assert reader(scale=0.0).number("scale", 1.0, 0.0) == 0.0      # lo is in without strict
    assert reader(table_error=0.5).number("table_error", 1e-3, 0.0, 0.5, strict=True) == 0.5
    with pytest.raises(ThinFilmError, match=r"^'temperature' is required \(in kelvin\)$"):
        reader().number("temperature", required="in kelvin")
    # the same check at an edit: no bound written where there is none
    with pytest.raises(ThinFilmError, match=r"^'x' must be a finite number \(K\), got nan$"):
        finite_number("'x'", math.nan, unit=" (K)")


def test_integer_boolean_and_choice():
    assert reader(max_bounces=3).integer("max_bounces", 64, 1) == 3
    for bad in (0, 2.0, True):
        with pytest.raises(ThinFilmError, match=rf"^'max_bounces' must be an integer >= 1, got {bad!r}$"):
            reader(max_bounces=bad).integer("max_bounces", 64, 1)
    assert reader().boolean("sample_visible", True) is True
    with pytest.raises(ThinFilmError, match=r"^'sample_visible' must be a boolean, got 1.0$"):
        reader(sample_visible=1.0).boolean("sample_visible", True)
    # a registry's first entry is the default; a wrong name is told as choose() tells it
    assert reader().choice("roughness_model", ROUGHNESS_MODELS) is next(iter(ROUGHNESS_MODELS.values()))
    assert reader(roughness_model=" EON ").choice("roughness_model", ROUGHNESS_MODELS).name == "eon"
    with pytest.raises(ThinFilmError) as err:
        reader(roughness_model="fujii").choice("roughness_model", ROUGHNESS_MODELS)
    with pytest.raises(ThinFilmError) as theirs:
        choose(ROUGHNESS_MODELS, "fujii", "'roughness_model'")
    assert str(err.value) == str(theirs.value)


def test_texture_number_texture_and_type_checks():
    read = reader(alpha=0.2, thickness=-0.5, eta="Au", k=mi.load_dict({"type": "uniform", "value": 2.0}))
    tex = read.texture("alpha", "a number > 0 or a texture", lo=0.0, strict=True, uniform_number=True)
    assert tex.class_name() == "UniformSpectrum" and float(mi.traverse(tex)["value"][0]) == pytest.approx(0.2)
    with pytest.raises(ThinFilmError, match=r"^'thickness' \(a scale\) must be a finite number >= 0 or a "
                                            r"texture, got -0.5 \(hint\)$"):
        read.texture("thickness", "a number or a texture", "'thickness' (a scale)", 0.0, hint=" (hint)")
    with pytest.raises(ThinFilmError, match=r"^'eta' must be a number or a texture, got 'Au'$"):
        read.texture("eta", "a number or a texture")
    # a texture's values are checked over its domain, the message naming it as `what` says
    with pytest.raises(ThinFilmError, match=r"^'k' must be finite and >= 3 everywhere, got a texture "
                                            r"with values in \[2.0, 2.0\]$"):
        read.texture("k", "a texture", lo=3.0)


def test_factor_is_none_when_absent_and_never_negative():
    assert reader().factor("specular_reflectance") is None
    with pytest.raises(ThinFilmError, match=r"^'specular_reflectance' must be a finite number >= 0 or a "
                                            r"texture, got -0.5$"):
        reader(specular_reflectance=-0.5).factor("specular_reflectance")


def test_substrate_films_and_stack_options():
    read = reader(eta=0.2, k=3.0, layers="1.46 100; 0.4+2.5j 20", table_error=0.01)
    assert read.substrate().label == "eta/k"
    films = read.films()
    assert [d for _, d in films] == [100.0, 20.0] and films[1][0].label == "0.4+2.5j"
    with pytest.raises(ThinFilmError, match=r"^layers\[1\] material: .*-2"):
        reader(layers="1.46 100; 0.4-2j 20").films()
    options = read.stack_options()
    assert options["table_error"] == 0.01 and options["tabulate"] == "auto"
    assert options["thickness_texture"] is None
    with pytest.raises(ThinFilmError, match=r"^give either 'material' \('Au'\) or 'eta' \+ 'k', not both$"):
        reader(material="Au", eta=0.2, k=3.0).substrate()
    with pytest.raises(ThinFilmError, match=r"^'thin_film_ior' is missing"):
        reader(thin_film_thickness=10.0).films()


def test_unqueried_sees_exactly_what_no_getter_read():
    read = reader(layers="1.46 100", colour="red", thicknes=2.0)
    read.films()
    with pytest.raises(ThinFilmError) as err:
        read.check_unqueried()
    text = str(err.value)
    assert text.startswith("unreferenced properties ") and "'colour' = 'red'" in text
    assert "'thicknes' = 2.0" in text and "layers" not in text
    read.value("colour")
    read.value("thicknes")
    read.check_unqueried()   # all read now


def test_stack_spec_parses_and_builds_nothing():
    from thinfilm_mi.render.kernel import KernelStack, StackSpec, build_stack
    read = reader(layers="1.46 100", ext_ior=1.33, int_ior="water", tabulate=False)
    interior, ambient = read.indices(("int_ior", 1.5), ("ext_ior", 1.0))
    assert (interior.label, ambient.mean_real()) == ("water", pytest.approx(1.33))
    spec = read.stack_spec(interior)
    assert isinstance(spec, StackSpec) and not isinstance(spec, KernelStack)
    assert spec.substrate is interior and spec.ambient.mean_real() == pytest.approx(1.33)
    assert [d for _, d in spec.films] == [100.0] and spec.options["tabulate"] is False
    stack = build_stack(spec, plugin="test")
    assert len(stack) == 1 and stack.substrate is interior and stack.plugin == "test"
    with pytest.raises(ThinFilmError, match=r"^ext_ior: must be a finite real index > 0, got -1.0$"):
        reader(ext_ior=-1.0).stack_spec(interior)


@pytest.mark.parametrize("plugin", ["thinfilm_conductor", "thinfilm_roughconductor", "thinfilm_dielectric",
                                    "thinfilm_roughdielectric", "thinfilm_coating", "thinfilm_diffuse"])
def test_a_misspelt_name_is_refused_before_the_stack_is_built(plugin, monkeypatch):
    """Every stack plugin reads all its properties, then builds (tables: seconds)."""
    import importlib
    module = importlib.import_module(f"thinfilm_mi.plugins.{plugin}")

    def build(*args, **kwargs):
        raise AssertionError("built before the properties were checked")
    # the diffuse plugin's stacks are built with its model's parts (render/layered/series.py)
    monkeypatch.setattr(module, "series_parts" if plugin == "thinfilm_diffuse" else "build_stack", build)
    scene = {"type": plugin, "layers": "1.46 100", "tabulat": True}
    if plugin == "thinfilm_coating":
        scene["bsdf"] = {"type": "diffuse"}
    with pytest.raises(Exception, match=r"unreferenced property 'tabulat' = True"):
        mi.load_dict(scene)
