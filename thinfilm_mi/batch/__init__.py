"""The batch layer: loading and rendering a scene, EXR output, sweeps.

* :mod:`thinfilm_mi.batch.scene` -- load a scene file with parameters and size/spp
  overrides, pick and set its variant, render it in passes, write EXR + PNG
  (:func:`render_file`, the library behind ``thinfilm-render``).
* :mod:`thinfilm_mi.batch.exr` -- EXR writing and reading, the PNG preview.
* :mod:`thinfilm_mi.batch.sweeps` -- parameter sweeps on Dask (:func:`thinfilm_mi.sweep`),
  with :mod:`~thinfilm_mi.batch.grid` (axes, frames, tasks),
  :mod:`~thinfilm_mi.batch.worker` (the worker processes),
  :mod:`~thinfilm_mi.batch.keys` (the ``mi.traverse`` key a ``-P`` names) and
  :mod:`~thinfilm_mi.batch.outputs` (frames, manifest, contact sheet). Dask is the
  ``[sweep]`` extra: this package imports it only when a sweep module is imported.

Errors are those of :mod:`thinfilm_mi.errors` (:class:`~thinfilm_mi.errors.UsageError`,
:class:`~thinfilm_mi.errors.RenderFailure`); nothing here exits the process.
"""
from thinfilm_mi.batch.exr import read_exr, write_exr, write_png
from thinfilm_mi.batch.scene import (
    DEFAULT_VARIANT,
    RenderResult,
    load_scene,
    render_file,
    render_scene,
    scene_variant,
    setup_variant,
)

__all__ = [
    "render_file", "render_scene", "load_scene", "RenderResult", "scene_variant", "setup_variant",
    "DEFAULT_VARIANT", "read_exr", "write_exr", "write_png",
]

__all__ = ["RenderResult", "load_scene", "render_file", "render_scene"]
