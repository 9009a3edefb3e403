"""design.options: the sides light comes from and the kinds of bound of a target."""
from __future__ import annotations

import numpy as np
import pytest

from thinfilm_mi.design import Design, Merit, load_problem
from thinfilm_mi.design.options import BACK, FRONT, KINDS, SIDES, as_side
from thinfilm_mi.errors import ThinFilmError


def test_kinds_keep_the_residuals_that_count():
    e = np.array([-1.5, 0.0, 2.0])
    de = np.arange(6.0).reshape(3, 2)
    for name, keep in (("=", [1, 1, 1]), ("<=", [0, 0, 1]), (">=", [1, 0, 0])):
        got, dgot = KINDS[name].residuals(e, de)
        np.testing.assert_array_equal(got, e * keep)
        np.testing.assert_array_equal(dgot, de * np.array(keep)[:, None])
        assert KINDS[name].residuals(e, None)[1] is None


def test_sides():
    assert list(SIDES) == ["front", "back"] and as_side("Back") is BACK and as_side(FRONT) is FRONT
    with pytest.raises(ThinFilmError, match=r"^side: expected one of front, back, got 'top'$"):
        as_side("top")
    amb, sub = np.array([1.0 + 0j]), np.array([1.5 + 0.01j])
    assert FRONT.media(amb, sub)[0][0] == 1.0 and FRONT.media(amb, sub)[1][0] == 1.5 + 0.01j
    assert BACK.media(amb, sub)[0][0] == 1.5 and BACK.media(amb, sub)[1][0] == 1.0
    assert FRONT.order(3) == [0, 1, 2] and BACK.order(3) == [2, 1, 0]
    assert FRONT.depths(2.0, 10.0) == 2.0 and BACK.depths(2.0, 10.0) == 8.0
    # columns computed in the order the light meets the films, put back in the front order
    order = BACK.order(3)
    a = np.array([[10.0, 11.0, 12.0, 99.0]])          # films 2, 1, 0, then a free index
    perm = np.r_[np.argsort(order), 3]
    np.testing.assert_array_equal(BACK.front_order((a,), perm, -1)[0], [[12.0, 11.0, 10.0, 99.0]])
    assert FRONT.front_order((a,), perm, -1)[0] is a


def test_back_side_is_the_reversed_stack_lit_from_the_substrate():
    """R and T from the back equal those of the reversed stack between swapped
    (lossless) media, lit from the front; the thickness gradients follow the films."""
    targets = [{"quantity": q, "wavelengths": "450:650:50", "angles": [35], "value": 0.5, "tolerance": 0.1,
                "side": side} for q in ("R", "T") for side in ("front", "back")]
    fwd = Merit(load_problem({"ambient": "1.0", "substrate": "1.52", "materials": ["1.38", "2.35"],
                              "targets": targets}))
    rev = Merit(load_problem({"ambient": "1.52", "substrate": "1.0", "materials": ["1.38", "2.35"],
                              "targets": targets}))
    d = Design([0, 1, 0], np.array([90.0, 40.0, 120.0]))
    e, J = fwd.evaluate(d)
    e_r, J_r = rev.evaluate(Design([0, 1, 0], d.d[::-1].copy()))
    n = 5                                   # points per target
    back, front = slice(n, 2 * n), slice(0, n)           # R from the back; R from the front
    np.testing.assert_allclose(e[back], e_r[front], rtol=0, atol=1e-12)   # float64 matrices, rounding
    np.testing.assert_allclose(J[back], J_r[front][:, ::-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(e[3 * n:], e_r[2 * n:3 * n], rtol=0, atol=1e-12)   # T likewise
