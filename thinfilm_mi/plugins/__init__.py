"""The Mitsuba plugins, one thin file each (its doc block first), and their registration.

A plugin module imports only the layers below (what the plugins share lives in
:mod:`thinfilm_mi.render`, as Mitsuba's BSDFs share ``microfacet.h``), never another
plugin module (``tests/cross/test_architecture.py`` checks both).

:func:`register` registers every plugin of this package (the BSDFs of :data:`PLUGINS`
and the textures of :data:`TEXTURES`) for the current Mitsuba variant and installs a
variant callback so that they are registered again whenever ``mi.set_variant``
switches variant. Plugins are registered in every variant; in a variant one does not
support (polarized RGB or mono) its constructor raises a clear error at scene load time.
"""
from __future__ import annotations

import importlib

from thinfilm_mi.render import gc_guard

__all__ = ["PLUGINS", "TEXTURES", "register"]

#: plugin name -> (module in thinfilm_mi.plugins, class name)
PLUGINS = {
    "thinfilm_coating": ("thinfilm_coating", "ThinFilmCoating"),
    "thinfilm_conductor": ("thinfilm_conductor", "ThinFilmConductor"),
    "thinfilm_dielectric": ("thinfilm_dielectric", "ThinFilmDielectric"),
    "thinfilm_diffuse": ("thinfilm_diffuse", "ThinFilmDiffuse"),
    "thinfilm_roughconductor": ("thinfilm_roughconductor", "ThinFilmRoughConductor"),
    "thinfilm_roughdielectric": ("thinfilm_roughdielectric", "ThinFilmRoughDielectric"),
}

#: texture (and spectrum) plugin name -> (module in thinfilm_mi.plugins, class name);
#: apart from :data:`PLUGINS`, which the tests treat as the list of BSDFs
TEXTURES = {
    "thinfilm_blackbody": ("thinfilm_blackbody", "ThinFilmBlackbody"),
}

_callback_installed = False
#: plugin module name -> the variant :func:`_register_current` last built it for
_built_for: dict[str, str] = {}


def _plugin_modules() -> dict:
    """The plugin modules by name. Imported here, not at the top: a module's classes
    derive from the variant's ``mi.BSDF`` (``mi.Texture``), so it can be imported only
    once a variant is set (and is reloaded per variant by :func:`_register_current`)."""
    from thinfilm_mi.plugins import (
        thinfilm_blackbody,
        thinfilm_coating,
        thinfilm_conductor,
        thinfilm_dielectric,
        thinfilm_diffuse,
        thinfilm_roughconductor,
        thinfilm_roughdielectric,
    )
    modules = (thinfilm_blackbody, thinfilm_coating, thinfilm_conductor, thinfilm_dielectric,
               thinfilm_diffuse, thinfilm_roughconductor, thinfilm_roughdielectric)
    return {m.__name__.rpartition(".")[2]: m for m in modules}


def _register_current() -> list[str]:
    import drjit as dr
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        return []
    modules = _plugin_modules()
    done = []
    for plugins, register_plugin in ((PLUGINS, mi.register_bsdf),
                                     (TEXTURES, mi.register_texture)):
        for name, (module, cls_name) in plugins.items():
            mod = modules[module]
            if _built_for.get(module) != variant:   # built for another variant (or unknown)
                mod = modules[module] = importlib.reload(mod)
                _built_for[module] = variant
            cls = getattr(mod, cls_name)
            if dr.is_jit_v(mi.Float):   # only JIT variants make symbolic calls
                gc_guard.watch_traces(cls)
            register_plugin(name, lambda props, cls=cls: cls(props))
            done.append(name)
    return done


def _on_variant_change(old, new) -> None:
    if new is not None:
        _register_current()


def register() -> list[str]:
    """Register the plugins for the current variant (if one is set) and for every
    later variant, and install :mod:`~thinfilm_mi.render.gc_guard` (no cyclic garbage
    collection, on any thread, while some thread traces our plugins in a symbolic call;
    their traced methods are wrapped to tell it). Returns the names registered now.
    Safe to call repeatedly."""
    global _callback_installed
    import mitsuba as mi

    gc_guard.install()

    if not _callback_installed:
        mi.detail.add_variant_callback(_on_variant_change)
        _callback_installed = True
    return _register_current()
