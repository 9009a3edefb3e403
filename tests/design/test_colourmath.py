"""The designer's colour math (thinfilm_mi/design/colourmath.py) against colour-science:
L*a*b*, the colour integrals, and CIEDE2000 with derivatives."""
from __future__ import annotations

import colour
import numpy as np

from tests.support.design import cs_colour
from thinfilm_mi.colour.cie import delta_e2000
from thinfilm_mi.design.colourmath import Dual, colour_weights, delta_e2000_residuals, lab


def test_colour_math_against_colour_science():
    rng = np.random.default_rng(0)
    wl, W, white = colour_weights("D65", 2)
    spectra = rng.random((4, wl.size))
    for s in spectra:
        XYZ, _, Lab = cs_colour(s)
        np.testing.assert_allclose(s @ W, XYZ, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(lab(Dual.variables(s @ W), white).val, Lab, atol=1e-9)
    A = np.column_stack([rng.uniform(0, 100, 500), rng.uniform(-90, 90, 500), rng.uniform(-90, 90, 500)])
    for B in (A + rng.normal(0, 3, A.shape), A[::-1]):      # near and far pairs (all hue branches)
        np.testing.assert_allclose(delta_e2000(A, B), colour.delta_E(A, B, method="CIE 2000"), atol=1e-10)


def test_delta_e2000_residuals_equal_colour_science():
    """The designer's CIEDE2000 with derivatives: its three residuals' norm is
    colour-science's dE00 on many random pairs (near and far, every hue branch, and
    achromatic ones). The tolerance: both evaluate the same closed form in float64 and
    differ only in the order of operations (degrees, the rotation term folded into the
    residuals, a square root of a sum of squares), a few ulp of terms up to ~250, i.e.
    ~1e-13 (measured ≤ 9e-14); 1e-10 is far below any tolerance compared with (≥ 0.01)."""
    rng = np.random.default_rng(7)
    n = 20000
    A = np.column_stack([rng.uniform(0, 100, n), rng.uniform(-128, 128, n), rng.uniform(-128, 128, n)])
    grey = A * np.array([1.0, 0.0, 0.0])
    for B in (A + rng.normal(0, 3, A.shape), A[::-1], grey[::-1], A):
        for X in (A, grey):
            e = delta_e2000_residuals(Dual(B, np.zeros(B.shape + (1,))), X).val
            np.testing.assert_allclose(np.sqrt(np.sum(e * e, axis=-1)),
                                       colour.delta_E(X, B, method="CIE 2000"), rtol=0, atol=1e-10)
