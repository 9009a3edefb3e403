"""The merit function (thinfilm_mi/design/merit.py): its gradient and the needle function
against central finite differences."""
from __future__ import annotations

import numpy as np

from tests.support.design import ALL_KINDS, ALL_KINDS_D, ALL_KINDS_FILMS
from thinfilm_mi.design import (
    Design,
    Merit,
    load_problem,
)


def test_merit_gradient_matches_finite_differences():
    merit = Merit(load_problem(ALL_KINDS))
    design_ = Design(ALL_KINDS_FILMS, ALL_KINDS_D.copy(), np.array([2.3]))
    value, grad = merit.merit_and_gradient(design_)
    x = np.r_[design_.d, design_.n]
    h = 1e-5        # nm (and index units): FD truncation ~h^2, rounding ~1e-16 / h, both < 1e-9 here
    fd = np.zeros_like(x)
    for k in range(x.size):
        up, down = x.copy(), x.copy()
        up[k] += h
        down[k] -= h
        fd[k] = (merit.merit(Design(ALL_KINDS_FILMS, up[:5], up[5:]))
                 - merit.merit(Design(ALL_KINDS_FILMS, down[:5], down[5:]))) / (2 * h)
    assert value > 1.0 and np.all(np.abs(grad) > 0)
    # the bound; measured 2e-10 (the index column, ~1e-11 for thicknesses)
    assert np.max(np.abs(grad - fd)) <= 1e-6 * np.max(np.abs(grad)), (grad, fd)


def test_needle_function_matches_inserting_a_film():
    merit = Merit(load_problem(ALL_KINDS))
    base = Design(ALL_KINDS_FILMS, ALL_KINDS_D.copy(), np.array([2.3]))
    depths, P = merit.needle_function(base)
    assert P.shape == (sum(len(z) for z in depths), 3)

    def sum_sq(films, d):
        e, _ = merit.evaluate(Design(films, np.array(d), base.n), jac=False)
        return float(e @ e)

    h = 1e-4
    offsets = np.r_[0, np.cumsum([len(z) for z in depths])]
    for j, k, m in ((0, 2, 1), (3, 5, 0), (4, len(depths[4]) - 1, 2)):
        z, dj = depths[j][k], ALL_KINDS_D[j]
        films = ALL_KINDS_FILMS[:j] + [ALL_KINDS_FILMS[j], m, ALL_KINDS_FILMS[j]] + ALL_KINDS_FILMS[j + 1:]
        d = lambda t: list(ALL_KINDS_D[:j]) + [z, t, dj - z] + list(ALL_KINDS_D[j + 1:])  # noqa: E731
        fd = (sum_sq(films, d(h)) - sum_sq(films, d(-h))) / (2 * h)  # a negative film is analytic too
        assert abs(fd - P[offsets[j] + k, m]) <= 1e-6 * max(1.0, abs(fd)), (j, k, m, fd, P[offsets[j] + k, m])
