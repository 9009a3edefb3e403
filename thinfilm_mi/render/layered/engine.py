"""The layered BSDF engine (no plugin classes here): :class:`Layered`, a top interface over a
bottom, the light between them summed by an estimator, as pbrt-v4's ``LayeredBxDF<Top,
Bottom>`` (of which its ``CoatedDiffuse`` and ``CoatedConductor`` are instances).

* the top (:mod:`thinfilm_mi.render.layered.top`): a thin-film stack, ``R`` and ``T``
  from both sides, exact or tabulated, smooth (delta lobes) or on rough microfacets;
* the bottom (:mod:`thinfilm_mi.render.layered.bottom`): a diffuse base (Lambertian or
  Oren–Nayar) or any nested Mitsuba BSDF;
* the estimator, registered by the kinds of the top and the bottom (:data:`ESTIMATORS`,
  :func:`layered` builds the engine): over a diffuse bottom, a closed form of
  :data:`~thinfilm_mi.render.layered.models.DIFFUSE_MODELS`
  (:class:`~thinfilm_mi.render.layered.series.SeriesEstimator`); over a nested BSDF, the
  estimator of :mod:`thinfilm_mi.render.layered.nested`, whose sum over paths is the
  base's closed form where it has one (:data:`~thinfilm_mi.render.layered.forms.CLOSED_FORMS`),
  else the random walk (:mod:`thinfilm_mi.render.layered.walk`), and whose base's delta
  lobes add the delta-base chain (:mod:`thinfilm_mi.render.layered.delta`); under a rough
  top, the walk of :mod:`thinfilm_mi.render.layered.rough`.

The engine gives the plugin its components, as the top names them
(:meth:`~thinfilm_mi.render.layered.top.Top.components`; 0: the top's reflection, a delta
lobe under a smooth top, a glossy one under a rough top; 1: the bottom's reflection lobes
through the top, absent over a pure-delta bottom under a smooth top), tells the estimator
which of them a context enables, and routes the parameters: the top's, the estimator's
own, the bottom's, in that order.
"""
from __future__ import annotations

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.layered.bottom import DiffuseBottom, NestedBottom
from thinfilm_mi.render.layered.nested import NestedEstimator
from thinfilm_mi.render.layered.rough import RoughEstimator
from thinfilm_mi.render.layered.series import SeriesEstimator
from thinfilm_mi.render.layered.top import RoughTop, SmoothTop

__all__ = ["ESTIMATORS", "Layered", "layered"]

#: The estimators by the classes of the top and the bottom they sum over, each built as
#: ``estimator(top, bottom, medium, mode, plugin, **own)`` (``own``: its own options).
ESTIMATORS = {
    (SmoothTop, NestedBottom): NestedEstimator,
    (RoughTop, NestedBottom): RoughEstimator,
    (SmoothTop, DiffuseBottom): SeriesEstimator,
}


def layered(top, bottom, medium, mode, plugin: str, **own) -> "Layered":
    """The engine of ``top`` over ``bottom`` through ``medium`` (what lies between them:
    the coat medium, or the paper's film ``N``), summed by the estimator registered for
    their classes (:data:`ESTIMATORS`) with its own options ``own``; ``mode``:
    :func:`thinfilm_mi.render.modes.current`; ``plugin`` names the BSDF in errors."""
    estimator = ESTIMATORS.get((type(top), type(bottom)))
    if estimator is None:
        raise ThinFilmError(f"{plugin}: no estimator sums a {type(top).__name__} over a "
                            f"{type(bottom).__name__}")
    return Layered(top, bottom, estimator(top, bottom, medium, mode, plugin, **own))


class Layered:
    """``top`` over ``bottom``, summed by ``estimator`` (built by :func:`layered`; it holds
    both: its ``sample(ctx, si, s1, s2, active, has_top, has_base)``, ``eval_pdf(ctx, si,
    wo, active, has_top, has_base, want_value, want_pdf)``, ``traverse``,
    ``parameters_changed(keys)`` and ``describe()``)."""

    def __init__(self, top, bottom, estimator):
        self.top, self.bottom, self.estimator = top, bottom, estimator

    def components(self) -> list:
        """The components' flags, as the top names them over the bottom."""
        return self.top.components(self.bottom)

    def enabled(self, ctx):
        """``(has_top, has_base)``: whether ``ctx`` enables component 0, resp. one of
        the lobes of component 1."""
        return self.top.enabled(ctx, self.bottom)

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
