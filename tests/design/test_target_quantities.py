"""design.target_quantities: each target quantity's parsing and residuals, and the
batched pass of the colour targets."""
from __future__ import annotations

import numpy as np
import pytest

from thinfilm_mi.design import Design, Merit, load_problem
from thinfilm_mi.design.target_quantities import COLOUR_SPACES, POWERS, TARGET_QUANTITIES
from thinfilm_mi.errors import ThinFilmError

COMMON = ("quantity", "angles", "tolerance", "kind", "polarization", "side")
BASE = {"substrate": "1.52", "materials": ["1.38", "2.35"]}


def test_registry():
    assert list(TARGET_QUANTITIES) == ["R", "T", "A", "Y", "colour"]
    for name, q in TARGET_QUANTITIES.items():
        assert q.name == name and q.keys[:len(COMMON)] == COMMON and set(q.required) <= set(q.keys)
    assert list(COLOUR_SPACES) == ["Lab", "xy"] and list(POWERS) == ["R", "T"]
    R, T = np.array([0.2, 0.3]), np.array([0.7, 0.5])
    curves = {name: TARGET_QUANTITIES[name].curve(R, T) for name in ("R", "T", "A")}
    np.testing.assert_array_equal(curves["R"], R)
    np.testing.assert_array_equal(curves["T"], T)
    np.testing.assert_array_equal(curves["A"], 1.0 - R - T)


@pytest.mark.parametrize("spelling, name", [("r", "R"), ("t", "T"), ("A", "A"), ("y", "Y"), ("Color", "colour"),
                                            ("COLOUR", "colour")])
def test_quantity_spellings(spelling, name):
    entry = {"quantity": spelling, "angles": [0], "tolerance": 0.01}
    entry.update({"wavelengths": 550, "value": 0.1} if name in "RTA" else
                 {"value": 0.1} if name == "Y" else {"Lab": [50, 0, 0]})
    t = load_problem({**BASE, "targets": [entry]}).targets[0]
    assert t.quantity is TARGET_QUANTITIES[name] and t.name == f"targets[0] ({name})"


def test_bad_quantities_name_the_entry():
    with pytest.raises(ThinFilmError, match=r"targets\[0\]: unknown quantity 'Q'; expected one of R, T, A, Y, colour"):
        load_problem({**BASE, "targets": [{"quantity": "Q"}]})
    with pytest.raises(ThinFilmError, match=r"targets\[0\] \(colour\): kind: colour targets are '=' only"):
        load_problem({**BASE, "targets": [{"quantity": "colour", "Lab": [50, 0, 0], "tolerance": 1, "kind": "<="}]})
    with pytest.raises(ThinFilmError, match=r"targets\[0\] \(Y\): of: expected one of R, T, got 'A'"):
        load_problem({**BASE, "targets": [{"quantity": "Y", "value": 0.1, "tolerance": 1, "of": "A"}]})


def test_colour_targets_of_one_space_evaluated_together_as_alone():
    """The batched pass over every colour target of a space gives each target the
    residuals and derivatives it has alone."""
    targets = [{"quantity": "colour", "angles": [0, 40], "Lab": [55, 8, -30], "tolerance": 2},
               {"quantity": "colour", "angles": [20], "xy": [0.3, 0.31], "tolerance": 0.01, "of": "T"},
               {"quantity": "colour", "angles": [60], "Lab": [70, -5, 10], "tolerance": 1, "illuminant": "A",
                "polarization": "s"},
               {"quantity": "R", "wavelengths": "450:650:100", "value": 0.05, "tolerance": 0.01}]
    d = Design([0, 1, 0], np.array([95.0, 60.0, 130.0]))
    together = Merit(load_problem({**BASE, "targets": targets}))
    e, J, values = together.evaluate(d, report=True)
    start = 0
    for i, t in enumerate(targets):
        e1, J1, v1 = Merit(load_problem({**BASE, "targets": [t]})).evaluate(d, report=True)
        sl = slice(start, start + e1.size)
        start = sl.stop
        # the same arithmetic per element; numpy's vectorised transcendental functions
        # may round the last bit differently in arrays of other lengths
        np.testing.assert_allclose(e[sl], e1, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(J[sl], J1, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(values[i].achieved, v1[0].achieved, rtol=1e-13, atol=1e-15)
    assert start == e.size
