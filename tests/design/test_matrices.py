"""Characteristic matrices (thinfilm_mi/design/matrices.py) against tmm's ``coh_tmm``."""
from __future__ import annotations

import numpy as np

from tests.support.design import tmm_rt
from thinfilm_mi.design.matrices import stack_response
from thinfilm_mi.optics.polarization import P, S


# ---------------------------------------------------------------------------
# optics and colour against the references
# ---------------------------------------------------------------------------
def test_characteristic_matrices_against_tmm():
    rng = np.random.default_rng(3)
    wl = np.linspace(380.0, 780.0, 9)
    for _ in range(4):
        films = [complex(rng.uniform(1.2, 2.6), rng.choice([0.0, rng.uniform(0, 0.3), rng.uniform(1, 4)]))
                 for _ in range(4)]
        d = rng.uniform(5.0, 300.0, 4)
        sub, angle = complex(rng.uniform(1.3, 2.0), rng.uniform(0, 2)), rng.uniform(0, 80)
        beta2 = np.full(wl.shape, np.sin(np.radians(angle)) ** 2)
        for pol in (S, P):
            res = stack_response(np.ones(wl.shape), np.full(wl.shape, sub), [np.full(wl.shape, n) for n in films],
                                 d, wl, beta2, pol, derivatives=False)
            R, T = tmm_rt(list(zip(films, d)), sub, 1.0, wl, angle, pol.name)
            # float64 transfer matrices of a few films: agreement to rounding
            np.testing.assert_allclose(res.R, R, rtol=0, atol=1e-12)
            np.testing.assert_allclose(res.T, T, rtol=0, atol=1e-12)
