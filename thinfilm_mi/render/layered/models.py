"""The coated-diffuse models (no plugin classes here): the closed forms of the sum over
paths under a smooth top over a :class:`~thinfilm_mi.render.layered.bottom.DiffuseBottom`,
``thinfilm_diffuse``'s ``model`` option. :data:`DIFFUSE_MODELS` holds one object per value,
each model's code in its class (:class:`DiffuseModel`): the paper's first-order
approximation ``"single"`` (Hirayama et al., eq. 8-10), its interreflection series
``"multiple"``, and the exact closed form ``"exact"`` (every film coherent over a base
medium; the expectation of :mod:`thinfilm_mi.render.layered.walk`'s walk over a Lambertian
base, as :mod:`thinfilm_mi.render.layered.forms` sums it under ``thinfilm_coating``). A
model says how it splits the films into a top and an absorbing film ``N``, its spectral
factors (hence its hemispherical terms and colour tables), the series ``G(k_d, R_dh)`` of
its diffuse term per wavelength, in the colour tables and over an Oren–Nayar bottom, and
whether ``R_dh`` carries derivatives; :class:`~thinfilm_mi.render.layered.series.SeriesEstimator`
applies one. A plugin reads one with
:meth:`~thinfilm_mi.render.reader.PluginProperties.choice`.
"""
from __future__ import annotations

from abc import ABC, abstractmethod

import drjit as dr

from thinfilm_mi.render.layered.factors import DiffuseFactors, ExactFactors, absorbs
from thinfilm_mi.render.textures import mitsuba_module, scalar
from thinfilm_mi.tabulate.base import opaque_float

__all__ = ["DiffuseModel", "Exact", "Single", "Multiple", "DIFFUSE_MODELS"]


class DiffuseModel(ABC):
    """One value of the ``model`` option of the coated-diffuse model.

    The interface the colour tables (:mod:`thinfilm_mi.tabulate.diffuse`) read is
    :meth:`g`, :meth:`series` and :attr:`interreflection`;
    :class:`~thinfilm_mi.render.layered.series.SeriesEstimator` reads the rest. This base class is
    the model with interreflection: ``G(k, r) = k / (1 - k r)``."""
    #: the value of ``model`` that names it
    name = ""
    #: whether the diffuse term sums the light that the coating sends back onto the base
    #: (``G`` depends on ``R_dh``, whose derivatives the kernel then needs)
    interreflection = True
    #: whether ``base_ior`` is a parameter of the model
    takes_base_ior = False

    @abstractmethod
    def split(self, films, ext, base):
        """``(coating films, exit medium, film N, its thickness)`` of ``films``
        (``[(SpectralIndex, thickness)]``) between the ambient ``ext`` and the base medium
        ``base``; film ``N`` and its thickness (an opaque float) ``None`` where there is none."""

    def factors(self, coating, film_n, film_n_thickness):
        """The spectral factors (:class:`~thinfilm_mi.render.layered.factors.DiffuseFactors`) of
        ``coating`` over film ``N``."""
        return DiffuseFactors(coating, film_n, None if film_n is None else scalar(film_n_thickness))

    def base_ratio(self, ext, base) -> bool:
        """Whether ``t`` carries the radiance factor ``n_0/n_b`` of a base medium unlike the
        ambient."""
        return False

    def g(self, kd, r):
        """``G(k_d, r)``: the diffuse term per wavelength divided by ``t_i t_o`` (numpy or
        Dr.Jit)."""
        return kd / (1.0 - kd * r)

    def series(self, kd, r):
        """``G(k_d, r) / k_d`` (numpy)."""
        return 1.0 / (1.0 - kd * r)

    def kernel_series(self, kd, r_dh):
        """``G(k_d, R_dh) / k_d`` in the kernel (``r_dh()``: ``R_dh`` at the hit, not called
        by a model without interreflection)."""
        return dr.rcp(1.0 - kd * r_dh())

    def rough_series(self, terms, r_dh):
        """``π f / (t_i t_o)`` over a rough base of :class:`~thinfilm_mi.render.orennayar.BaseTerms`
        ``terms``: ``π f_b + E_i E_o R_dh / (1 - Ē R_dh)`` (``r_dh()`` as in :meth:`kernel_series`)."""
        r = r_dh()
        return terms.pi_f + terms.e_i * terms.e_o * r * dr.rcp(1.0 - terms.e_avg * r)

    def rough_integrated(self, node_values, terms):
        """``π f`` per colour channel over a rough base from the integrated diffuse table's
        terms ``node_values = [(r_j, M_j)]`` (built without a fixed albedo,
        :meth:`thinfilm_mi.tabulate.diffuse.ColourDiffuse.node_values`; the Lagrange basis
        sums to 1): ``π f_b Σ M_j + E_i E_o Σ r_j/(1 - Ē r_j) M_j``, the integral of
        :meth:`rough_series` against colour matching."""
        mi = mitsuba_module()
        single = mi.Spectrum(0.0)
        rest = mi.Spectrum(0.0)
        for r, m in node_values:
            single += m
            rest += r * dr.rcp(1.0 - terms.e_avg * r) * m
        return terms.pi_f * single + terms.e_i * terms.e_o * rest


class Exact(DiffuseModel):
    """``"exact"``: every film, coherent, over a base medium of index ``base_ior``."""
    name = "exact"
    takes_base_ior = True

    def split(self, films, ext, base):
        return films, base, None, None

    def factors(self, coating, film_n, film_n_thickness):
        return ExactFactors(coating)

    def base_ratio(self, ext, base) -> bool:
        return base is not ext


class Multiple(DiffuseModel):
    """``"multiple"``: the paper's split (films ``1..N-1`` over an absorbing film ``N``,
    which only attenuates) and the interreflection series."""
    name = "multiple"

    def split(self, films, ext, base):
        if films and absorbs(films[-1][0]):
            return films[:-1], films[-1][0], films[-1][0], opaque_float(films[-1][1])
        # no absorbing film N: all films over the base medium (matched to the ambient)
        return films, ext, None, None


class Single(Multiple):
    """``"single"``: the paper's first-order model as published, ``G = k_d``."""
    name = "single"
    interreflection = False

    def g(self, kd, r):
        return kd

    def series(self, kd, r):
        return 1.0

    def kernel_series(self, kd, r_dh):
        return mitsuba_module().UnpolarizedSpectrum(1.0)

    def rough_series(self, terms, r_dh):
        return terms.pi_f

    def rough_integrated(self, node_values, terms):
        single = mitsuba_module().Spectrum(0.0)
        for _, m in node_values:
            single += m
        return terms.pi_f * single


#: The coated-diffuse models by their ``model`` value; the first is the default.
DIFFUSE_MODELS = {m.name: m for m in (Exact(), Single(), Multiple())}
