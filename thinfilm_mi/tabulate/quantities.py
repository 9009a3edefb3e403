"""What a table holds: one *quantity* object per kind, registered in :data:`QUANTITIES`.

A :class:`~thinfilm_mi.tabulate.base.SideData` carries its quantity; the builders
(:mod:`thinfilm_mi.tabulate.exact`, :mod:`thinfilm_mi.tabulate.band`) and the render
kernel (:mod:`thinfilm_mi.render.kernel`) ask it, never test which it is:

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

__all__ = ["AUTO_MAX_TEXELS", "AUTO_MIN_FILMS", "LINEAR_MAX_FLOATS", "POWERS", "QUANTITIES", "RT_AUTO_MIN_FILMS",
           "PowersQuantity"]

#: ``tabulate="auto"`` tabulates a side of ``R`` only from this many films (after the
#: skips): one film on a conductor renders at 0.98x ``conductor`` tabulated against
#: 1.07x exact (issue 32), within ``table_error`` (~3e-4 at the default 1e-3).
AUTO_MIN_FILMS = 1
#: The same for a side of ``R`` and ``T`` (two channels). With cubic lookups (16 texels a
#: wavelength) such a table cost what 4-5 films of the exact loop do, and this was 5
#: (issue 44). Read bilinearly (:mod:`~thinfilm_mi.tabulate.bilinear`): sphere scene of
#: benchmarks/timing.py on glass 1.6, one process, 7 rounds, tabulated / exact against
#: Mitsuba's ``dielectric``: "Cr 5" 1.14x / 1.26x, "Au 20" 1.75x / 1.62x (its table from
#: the glass, across the surface plasmon, is 4.5 MiB), "SiO2 100; Cr 5" 1.37x / 1.47x,
#: "TiO2 60; Ag 12; TiO2 60" 2.06x / 2.18x, "SiO2 500; Au 20; Al 10" 1.84x / 1.79x (its side
#: lit from the glass is over the build budget: exact either way); "SiO2 100; Cr 5" twice
#: 1.26x / 1.83x, three times 1.37x / 2.43x. Below 4 films a table gains at most ~10 % (or
#: loses) and its build costs the first image 0.1-1.3 s (0.7 s for the demo's glass, whose
#: side lit from the glass fails after its probe): from 4.
RT_AUTO_MIN_FILMS = 4
#: ``tabulate="auto"`` keeps tables of at most this many texels (over all
#: channels, 2 MiB of float32): a cubic lookup in a table that fits the cache
#: costs 3-4.6 ns per point, beyond it 7-12 ns, as much as the exact recursion
#: of 3-10 films (benchmarks/SPEED.md). ``tabulate=true`` allows
#: :data:`~thinfilm_mi.tabulate.base.MAX_TEXELS` per channel.
AUTO_MAX_TEXELS = 1 << 19
#: Tables of the powers are read bilinearly where the spline resampled for that
#: (:mod:`thinfilm_mi.tabulate.bilinear`) takes at most this many floats (8 MiB): a
#: bilinear lookup (4 texels a wavelength) costs less than a cubic one of the spline (16):
#: 1.1-3.5 ns against 3.9-10 ns per lookup at random positions in 1-2-channel tables of
#: 0.1-6 MiB, but 7.5 ns in a bilinear table of 9 MiB (issue 44, one process, 10^6 points);
#: beyond it the spline stays.
LINEAR_MAX_FLOATS = 1 << 21


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

