"""Design synthesis (thinfilm_mi/design/synthesis.py). The design targets of issue 34 are
checked on designs found from no start: the broadband AR coating (R_avg <= 0.15 %,
R_max <= 0.35 % over 420-680 nm with tmm at 1 nm) and colour targets made from random
3-film stacks (within dE2000 2 at every angle); a free index is recovered, films that
reach zero are removed."""
from __future__ import annotations

import numpy as np
import pytest

from tests.support.design import AR, labs, numeric_layers, tmm_rt
from thinfilm_mi.colour.cie import delta_e2000
from thinfilm_mi.design import (
    design,
    refine,
)


# ---------------------------------------------------------------------------
# designs
# ---------------------------------------------------------------------------
def test_broadband_ar_from_no_start_meets_the_issue_target():
    result = design(AR)
    films = numeric_layers(result.layers)
    assert 1 <= len(films) <= 8 and result.problem.start is None
    wl = np.arange(420.0, 680.5, 1.0)
    R, _ = tmm_rt(films, 1.52, 1.0, wl, 0.0)
    # issue 34: R_avg <= 0.15 %, R_max <= 0.35 %; measured 0.046 % and 0.128 % (6 films)
    assert R.mean() <= 0.0015 and R.max() <= 0.0035, (R.mean(), R.max(), result.layers)
    t = result.values[0].target
    R_at, _ = tmm_rt(films, 1.52, 1.0, t.wavelengths, 0.0)
    np.testing.assert_allclose(result.values[0].achieved[0], R_at, atol=1e-12)
    e = (R_at - t.value) / t.tolerance
    assert abs(result.merit - np.sqrt(np.mean(e * e))) < 1e-9


@pytest.mark.parametrize("case", range(2))
def test_colour_targets_of_random_three_film_stacks_are_reached(case):
    rng = np.random.default_rng(100 + case)
    first = int(rng.integers(2))
    truth = [((1.46, 2.35)[(first + k) % 2], float(rng.uniform(20, 300))) for k in range(3)]
    angles = [0.0, 30.0, 60.0]
    wanted = labs(truth, angles)
    targets = {"substrate": "1.52", "materials": ["1.46", "2.35"], "max_layers": 3, "seeds": 8,
               "targets": [{"quantity": "colour", "angles": [a], "Lab": wanted[i].tolist(), "tolerance": 1.0}
                           for i, a in enumerate(angles)]}
    result = design(targets)
    got = labs(numeric_layers(result.layers), angles)
    dE = delta_e2000(wanted, got)
    assert np.all(dE <= 2.0), (truth, result.layers, dE)      # the issue's bound, at every angle
    reported = np.array([v.achieved[0] for v in result.values])
    assert np.all(delta_e2000(got, reported) < 1e-6)            # reported Lab = tmm + colour-science


def test_free_index_is_recovered():
    truth = "1.38 95; 2.1 60"
    wl = np.arange(420.0, 681.0, 10.0)
    targets = {"substrate": "1.52", "materials": ["1.38", {"index": 2.0, "free": [1.8, 2.4]}],
               "targets": [{"quantity": "R", "wavelengths": wl.tolist(), "angles": [a],
                            "value": tmm_rt(numeric_layers(truth), 1.52, 1.0, wl, a)[0].tolist(),
                            "tolerance": 0.001} for a in (0.0, 45.0)]}
    result = refine(targets, "1.38 90; 2.0 70")
    (m0, d0), (m1, d1) = result.films
    # exact data, one minimum nearby: recovered to the optimiser's convergence
    assert abs(float(m1) - 2.1) < 1e-5 and abs(d0 - 95) < 1e-3 and abs(d1 - 60) < 1e-3, result.layers
    assert m0 == "1.38" and result.merit < 1e-4


def test_films_that_reach_zero_are_removed():
    wl = np.arange(450.0, 651.0, 10.0)
    targets = {"substrate": "1.52", "materials": ["1.38", "2.35"],
               "targets": [{"quantity": "R", "wavelengths": wl.tolist(), "tolerance": 0.001,
                            "value": tmm_rt([(1.38, 99.6)], 1.52, 1.0, wl, 0.0)[0].tolist()}]}
    # the target is one 1.38 film's R: the 2.35 film must go to 0 and be removed
    result = refine(targets, "1.38 95; 2.35 5")
    assert [m for m, _ in result.films] == ["1.38"], result.layers
    assert abs(result.films[0][1] - 99.6) < 1e-3 and result.merit < 1e-4
