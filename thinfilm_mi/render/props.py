"""The bare-properties form of :class:`~thinfilm_mi.render.reader.PluginProperties`, for
code that still passes a plugin's ``mi.Properties`` and its name around: each function
reads through a reader, inside :func:`~thinfilm_mi.errors.plugin_boundary` of ``plugin``,
so its errors name the plugin, the property and the value as before. A plugin reads its
properties through the reader itself and runs its constructor in the boundary.
"""
from __future__ import annotations

from thinfilm_mi.errors import plugin_boundary
from thinfilm_mi.render.kernel import KernelStack
from thinfilm_mi.render.media import DEFAULT_EXT_IOR, SpectralIndex
from thinfilm_mi.render.reader import MAX_SPECTRAL_RESOLUTION, PluginProperties

__all__ = ["MAX_SPECTRAL_RESOLUTION", "optional_texture", "films_from_props", "tabulate_from_props",
           "stack_from_props", "stack_options_from_props", "ext_ior_from_props", "check_unqueried"]


def optional_texture(props, name: str, plugin: str):
    """:meth:`PluginProperties.factor`: the factor texture ``name``, or ``None``."""
    with plugin_boundary(plugin):
        return PluginProperties(props).factor(name)


def films_from_props(props, plugin: str) -> list[tuple[SpectralIndex, float]]:
    """:meth:`PluginProperties.films`: ``layers`` or the one-film shorthand."""
    with plugin_boundary(plugin):
        return PluginProperties(props).films()


def tabulate_from_props(props, plugin: str) -> bool | str:
    """:meth:`PluginProperties.tabulate`: ``"auto"`` (default), ``true`` or ``false``."""
    with plugin_boundary(plugin):
        return PluginProperties(props).tabulate()


def stack_from_props(props, plugin: str, substrate: SpectralIndex,
                     ambient: SpectralIndex | None = None, *,
                     sides: dict | None = None) -> KernelStack:
    """:meth:`PluginProperties.kernel_stack`: the :class:`KernelStack` of a thin-film BSDF."""
    with plugin_boundary(plugin):
        return PluginProperties(props).kernel_stack(substrate, ambient, sides=sides, plugin=plugin)


def stack_options_from_props(props, plugin: str, thickness_texture: bool = True) -> dict:
    """:meth:`PluginProperties.stack_options`, with ``plugin`` (the stack's name for the
    BSDF)."""
    with plugin_boundary(plugin):
        return dict(PluginProperties(props).stack_options(thickness_texture), plugin=plugin)


def ext_ior_from_props(props) -> SpectralIndex:
    """``ext_ior`` (:meth:`PluginProperties.index`)."""
    return PluginProperties(props).index("ext_ior", DEFAULT_EXT_IOR)


def check_unqueried(props, plugin: str) -> None:
    """:meth:`PluginProperties.check_unqueried`: no property left unread."""
    with plugin_boundary(plugin):
        PluginProperties(props).check_unqueried()
