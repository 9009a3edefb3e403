"""The plugin reference says what the plugins read (issue 41).

Each plugin's page in the documentation site is generated from the doc block that
opens its module (``docs/_ext/thinfilm_plugins.py``; the site itself is built, with
warnings as errors, by ``make docs`` under tests/cross/test_readme_commands.py, which also
checks that every parameter of every doc block is on its page). Here: the set of
properties a doc block's ``.. pluginparameters::`` table lists equals the set of
properties the plugin reads.

"Reads" is measured, not parsed: every ``mi.Properties`` accessor that takes a name
(``get``, ``in``, ``get_texture``, ...) is wrapped to record the name, and the plugin is
loaded in the configurations of :data:`CONFIGS`, which take each branch of its
constructor that reads a property (``eta``/``k`` instead of ``material``, the
anisotropic roughness, ...). A presence test (``"eta" in props``) counts as a read,
so most names are recorded by the default load already. A plugin that iterated over
all its properties (``keys()``, ``items()``) would read names no table can list, and
fails here.
"""
from __future__ import annotations

import sys

import mitsuba as mi
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support import ROOT
from thinfilm_mi.plugins import PLUGINS, TEXTURES  # noqa: E402

REPO = ROOT
sys.path.insert(0, str(REPO / "docs" / "_ext"))
try:
    import thinfilm_plugins as docs_ext  # noqa: E402
finally:
    sys.path.pop(0)

#: plugin -> the property dictionaries it is loaded with (each beside ``type``);
#: together they take every branch of the constructor that reads a property
CONFIGS = {
    "thinfilm_coating": [{"bsdf": {"type": "diffuse"}},
                         {"bsdf": {"type": "diffuse"}, "coat_sigma_a": 0.1, "coat_thickness": 2.0,
                          "max_bounces": 8, "thin_film_ior": 1.46, "thin_film_thickness": 300.0}],
    "thinfilm_conductor": [{}, {"eta": 0.2, "k": 3.0},
                           {"thin_film_ior": 1.46, "thin_film_thickness": 300.0}],
    "thinfilm_dielectric": [{}, {"thin_film_ior": "SiO2", "thin_film_thickness": 300.0}],
    "thinfilm_diffuse": [{}, {"roughness": 0.3, "roughness_model": "eon"},
                         {"model": "multiple", "layers": "SiO2 100; Au 5"},
                         {"base_ior": 1.5, "thin_film_ior": 1.46, "thin_film_thickness": 300.0}],
    "thinfilm_roughconductor": [{}, {"alpha_u": 0.1, "alpha_v": 0.3, "distribution": "ggx"},
                                {"eta": 0.2, "k": 3.0, "alpha": 0.2}],
    "thinfilm_roughdielectric": [{}, {"alpha_u": 0.1, "alpha_v": 0.3, "distribution": "ggx"}],
    "thinfilm_blackbody": [{"temperature": 2856.0},
                           {"temperature": 5000.0, "wavelength_min": 400.0, "wavelength_max": 700.0}],
}

#: mi.Properties methods whose first argument is a property name
NAMED = ("get", "__contains__", "__getitem__", "has_property", "get_texture", "get_unbounded_texture",
         "get_emissive_texture", "mark_queried", "was_queried", "type", "remove_property", "as_string")
#: mi.Properties methods that hand out every property
ALL = ("keys", "items", "property_names")

#: plugin -> why its doc block and its reads differ today (the test then xfails, strictly)
KNOWN_MISMATCHES: dict[str, str] = {}

PLUGIN_PATHS = docs_ext.plugin_files()


@pytest.fixture
def recorded(monkeypatch) -> set[str]:
    """The names every ``mi.Properties`` accessor is asked for while the fixture lives."""
    names: set[str] = set()

    def wrap(method, every):
        def recording(self, *args, **kwargs):
            names.add("*" if every else args[0])
            return method(self, *args, **kwargs)
        return recording

    for name in NAMED + ALL:
        if hasattr(mi.Properties, name):
            monkeypatch.setattr(mi.Properties, name, wrap(getattr(mi.Properties, name), name in ALL))
    return names


def test_every_registered_plugin_has_a_doc_page_and_configurations():
    assert {p.stem for p in PLUGIN_PATHS} == set(PLUGINS) | set(TEXTURES) == set(CONFIGS)


@pytest.mark.parametrize("path", [
    pytest.param(p, marks=pytest.mark.xfail(strict=True, reason=KNOWN_MISMATCHES[p.stem]))
    if p.stem in KNOWN_MISMATCHES else p for p in PLUGIN_PATHS], ids=lambda p: p.stem)
def test_doc_block_lists_exactly_the_properties_the_plugin_reads(path, recorded):
    documented = docs_ext.documented_parameters(docs_ext.doc_block(path))
    assert len(documented) == len(set(documented)), f"{path.stem}: a parameter is listed twice"
    read: set[str] = set()
    for config in CONFIGS[path.stem]:
        recorded.clear()
        mi.load_dict({"type": path.stem, **config})
        read |= recorded
    assert "*" not in read, f"{path.stem} reads all its properties (keys()/items()): list what it reads"
    assert read - set(documented) == set(), f"{path.stem} reads properties its doc block does not list"
    assert set(documented) - read == set(), f"{path.stem}'s doc block lists properties it does not read"


def test_the_recording_sees_presence_tests_and_only_what_is_asked(recorded):
    # the method itself: a name tested with `in` and absent counts ("eta" here), a
    # name the plugin never asks for (a dielectric's "int_ior") is not recorded
    mi.load_dict({"type": "thinfilm_conductor"})
    assert {"material", "eta", "k", "layers"} <= recorded and "int_ior" not in recorded
