"""The materials layer: refractive-index data and models, and the float64 ``Stack``.

* :mod:`thinfilm_mi.materials.catalog` -- materials (constants, tables, formulas), their
  sources (shipped data, refractiveindex.info, Mitsuba's presets, user files) and
  :func:`resolve`, which turns a name, number or file into a :class:`Material`.
* :mod:`thinfilm_mi.materials.dispersion` -- refractiveindex.info's dispersion formulas, one
  registry (:data:`~thinfilm_mi.materials.dispersion.FORMULAS`) for material files and the fit.
* :mod:`thinfilm_mi.materials.stack` -- :class:`Stack`: films of materials over a
  substrate, evaluated exactly in float64 (numpy in and out).
"""
from thinfilm_mi.materials.catalog import (
    conductor_spectra,
    list_materials,
    refractive_index,
    resolve,
    save_material,
)
from thinfilm_mi.materials.model import MAX_INDEX, MIN_INDEX, SPECTRAL_RANGE, Material
from thinfilm_mi.materials.stack import Layer, RTResult, Stack, parse_layers

__all__ = ["MAX_INDEX", "MIN_INDEX", "SPECTRAL_RANGE", "Layer", "Material", "RTResult",
           "Stack", "conductor_spectra", "list_materials", "parse_layers", "refractive_index", "resolve",
           "save_material"]
