"""Tolerance analysis (thinfilm_mi/design/tolerance.py): the tolerance syntax and the
statistics of the draws."""
from __future__ import annotations

import numpy as np
import pytest

from tests.support.design import ALL_KINDS, ALL_KINDS_D, ALL_KINDS_FILMS
from thinfilm_mi.design import (
    Design,
    Merit,
    load_problem,
    parse_tolerance,
    tolerance_analysis,
)
from thinfilm_mi.errors import ThinFilmError


# ---------------------------------------------------------------------------
# tolerances
# ---------------------------------------------------------------------------
def test_parse_tolerance():
    spec = parse_tolerance("1%:200")
    assert (spec.sigma, spec.relative, spec.draws, spec.distribution.name) == (0.01, True, 200, "normal")
    spec = parse_tolerance("2nm:500:uniform")
    assert (spec.sigma, spec.relative, spec.draws, spec.distribution.name) == (2.0, False, 500, "uniform")
    assert parse_tolerance("0.5%").draws == 200
    for bad in ("1", "abc", "-1%", "1%:0", "150%", "1%:10:gauss", "nan%"):
        with pytest.raises(ThinFilmError, match="--tolerance"):
            parse_tolerance(bad)


def test_tolerance_statistics_are_those_of_the_draws():
    problem = load_problem(ALL_KINDS)
    merit = Merit(problem)
    nominal = Design(ALL_KINDS_FILMS, ALL_KINDS_D.copy(), np.array([2.3]))
    res = tolerance_analysis(merit, nominal, "3%:40:uniform", seed=5)
    assert np.all(np.abs(res.thicknesses / ALL_KINDS_D[:, None] - 1) <= 0.03 + 1e-12)
    for b in (0, 17, 39):   # the batched evaluation equals one evaluation per draw
        one = merit.merit(Design(ALL_KINDS_FILMS, res.thicknesses[:, b], nominal.n))
        assert abs(res.merits[b] - one) < 1e-9 * one
    d = res.to_dict()
    assert d["merit"]["worst"] == pytest.approx(res.merits.max())
    assert d["merit"]["mean"] == pytest.approx(res.merits.mean())
    colour_rec = d["targets"][2]
    assert len(colour_rec["delta_e2000"]) == 2 and len(colour_rec["delta_e2000_nominal"]) == 2
    none = tolerance_analysis(merit, nominal, "0nm:5")
    assert np.allclose(none.merits, none.nominal_merit, rtol=1e-12)
    assert all(t["delta_e2000_nominal"][0]["worst"] < 1e-9 for t in none.targets if "delta_e2000_nominal" in t)


def test_tolerance_distributions_draw_their_errors():
    """DISTRIBUTIONS: normal draws are numpy's standard normals times sigma; uniform ones
    lie within ±sigma and fill it; both clipped at 0 nm."""
    from thinfilm_mi.design.tolerance import DISTRIBUTIONS, draw_thicknesses

    assert list(DISTRIBUTIONS) == ["normal", "uniform"]
    d = np.array([100.0, 3.0])
    normal = draw_thicknesses(d, parse_tolerance("2nm:4000"), seed=7)
    want = d[:, None] + 2.0 * np.random.default_rng(7).standard_normal((2, 4000))
    np.testing.assert_array_equal(normal, np.maximum(want, 0.0))
    uniform = draw_thicknesses(d, parse_tolerance("1%:4000:uniform"), seed=7)
    ratio = uniform[0] / d[0] - 1.0
    # 4000 uniform draws on [-0.01, 0.01]: each lands within 1e-3 of a given end with
    # probability 0.05, so both extremes do unless (0.95)^4000 ~ 1e-89 happens (normal draws
    # would leave the band [-0.01, 0.01] of 1 sigma in 32 % of cases)
    assert np.all(np.abs(ratio) <= 0.01 + 1e-15) and ratio.max() > 0.01 - 1e-3 and ratio.min() < -0.01 + 1e-3
