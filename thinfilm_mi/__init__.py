"""thinfilm-mi: multilayer thin-film BSDFs for Mitsuba 3.

The library (this package) holds the optics core (:mod:`thinfilm_mi.optics.core`),
materials (:mod:`thinfilm_mi.materials.catalog`) and the public :class:`Stack` API. The
Mitsuba plugins live in :mod:`thinfilm_mi.plugins` and are registered by
:func:`thinfilm_mi.register` (called on import when Mitsuba is importable).
"""
from __future__ import annotations

from thinfilm_mi.errors import MaterialError, ThinFilmError
from thinfilm_mi.llvm import LLVMVersionError, require_llvm
from thinfilm_mi.materials.catalog import refractive_index
from thinfilm_mi.materials.catalog import resolve as resolve_material
from thinfilm_mi.materials.model import Material
from thinfilm_mi.materials.stack import Layer, RTResult, Stack, parse_layers
from thinfilm_mi.plugins import PLUGINS, register
from thinfilm_mi.version import __version__

try:  # Mitsuba is a dependency, but keep the optics usable if its import fails.
    import mitsuba as _mi  # noqa: F401
except ImportError:  # pragma: no cover
    pass
else:
    register()


def __getattr__(name: str):
    """``thinfilm_mi.sweep``: :func:`thinfilm_mi.batch.sweeps.sweep`, and
    ``thinfilm_mi.design``: the coating-design subpackage, imported on first use
    so that importing the package imports neither Dask nor scipy."""
    if name == "sweep":
        from thinfilm_mi.batch.sweeps import sweep

        return sweep
    if name == "design":
        import importlib

        return importlib.import_module(".design", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "__version__", "sweep", "design", "Stack", "Layer", "RTResult", "parse_layers", "Material", "refractive_index",
    "resolve_material", "register", "PLUGINS", "ThinFilmError", "MaterialError", "LLVMVersionError", "require_llvm",
]
