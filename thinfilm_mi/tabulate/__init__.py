"""The tabulation layer: verified tables that replace the recursion in render kernels.

The shared base, used by every builder:

* :mod:`thinfilm_mi.tabulate.axes` -- the angle axes of the tables (:data:`~thinfilm_mi.tabulate.axes.AXES`:
  plain, split at a critical angle, warped for band-limited tables) and how the ghost
  nodes beyond their ends are made.
* :mod:`thinfilm_mi.tabulate.base` -- a lit side of a stack (:class:`~thinfilm_mi.tabulate.base.SideData`)
  and its exact float64 evaluation in batches, the wavelength axis, B-splines and their
  midpoint prediction, the :class:`~thinfilm_mi.tabulate.base.Table` lookup and how it
  interpolates (:data:`~thinfilm_mi.tabulate.base.INTERPOLATIONS`),
  :class:`~thinfilm_mi.tabulate.base.BuildReport` and the :class:`~thinfilm_mi.tabulate.base.TableCache`.
* :mod:`thinfilm_mi.tabulate.quantities` -- what a table holds
  (:data:`~thinfilm_mi.tabulate.quantities.QUANTITIES`: the powers, or the Mueller
  components of :mod:`thinfilm_mi.tabulate.mueller`).
* :mod:`thinfilm_mi.tabulate.store` -- built tables kept on disk between processes (the
  table store, ``THINFILM_MI_TABLE_CACHE``).
* :mod:`thinfilm_mi.tabulate.refine` -- the :class:`~thinfilm_mi.tabulate.refine.Budget` a
  build may spend, the first sample step from the stack's optical thickness, the
  convergence-order refinement of the cubic tables, and the 4-point rule and angle axis
  of the linear (colour and diffuse) tables.

The builders on top:

* :mod:`thinfilm_mi.tabulate.exact` -- cubic B-spline tables of the exact ``R``/``T`` over
  (angle, wavelength) and their verification.
* :mod:`thinfilm_mi.tabulate.bilinear` -- a verified spline table resampled for bilinear
  lookups (4 texels where the spline reads 16), verified against the spline.
* :mod:`thinfilm_mi.tabulate.band` -- tables of ``R``/``T`` convolved with a Gaussian in
  wavenumber (deep stacks), on a sheared axis, from rows sampled through the stack's
  smooth amplitudes: one algorithm in one module.
* :mod:`thinfilm_mi.tabulate.integrated` -- colour tables: ``R``/``T`` integrated against colour
  matching over the angle (RGB and mono variants).
* :mod:`thinfilm_mi.tabulate.diffuse` -- the coated-diffuse product film-in x base x film-out.
* :mod:`thinfilm_mi.tabulate.hemispherical` -- hemispherical terms ``R_dh``, ``T_hemi``.

The subpackage exports no names of its own: each is imported from its module.
"""

__all__: list[str] = []
