"""What a table holds: one *quantity* object per kind, registered in :data:`QUANTITIES`.

A :class:`~thinfilm_mi.tabulate.base.SideData` carries its quantity; the builders
(:mod:`thinfilm_mi.tabulate.exact`, :mod:`thinfilm_mi.tabulate.band`) and the render layer's
stack (:mod:`thinfilm_mi.render.stack_plan`, :mod:`thinfilm_mi.render.stack_build`) ask it, never test which it is:

* :data:`POWERS` (``"powers"``): the unpolarized ``R`` [, ``T``] of the spectral
  variants, evaluated by :func:`~thinfilm_mi.optics.unpolarized.unpolarized_rt`
  (or the incoherent-aware :func:`~thinfilm_mi.optics.incoherent.incoherent_rt`);
* :data:`~thinfilm_mi.tabulate.mueller.MUELLER` (``"mueller"``): the Mueller
  components of the polarized variants.

Each provides: ``name`` (in the table cache's key), ``channels(transmission)``,
``auto_min_films(transmission)`` and ``auto_max_floats`` (what ``tabulate="auto"``
tabulates), the build's evaluators ``rt(incoherent)`` and ``rt_loop``, and for the
band-limited build ``v_spacing``, ``smooth_terms`` (the smooth amplitudes of the first
level), ``values`` (the channels from them), ``grazing(transmission)`` (the channels
at grazing incidence), ``colour_terms`` (the powers the colour check compares) and
``squared_terms`` (whether channels 8-9 of ``smooth_terms`` are squared amplitudes,
rescaled twice by the exponents). A new quantity is one class and one entry.
"""
from __future__ import annotations

import numpy as np

from thinfilm_mi.optics.incoherent import incoherent_rt
from thinfilm_mi.optics.unpolarized import unpolarized_rt, unpolarized_rt_loop
from thinfilm_mi.tabulate.band import V_SPACING, amplitudes, powers_of
from thinfilm_mi.tabulate.mueller import MUELLER
from thinfilm_mi.tabulate.policy import AUTO_MAX_TEXELS, AUTO_MIN_FILMS, LINEAR_MAX_FLOATS, RT_AUTO_MIN_FILMS

__all__ = ["POWERS", "QUANTITIES", "PowersQuantity"]


class PowersQuantity:
    """The unpolarized powers ``R`` [, ``T``] (see the module)."""

    name = "powers"
    auto_max_floats = AUTO_MAX_TEXELS
    linear_max_floats = LINEAR_MAX_FLOATS
    #: First v-node spacing of band-limited tables (σ_ν units)
    v_spacing = V_SPACING
    squared_terms = True
    smooth_terms = staticmethod(amplitudes)
    values = staticmethod(powers_of)
    rt_loop = staticmethod(unpolarized_rt_loop)

    @staticmethod
    def channels(transmission: bool) -> int:
        return 2 if transmission else 1

    @staticmethod
    def auto_min_films(transmission: bool) -> int:
        """Films from which ``tabulate="auto"`` tabulates a side (``transmission``: of
        ``R`` and ``T``)."""
        return RT_AUTO_MIN_FILMS if transmission else AUTO_MIN_FILMS

    @staticmethod
    def rt(incoherent: list):
        """The build's evaluator ``(n0, cos0, films, n_exit, wl, transmission) -> R |
        (R, T)`` of a side with these incoherent flags."""
        if any(incoherent):
            return lambda n0, cos0, films, n_exit, wl, transmission: incoherent_rt(
                n0, cos0, films, n_exit, wl, incoherent, transmission=transmission)
        return unpolarized_rt

    @staticmethod
    def grazing(transmission: bool) -> np.ndarray:
        """``R = 1`` [, ``T = 0``] at grazing incidence."""
        return np.array([1.0, 0.0] if transmission else [1.0])

    @staticmethod
    def colour_terms(values: np.ndarray, transmission: bool) -> np.ndarray:
        """The powers the colour check compares: the channels themselves."""
        return values


#: The powers (stateless; one instance shared by every build).
POWERS = PowersQuantity()
#: Every quantity by name.
QUANTITIES = {q.name: q for q in (POWERS, MUELLER)}

