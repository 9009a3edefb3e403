"""The spectral factors of a ``thinfilm_diffuse`` as its colour tables
(:mod:`thinfilm_mi.tabulate.diffuse`) integrate them: the coating's transmittance at
any (angle, wavelength) and its hemispherical terms, read from the plugin's
:class:`~thinfilm_mi.render.kernel.KernelStack` and media."""
from __future__ import annotations

import math

import numpy as np

from thinfilm_mi.render.kernel import side_rt
from thinfilm_mi.render.textures import scalar
from thinfilm_mi.tabulate.hemispherical import hemispherical_factors, r_dh_partials


class DiffuseFactors:
    """The spectral factors of a ``thinfilm_diffuse`` for :class:`ColourDiffuse`:
    ``t(cos, wl)`` (shape ``(len cos, len wl)``) and ``hemispherical(wl) ->
    (R_dh, T_hemi)`` (over ``wl``), for the coating ``coating`` (a
    :class:`~thinfilm_mi.render.kernel.KernelStack`) over the absorbing film ``film_n``
    (a ``SpectralIndex``) of ``film_n_thickness`` nm, or over the base medium
    (``film_n`` ``None``)."""

    def __init__(self, coating, film_n, film_n_thickness: float | None):
        self.coating, self.film_n, self.film_n_thickness = coating, film_n, film_n_thickness

    def t(self, cos, wl):

        _, T = side_rt(self.coating, False, cos, wl)
        if self.film_n is None:
            return T
        n0 = self.coating.ambient.spectral_values(wl, real=True)
        n_f = self.film_n.spectral_values(wl)
        beta2 = (n0 ** 2)[None, :] * (1.0 - cos ** 2)[:, None]
        q = np.sqrt((n_f ** 2)[None, :] - beta2 + 0j)
        q = np.where(q.imag < 0, -q, q)           # the decaying root
        return T * np.exp(-(4.0 * math.pi / wl)[None, :] * q.imag * self.film_n_thickness)

    def _arguments(self, wl):
        """:func:`~thinfilm_mi.tabulate.hemispherical.hemispherical_factors`'s arguments at ``wl``."""

        c = self.coating
        n0 = c.ambient.spectral_values(wl, real=True)
        coat = [(ix.spectral_values(wl), scalar(d)) for ix, d in zip(c.indices, c.thickness)]
        fn = None if self.film_n is None else (self.film_n.spectral_values(wl),
                                               self.film_n_thickness)
        return n0, coat, c.substrate.spectral_values(wl), fn

    def hemispherical(self, wl):

        t_hemi, r_dh = hemispherical_factors(*self._arguments(wl), wavelengths=wl)
        return r_dh, t_hemi

    def r_dh_partials(self, wl):
        """``∂R_dh/∂x`` at ``wl`` (:func:`~thinfilm_mi.tabulate.hemispherical.r_dh_partials`):
        per film of the coating, then film ``N``, its thickness, ``Re n``, ``Im n``."""

        return r_dh_partials(*self._arguments(wl), wavelengths=wl)
