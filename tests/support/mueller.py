"""tmm's Mueller channels, shared by the Mueller-component tests."""
from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.llvm import Float64

import thinfilm_mi  # noqa: F401  (registers the plugins in every variant)
from tests.support.polarized import polarized_variant, pytestmark  # noqa: F401  (the skip mark, variant fixture)


def channels(out, size) -> np.ndarray:
    zero = dr.zeros(Float64, size)
    return np.stack([np.array(c + zero) for c in out], axis=-1)
