"""The tabulation layer: verified tables that replace the recursion in render kernels.

The shared base, used by every builder:

* :mod:`thinfilm_mi.tabulate.base` -- a lit side of a stack (:class:`SideData`) and its
  exact float64 evaluation in batches, the cubic tables' angle and wavelength axes,
  B-splines and their midpoint prediction, the :class:`Table` lookup, :class:`BuildReport`
  and the :class:`TableCache`.
* :mod:`thinfilm_mi.tabulate.store` -- built tables kept on disk between processes (the
  table store, ``THINFILM_MI_TABLE_CACHE``).
* :mod:`thinfilm_mi.tabulate.refine` -- the :class:`~thinfilm_mi.tabulate.refine.Budget` a
  build may spend, the first sample step from the stack's optical thickness, the
  convergence-order refinement of the cubic tables, and the 4-point rule and angle axis
  of the linear (colour and diffuse) tables.

The builders on top:

* :mod:`thinfilm_mi.tabulate.exact` -- cubic B-spline tables of the exact ``R``/``T`` over
  (angle, wavelength), their verification, and the table cache.
* :mod:`thinfilm_mi.tabulate.band` -- tables of ``R``/``T`` convolved with a Gaussian in
  wavenumber (deep stacks), on a sheared axis (:mod:`thinfilm_mi.tabulate.shear`), from
  rows (:mod:`thinfilm_mi.tabulate.band_rows`) sampled through the stack's smooth
  amplitudes (:mod:`thinfilm_mi.tabulate.band_amplitudes`).
* :mod:`thinfilm_mi.tabulate.colour` -- colour tables: ``R``/``T`` integrated against colour
  matching over the angle (RGB and mono variants).
* :mod:`thinfilm_mi.tabulate.diffuse` -- the coated-diffuse product film-in x base x film-out.
* :mod:`thinfilm_mi.tabulate.hemispherical` -- hemispherical terms ``R_dh``, ``T_hemi``.
"""
from thinfilm_mi.tabulate.band import build_table
from thinfilm_mi.tabulate.base import SideData, Table, TableCache, evaluate_side
from thinfilm_mi.tabulate.colour import ColourTable
from thinfilm_mi.tabulate.hemispherical import hemispherical_factors, r_dh_partials

__all__ = ["ColourTable", "SideData", "Table", "TableCache", "build_table", "evaluate_side",
           "hemispherical_factors", "r_dh_partials"]
