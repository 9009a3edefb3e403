r"""Closed forms of the sum over paths under a smooth top, where the nested base allows one
(no plugin classes here): the registry :data:`CLOSED_FORMS`, keyed by the nested BSDF's
class, each form's code in its class; :func:`closed_form` picks one for a
:class:`~thinfilm_mi.render.layered.nested.NestedEstimator`, which then sums its base part
by that form instead of the random walk
(:func:`~thinfilm_mi.render.layered.nested.sum_estimator`).

**Lambertian** (:class:`Lambertian`, Mitsuba's ``diffuse``): every base vertex sends
``ρ/π`` towards every direction and, sampled by its cosine, returns ``ρ R_in`` on average,
so the walk's sum (at most ``N = max_bounces`` vertices) has the expectation::

    Σ_{k<N} ρ/π cos θ_o' (ρ R_dh)^k = ρ/π cos θ_o' (1 - (ρ R_dh)^N) / (1 - ρ R_dh)

with ``R_dh = ∫ R_in(μ) 2μ dμ`` the underside's cosine-weighted hemispherical
reflectance: the series of ``thinfilm_diffuse``'s model ``"exact"`` (its
:class:`~thinfilm_mi.render.layered.models.Exact`'s factors and
:class:`~thinfilm_mi.render.layered.factors.SpectralTerms`, over the coating's own stack: exact,
or tabulated over a ``thickness`` texture's scale; recomputed on edits). ``ρ`` is read from
the base itself, its ``eval`` at ``wi = wo = z`` times π (the reflectance texture at the
hit, for any Lambertian). No walk noise, and no walk. It applies without a coat medium's
absorption (``A²`` would weigh ``R_in`` by angle inside the integral) and in spectral
variants (RGB and mono keep the walk, per channel of the colour tables); in polarized
variants the base depolarizes at every vertex, so the sum is a depolarizer of that value.
Gradients: the films' gradients reach ``R_dh`` through one cosine-distributed direction
``μ`` (seeded as the walk), ``R_dh + R_in(μ) - detach(R_in(μ))``: the value stays exact,
its derivative is an unbiased estimate of ``∂R_dh``; ``ρ``'s gradient is the base's own.
"""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.render.layered.bottom import base_interaction, intensity
from thinfilm_mi.render.layered.factors import SpectralTerms
from thinfilm_mi.render.layered.models import Exact
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["Lambertian", "CLOSED_FORMS", "closed_form"]


class Lambertian:
    """The closed form over a Lambertian base (module docstring) for ``layer`` (a
    :class:`~thinfilm_mi.render.layered.nested.NestedEstimator`)."""

    def __init__(self, layer):
        self.layer = layer
        self.terms = None
        self.refresh()

    @staticmethod
    def applies(layer) -> bool:
        """No coat absorption, a spectral variant."""
        return layer.medium.sigma_a is None and not layer.mode.integrated

    def refresh(self) -> None:
        """``R_dh`` at the current films (load and edits; updated in place: no recompile)."""
        c = self.layer
        # thinfilm_diffuse's model "exact": the whole stack over the coat medium
        factors = Exact().factors(c.stack, None, None)
        self.terms = SpectralTerms(factors, c.stack.thickness_texture, c.plugin,
                                   self.terms)

    def albedo(self, ctx_mode, si, active):
        """``ρ`` at the hit: the base's ``eval`` at ``wi = wo = z`` times π."""
        mi = mitsuba_module()
        z = mi.Vector3f(0.0, 0.0, 1.0)
        value = self.layer.base.eval(mi.BSDFContext(ctx_mode), base_interaction(si, z), z,
                                       active)
        return intensity(value, self.layer.mode.polarized) * dr.pi

    def sum(self, ctx_mode, si, wi_in, wo_in, seed, active):
        """The walk's expectation ``ρ/π cos θ_o' (1 - (ρ R_dh)^N) / (1 - ρ R_dh)`` (the
        variant's value; any ``wi_in``); ``seed``: the walk's, for ``R_dh``'s gradient."""
        mi = mitsuba_module()
        c = self.layer
        rho = self.albedo(ctx_mode, si, active)
        r_dh = dr.detach(mi.UnpolarizedSpectrum(self.terms.lookup(si, c.stack, active)[0]))
        if c.tracks_gradients(si, active):
            mu = dr.sqrt(mi.sample_tea_float32(seed[0], seed[1], 4))
            r_in = c.top.unpolarized(si, mu, active, inside=True, transmission=False).R
            r_dh = r_dh + (r_in - dr.detach(r_in))
        x = rho * r_dh
        # 1e-6: below it the series' N terms are all ~1 (x^N = 1 - N(1 - x))
        far = x < 1.0 - 1e-6
        series = dr.select(far, (1.0 - dr.power(x, c.max_bounces))
                           / dr.select(far, 1.0 - x, 1.0), float(c.max_bounces))
        # (dr.select returns a plain array, which mi.depolarizer reads as one number)
        value = mi.UnpolarizedSpectrum(rho * dr.inv_pi * dr.maximum(wo_in.z, 0.0) * series)
        return mi.depolarizer(value) if c.mode.polarized else mi.Spectrum(value)


#: The closed forms by the nested BSDF's class (``class_name()``): Mitsuba's ``diffuse``.
CLOSED_FORMS = {"SmoothDiffuse": Lambertian}


def closed_form(layer):
    """The closed form of ``layer``'s base (an instance of a :data:`CLOSED_FORMS` class),
    or ``None`` where its class has none or the form does not apply (the walk then)."""
    form = CLOSED_FORMS.get(layer.base.class_name())
    return form(layer) if form is not None and form.applies(layer) else None
