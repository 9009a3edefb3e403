"""``thinfilm_roughconductor``: at small roughness it is the smooth
``thinfilm_conductor``."""
from __future__ import annotations

import mitsuba as mi
import pytest

mi.set_variant("llvm_ad_spectral")

import thinfilm_mi as tf  # noqa: E402  (registers the plugins)
from tests.support.bsdf import direction
from tests.support.rough import ALPHA0, COND_FILMS, COND_SUB, check_near_smooth, conductor, layers_of


@pytest.mark.parametrize("theta", [0.0, 35.0, 70.0])
def test_small_alpha_is_smooth_conductor(theta):
    rough = conductor(alpha=ALPHA0)
    smooth = mi.load_dict({"type": "thinfilm_conductor", "layers": layers_of(COND_FILMS),
                           "eta": COND_SUB.real, "k": COND_SUB.imag, "ext_ior": 1.0})
    stack = tf.Stack(COND_FILMS, substrate=COND_SUB, ambient=1.0)
    # a facet tilted by <= 8 alpha turns the mirror direction by <= 16 alpha
    check_near_smooth(rough, smooth, stack, direction(theta, 40.0), theta, "R",
                       mi.BSDFContext(), 16 * ALPHA0, seed=1)
