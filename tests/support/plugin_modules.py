"""Test helper shared by the files that parametrise over every registered plugin."""
from __future__ import annotations

import importlib

import mitsuba as mi

from thinfilm_mi.plugins import PLUGINS


def import_error(plugin: str, variant: str) -> str | None:
    """``None`` if the plugin's module imports in ``variant``, else why not (a plugin
    being written may not import yet; such a plugin is skipped, with this reason)."""
    module = PLUGINS[plugin][0]
    mi.set_variant(variant)
    try:
        importlib.import_module(f"thinfilm_mi.plugins.{module}")
    except Exception as e:  # noqa: BLE001 - report any import failure as the reason
        return f"{plugin}: module thinfilm_mi.plugins.{module} does not import yet ({e!r})"
    return None


#: What a plugin needs besides its films to load, for the matrices over every plugin:
#: the nested base of ``thinfilm_coating`` (a Lambertian one: the cheapest walk, and
#: every property those matrices check holds for it).
REQUIRED = {"thinfilm_coating": {"bsdf": {"type": "diffuse"}}}


def plugin_dict(plugin: str, **props) -> dict:
    """``{"type": plugin, ...}`` with what the plugin needs to load (:data:`REQUIRED`)
    and ``props``."""
    return {"type": plugin, **REQUIRED.get(plugin, {}), **props}
