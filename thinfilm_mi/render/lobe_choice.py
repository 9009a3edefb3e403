"""The choice between a dielectric's reflected and transmitted lobe, shared by the smooth
and the rough thin-film dielectric: reflection is drawn with the probability of its share
of the spectrally averaged power, and the chosen lobe's weight is divided by it.
"""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.render.variant import spectral_mean

__all__ = ["reflection_probability", "chosen_weight"]


def reflection_probability(R, T):
    """Probability of choosing reflection: the spectral mean of ``R`` over that of ``R +
    T`` (1 where both are 0, so a black lane still reflects)."""
    pr, pt = spectral_mean(R), spectral_mean(T)
    total = pr + pt
    return dr.select(total > 0, pr / dr.select(total > 0, total, 1.0), 1.0)


def chosen_weight(selected_r, prob_r, R, T):
    """The weight of the chosen lobe: ``R / prob_r`` where reflection was chosen, ``T / (1
    - prob_r)`` where transmission was (no division by a zero probability, whose lobe is
    never chosen), formed as the chosen lobe times one reciprocal per lane rather than a
    division per wavelength and lobe."""
    p = dr.select(selected_r, prob_r, 1.0 - prob_r)
    return dr.select(selected_r, R, T) * dr.rcp(dr.select(p > 0, p, 1.0))
