"""The layered BSDF engine (no plugin classes here): :class:`Layered`, a top interface over a
bottom, the light between them summed by an estimator, as pbrt-v4's ``LayeredBxDF<Top,
Bottom>`` (of which its ``CoatedDiffuse`` and ``CoatedConductor`` are instances).

* the top (:mod:`thinfilm_mi.render.layered.top`): a thin-film stack, ``R`` and ``T``
  from both sides, exact or tabulated, smooth (delta lobes) or on rough microfacets;
* the bottom (:mod:`thinfilm_mi.render.layered.bottom`): a diffuse base (Lambertian or
  Oren–Nayar) or any nested Mitsuba BSDF;
* the estimator: over a diffuse bottom, a closed form of
  :data:`~thinfilm_mi.render.layered.models.DIFFUSE_MODELS`
  (:class:`~thinfilm_mi.render.layered.series.SeriesEstimator`); over a nested BSDF, the
  estimator of :mod:`thinfilm_mi.render.layered.nested`, whose sum over paths is the
  base's closed form where it has one (:data:`~thinfilm_mi.render.layered.forms.CLOSED_FORMS`),
  else the random walk (:mod:`thinfilm_mi.render.layered.walk`), and whose base's delta
  lobes add the delta-base chain (:mod:`thinfilm_mi.render.layered.delta`); under a rough
  top, the walk of :mod:`thinfilm_mi.render.layered.rough`.

The engine gives the plugin its components (0: the top's reflection, a delta lobe under a
smooth top; 1: the bottom's
reflection lobes through the top, absent over a pure-delta bottom), tells the estimator
which of them a context enables, and routes the parameters: the top's, the estimator's
own, the bottom's, in that order.
"""
from __future__ import annotations

from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["Layered"]


class Layered:
    """``top`` over ``bottom``, summed by ``estimator`` (which holds both: its
    ``sample(ctx, si, s1, s2, active, has_delta, has_base)``, ``eval_pdf(ctx, si, wo,
    active, has_delta, has_base, want_value, want_pdf)``, ``traverse``,
    ``parameters_changed(keys)`` and ``describe()``)."""

    def __init__(self, top, bottom, estimator):
        self.top, self.bottom, self.estimator = top, bottom, estimator

    def components(self) -> list:
        """The components' flags: the delta reflection, and the bottom's lobes (if any)."""
        mi = mitsuba_module()
        components = [mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide]
        if self.bottom.lobes:
            lobes = mi.BSDFFlags.Empty
            for lobe in self.bottom.lobes:
                lobes = lobes | lobe
            components.append(lobes | mi.BSDFFlags.FrontSide)
        return components

    def enabled(self, ctx):
        """``(has_delta, has_base)``: whether ``ctx`` enables component 0, resp. one of
        the bottom's lobes as component 1."""
        mi = mitsuba_module()
        return (ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0),
                any(ctx.is_enabled(lobe, 1) for lobe in self.bottom.lobes))

    def sample(self, ctx, si, sample1, sample2, active=True):
        return self.estimator.sample(ctx, si, sample1, sample2, active, *self.enabled(ctx))

    def eval(self, ctx, si, wo, active=True):
        return self.estimator.eval_pdf(ctx, si, wo, active, *self.enabled(ctx),
                                       want_pdf=False)[0]

    def pdf(self, ctx, si, wo, active=True):
        return self.estimator.eval_pdf(ctx, si, wo, active, *self.enabled(ctx),
                                       want_value=False)[1]

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.estimator.eval_pdf(ctx, si, wo, active, *self.enabled(ctx))

    def traverse(self, callback) -> None:
        """The top's parameters, the estimator's own, the bottom's."""
        self.top.traverse(callback)
        self.estimator.traverse(callback)
        self.bottom.traverse(callback)

    def parameters_changed(self, keys) -> None:
        """Refresh the top, then the estimator, after an edit of ``keys`` (``None``: any)."""
        self.top.parameters_changed()
        self.estimator.parameters_changed(keys)
