"""What ``thinfilm_diffuse`` needs beyond its kernel stack.

* :class:`DiffuseFactors`: its spectral factors as its colour tables
  (:mod:`thinfilm_mi.tabulate.diffuse`) integrate them: the coating's transmittance at
  any (angle, wavelength) and its hemispherical terms, read from the plugin's
  :class:`~thinfilm_mi.render.kernel.KernelStack` and media.
* :func:`update_derivative_table`, :func:`with_derivatives`: ``R_dh`` carrying its
  derivatives with respect to the films' thicknesses and indices (model "multiple"
  in AD variants), from a table built when a film parameter carries gradients.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import GRID
from thinfilm_mi.render.kernel import side_rt
from thinfilm_mi.render.textures import mitsuba_module, scalar
from thinfilm_mi.tabulate.diffuse_scale import exact_hemispherical, paper_hemispherical
from thinfilm_mi.tabulate.hemispherical import PER_FILM, DerivativeTable, hemispherical_factors, r_dh_partials


class DiffuseFactors:
    """The spectral factors of a ``thinfilm_diffuse`` for :class:`ColourDiffuse`:
    ``t(cos, wl)`` (shape ``(len cos, len wl)``) and ``hemispherical(wl) ->
    (R_dh, T_hemi)`` (over ``wl``), for the coating ``coating`` (a
    :class:`~thinfilm_mi.render.kernel.KernelStack`) over the absorbing film ``film_n``
    (a ``SpectralIndex``) of ``film_n_thickness`` nm, or over the base medium
    (``film_n`` ``None``); every thickness times ``scale`` (a ``thickness`` texture's
    value). :meth:`hemispherical_scales` gives the terms at several scales."""

    def __init__(self, coating, film_n, film_n_thickness: float | None, scale: float = 1.0):
        self.coating, self.film_n, self.film_n_thickness = coating, film_n, film_n_thickness
        self.scale = float(scale)

    def at_scale(self, scale: float) -> "DiffuseFactors":
        """The same factors with every thickness times ``scale`` (instead of :attr:`scale`)."""
        return DiffuseFactors(self.coating, self.film_n, self.film_n_thickness, scale)

    def hemispherical_scales(self, wl, scales):
        """``(R_dh, T_hemi)`` at every thickness scale of ``scales``, each of shape
        ``(len scales, len wl)``."""
        n0, coat, n_exit, fn = self.at_scale(1.0)._arguments(wl)
        if fn is None:   # the coating over the (matched) base medium: the exact terms
            return exact_hemispherical(n0, coat, n_exit.real, wl, scales)
        return paper_hemispherical(n0, coat, fn, wl, scales)

    def t(self, cos, wl):

        _, T = side_rt(self.coating, False, cos, wl, self.scale)
        if self.film_n is None:
            return T
        n0 = self.coating.ambient.spectral_values(wl, real=True)
        n_f = self.film_n.spectral_values(wl)
        beta2 = (n0 ** 2)[None, :] * (1.0 - cos ** 2)[:, None]
        q = np.sqrt((n_f ** 2)[None, :] - beta2 + 0j)
        q = np.where(q.imag < 0, -q, q)           # the decaying root
        return T * np.exp(-(4.0 * math.pi / wl)[None, :] * q.imag * self.film_n_thickness
                          * self.scale)

    def _arguments(self, wl):
        """:func:`~thinfilm_mi.tabulate.hemispherical.hemispherical_factors`'s arguments at ``wl``."""

        c = self.coating
        n0 = c.ambient.spectral_values(wl, real=True)
        coat = [(ix.spectral_values(wl), scalar(d) * self.scale)
                for ix, d in zip(c.indices, c.thickness)]
        fn = None if self.film_n is None else (self.film_n.spectral_values(wl),
                                               self.film_n_thickness * self.scale)
        return n0, coat, c.substrate.spectral_values(wl), fn

    def hemispherical(self, wl):

        t_hemi, r_dh = hemispherical_factors(*self._arguments(wl), wavelengths=wl)
        return r_dh, t_hemi

    def r_dh_partials(self, wl):
        """``∂R_dh/∂x`` at ``wl`` (:func:`~thinfilm_mi.tabulate.hemispherical.r_dh_partials`):
        per film of the coating, then film ``N``, its thickness, ``Re n``, ``Im n``."""

        return r_dh_partials(*self._arguments(wl), wavelengths=wl)


def film_gradients(bsdf) -> bool:
    """Whether a film parameter of ``bsdf`` (a ``layers.*`` value) carries gradients."""
    mi = mitsuba_module()
    if not dr.is_diff_v(mi.Float):
        return False
    params = mi.traverse(bsdf)
    return any(dr.grad_enabled(params[k]) for k in params.keys()
               if k.startswith("layers.") and dr.is_diff_v(params[k]))


def update_derivative_table(bsdf, factors, model: str, table):
    """``R_dh``'s derivative table for ``bsdf`` now: built from ``factors`` (a
    :class:`DiffuseFactors`) if a film parameter carries gradients and ``table`` is
    missing, kept if it is there, ``None`` when nothing carries gradients (or for
    model "single", or no films). Never needed at scene load, where nothing carries
    gradients: the reverse-mode pass then never runs on Mitsuba's loader threads."""
    if factors is None or model == "single" or not film_gradients(bsdf):
        return None
    return table if table is not None else DerivativeTable(factors.r_dh_partials(GRID))


def with_derivatives(table, r_dh, films, si, wavelengths, index_at, active, plugin: str):
    """``R_dh`` (at ``wavelengths``) plus ``Σ_x ∂R_dh/∂x (x - detach(x))`` over the
    ``films`` (``(SpectralIndex, thickness)``, the coating's then film N) whose
    thickness or index carries gradients: the same value, with ``R_dh``'s derivatives
    (``table``, a :class:`~thinfilm_mi.tabulate.hemispherical.DerivativeTable`).
    ``index_at(ix)``: a film's index at ``wavelengths``. Gradients that reach here
    without a table (enabled without ``params.update()``) raise, never bias."""
    mi = mitsuba_module()
    carriers = {}
    for f, (ix, d) in enumerate(films):
        if dr.grad_enabled(d):
            carriers[PER_FILM * f] = mi.UnpolarizedSpectrum(d - dr.detach(d))
        if ix.carries_gradients(si, active):
            n = index_at(ix)
            carriers[PER_FILM * f + 1] = mi.UnpolarizedSpectrum(n.re - dr.detach(n.re))
            carriers[PER_FILM * f + 2] = mi.UnpolarizedSpectrum(n.im - dr.detach(n.im))
    if not carriers:
        return r_dh
    if table is None:
        raise ThinFilmError(
            f"{plugin}: a film parameter carries gradients, but R_dh's derivative table "
            "was not built: call params.update() after enabling gradients "
            "(dr.enable_grad(params[key]); params.update()), as mi.ad optimisers do")
    return r_dh + table.tangent(wavelengths, carriers, active)
