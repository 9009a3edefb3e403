"""Incoherent Mueller components (thinfilm_mi/optics/incoherent_mueller.py): the average
over a thick film's phase."""
from __future__ import annotations

import numpy as np
from drjit.llvm import Float64

import thinfilm_mi  # noqa: F401  (registers the plugins in every variant)
from tests.support.mueller import channels
from tests.support.polarized import polarized_variant, pytestmark  # noqa: F401  (the skip mark, variant fixture)
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.optics.incoherent import incoherent_rt
from thinfilm_mi.optics.incoherent_mueller import incoherent_mueller
from thinfilm_mi.optics.mueller import mueller_rt


def test_incoherent_components_are_the_average_over_a_thick_films_phase():
    """One lossless thick film between two coherent sub-stacks (over glass and over
    a metal): the incoherent combination of the parts' Mueller components
    (optics.incoherent_mueller) equals the average of the coherent components over
    the film's phase 2 delta (64 thicknesses across one period: the orders of the
    round trips alias only from the 64th on, whose weight here is < (R_b R_e)^32 <
    1e-30), every channel, to float64 rounding (measured 2e-15 over glass, 3e-11
    over the metal, the same with 128 thicknesses: rounding, not aliasing). (An absorbing
    film's attenuation changes across a period too, by ~1e-4 at k = 2e-5, so there
    the average is not the same quantity.) An absorbing thick film and several
    thick films: R and T are exactly the unpolarized incoherent evaluator's (tmm's
    inc_tmm model, tests/tabulate/test_exact.py: absorption enters both through the same
    single-pass P) and every lobe is physical, R >= sqrt(B² + |C|²)."""
    rng = np.random.default_rng(1)
    cos, wl = rng.uniform(0.05, 1.0, 8), rng.uniform(400.0, 800.0, 8)
    for n_exit in (1.52, 0.2 + 3.0j):
        films = [(1.46, 300.0), (1.6, 20000.0), (2.3, 80.0)]
        flags = [False, True, False]
        transmission = complex(n_exit).imag == 0
        ex = Cx(complex(n_exit).real, complex(n_exit).imag)
        cx = [(Cx(n.real, n.imag), d) for n, d in map(lambda f: (complex(f[0]), f[1]), films)]
        ours = channels(incoherent_mueller(1.0, Float64(cos), cx, ex, Float64(wl), flags,
                                           transmission), cos.size)
        q = np.sqrt(1.6 ** 2 - (1.0 - cos ** 2))
        steps = 64       # all thicknesses in one batch: (step, point)
        d = 20000.0 + (np.arange(steps)[:, None] / steps) * (wl / (2.0 * q))[None, :]
        cs, ws = np.tile(cos, steps), np.tile(wl, steps)
        avg = channels(mueller_rt(1.0, Float64(cs), [cx[0], (cx[1][0], Float64(d.ravel())), cx[2]],
                                  ex, Float64(ws), transmission), cs.size)
        avg = avg.reshape(steps, cos.size, -1).mean(axis=0)
        assert np.abs(ours - avg).max() < 1e-10, n_exit
        assert np.abs(ours[:, 2 if transmission else 1:]).max() > 0.05
    for films, flags in (([(1.46, 300.0), (1.6 + 2e-5j, 20000.0), (2.3, 80.0)], [False, True, False]),
                         ([(1.46, 300.0), (1.6, 20000.0), (2.3, 80.0), (1.38 + 1e-5j, 30000.0),
                           (2.1, 120.0)], [False, True, False, True, False])):
        cx = [(Cx(complex(n).real, complex(n).imag), d) for n, d in films]
        ours = channels(incoherent_mueller(1.0, Float64(cos), cx, Cx(1.52, 0.0), Float64(wl),
                                           flags), cos.size)
        R, T = incoherent_rt(1.0, Float64(cos), cx, Cx(1.52, 0.0), Float64(wl), flags)
        assert np.abs(ours[:, 0] - np.array(R)).max() < 1e-14
        assert np.abs(ours[:, 1] - np.array(T)).max() < 1e-14
        for P, B, cr, ci in ((0, 2, 3, 4), (1, 5, 6, 7)):
            norm = np.sqrt(ours[:, B] ** 2 + ours[:, cr] ** 2 + ours[:, ci] ** 2)
            assert np.all(norm <= ours[:, P] * (1 + 1e-12))
