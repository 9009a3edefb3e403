"""Registration of the thin-film plugins with Mitsuba.

:func:`register` registers every plugin of :mod:`thinfilm_mi.plugins` (the
BSDFs of :data:`PLUGINS` and the textures of :data:`TEXTURES`) for the
current Mitsuba variant and installs a variant callback so that they are
registered again whenever ``mi.set_variant`` switches variant. Plugins are
registered in every variant; in a variant they do not support (RGB, mono)
their constructor raises a clear error at scene load time.
"""
from __future__ import annotations

import importlib

from thinfilm_mi.render import gc_guard

#: plugin name -> (module in thinfilm_mi.plugins, class name)
PLUGINS = {
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


def _register_current() -> list[str]:
    import mitsuba as mi

    if mi.variant() is None:
        return []
    done = []
    for plugins, register_plugin in ((PLUGINS, mi.register_bsdf),
                                     (TEXTURES, mi.register_texture)):
        for name, (module, cls_name) in plugins.items():
            # Modules are imported after the variant is set: their classes derive
            # from the variant's mi.BSDF (mi.Texture), so they are re-imported per variant.
            mod = importlib.import_module(f"thinfilm_mi.plugins.{module}")
            if getattr(mod, "_variant", None) != mi.variant():
                mod = importlib.reload(mod)
                mod._variant = mi.variant()
            cls = getattr(mod, cls_name)
            register_plugin(name, lambda props, cls=cls: cls(props))
            done.append(name)
    return done


def _on_variant_change(old, new) -> None:
    if new is not None:
        _register_current()


def register() -> list[str]:
    """Register the plugins for the current variant (if one is set) and for every
    later variant, and install :mod:`.gc_guard` (no cyclic garbage collection
    while Dr.Jit traces a symbolic call). Returns the names registered now. Safe
    to call repeatedly."""
    global _callback_installed
    import mitsuba as mi

    gc_guard.install()

    if not _callback_installed:
        mi.detail.add_variant_callback(_on_variant_change)
        _callback_installed = True
    return _register_current()
