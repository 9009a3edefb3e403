"""The escape cone of a smooth top seen from the coat medium (no plugin classes here): its
critical cosine, and the fold that maps the directions beyond it, which total internal
reflection traps, into the cone and back (the sampling mixture of
:class:`~thinfilm_mi.render.layered.nested.NestedEstimator` and the walk's steps,
:class:`~thinfilm_mi.render.layered.walk.RandomWalk`)."""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["critical_cosine", "fold", "unfold"]


def critical_cosine(eta):
    """``μ_c = cos θ_c``, beyond which light under a top of relative index ``eta``
    (``η_c/η_e``) is totally reflected; 0 where ``eta <= 1`` (no total reflection)."""
    return dr.select(eta > 1, dr.safe_sqrt(1.0 - dr.rcp(dr.square(eta))), 0.0)


def _with_cosine(w, mu):
    """``w`` turned about the normal's azimuth to the cosine ``mu`` (``w``'s sine from its
    own components, exact near the normal; along the normal itself, the azimuth 0)."""
    mi = mitsuba_module()
    sin2 = dr.square(w.x) + dr.square(w.y)
    k = dr.safe_sqrt((1.0 - dr.square(mu)) / dr.maximum(sin2, 1e-30))
    on_axis = sin2 < 1e-30
    return mi.Vector3f(dr.select(on_axis, dr.safe_sqrt(1.0 - dr.square(mu)), w.x * k),
                       dr.select(on_axis, 0.0, w.y * k), mu)


def fold(w, mu_c):
    """An inner direction beyond the critical cosine (``0 < w.z < μ_c``) folded into the
    escape cone: ``μ' = μ_c + (μ_c - μ)(1 - μ_c)/μ_c``, the same azimuth (its density is
    multiplied by ``μ_c / (1 - μ_c)``)."""
    return _with_cosine(w, mu_c + (mu_c - w.z) * (1.0 - mu_c) / dr.maximum(mu_c, 1e-6))


def unfold(w, mu_c):
    """The direction beyond the critical cosine that :func:`fold` maps to ``w`` (in the
    escape cone)."""
    return _with_cosine(w, mu_c - (w.z - mu_c) * mu_c / dr.maximum(1.0 - mu_c, 1e-6))
