"""Dispersion formulas (thinfilm_mi/materials/dispersion.py): each of refractiveindex.info's
nine formulas against a closed form written here from the database's definitions
(``database/doc/Dispersion formulas.pdf``), the two Sellmeier conventions, the gradients a
fit chains through, and the shipped formula files against published indices.
"""
from __future__ import annotations

import numpy as np
import pytest

from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials import catalog as M
from thinfilm_mi.materials.dispersion import FORMULAS, DifferentiableFormula, Sellmeier, formula_by_number

LAM = np.array([0.4, 0.55, 0.7, 1.3])  # µm; every pole of the cases below is >= 0.1 µm away

# Coefficient sets of several terms, and n written out from the published definition.
CASES = {
    # 1 Sellmeier: n² - 1 = C1 + Σ C(2j) λ²/(λ² - C(2j+1)²)  (Malitson's silica plus a constant)
    1: ([0.1, 0.6961663, 0.0684043, 0.4079426, 0.1162414, 0.8974794, 9.896161],
        lambda l, c: np.sqrt(1 + c[0] + c[1] * l**2 / (l**2 - c[2]**2) + c[3] * l**2 / (l**2 - c[4]**2)
                             + c[5] * l**2 / (l**2 - c[6]**2))),
    # 2 Sellmeier-2: n² - 1 = C1 + Σ C(2j) λ²/(λ² - C(2j+1))  (SCHOTT's N-BK7 plus a constant)
    2: ([0.1, 1.03961212, 0.00600069867, 0.231792344, 0.0200179144, 1.01046945, 103.560653],
        lambda l, c: np.sqrt(1 + c[0] + c[1] * l**2 / (l**2 - c[2]) + c[3] * l**2 / (l**2 - c[4])
                             + c[5] * l**2 / (l**2 - c[6]))),
    # 3 Polynomial: n² = C1 + Σ C(2j) λ^C(2j+1)
    3: ([2.1, 0.03, -2, -0.01, 2, 0.002, -4],
        lambda l, c: np.sqrt(c[0] + c[1] / l**2 + c[3] * l**2 + c[5] / l**4)),
    # 4 RefractiveIndex.INFO: n² = C1 + C2 λ^C3/(λ² - C4^C5) + C6 λ^C7/(λ² - C8^C9) + C10 λ^C11
    4: ([2.5, 0.3, 2, 0.2, 2, 0.05, 2.2, 9.0, 1.0, -0.01, 2],
        lambda l, c: np.sqrt(c[0] + c[1] * l**2 / (l**2 - 0.04) + c[5] * l**2.2 / (l**2 - 9.0) + c[9] * l**2)),
    # 5 Cauchy: n = C1 + Σ C(2j) λ^C(2j+1)
    5: ([1.45, 0.004, -2, 0.0001, -4, 0.01, 1],
        lambda l, c: c[0] + c[1] / l**2 + c[3] / l**4 + c[5] * l),
    # 6 Gases: n - 1 = C1 + Σ C(2j)/(C(2j+1) - λ⁻²)  (Ciddor's air plus a constant)
    6: ([1e-6, 0.05792105, 238.0185, 0.00167917, 57.362],
        lambda l, c: 1 + c[0] + c[1] / (c[2] - 1 / l**2) + c[3] / (c[4] - 1 / l**2)),
    # 7 Herzberger: n = C1 + C2/(λ² - 0.028) + C3/(λ² - 0.028)² + C4 λ² + C5 λ⁴ + C6 λ⁶
    7: ([1.5, 0.01, 0.001, 0.002, -1e-4, 1e-6],
        lambda l, c: c[0] + c[1] / (l**2 - 0.028) + c[2] / (l**2 - 0.028)**2 + c[3] * l**2 + c[4] * l**4
        + c[5] * l**6),
    # 8 Retro: (n² - 1)/(n² + 2) = C1 + C2 λ²/(λ² - C3) + C4 λ²  ->  n² = (1 + 2x)/(1 - x)
    8: ([0.25, 0.05, 0.02, -0.001],
        lambda l, c: np.sqrt((1 + 2 * (c[0] + c[1] * l**2 / (l**2 - c[2]) + c[3] * l**2))
                             / (1 - (c[0] + c[1] * l**2 / (l**2 - c[2]) + c[3] * l**2)))),
    # 9 Exotic: n² = C1 + C2/(λ² - C3) + C4 (λ - C5)/((λ - C5)² + C6)
    9: ([2.2, 0.03, 0.04, 0.01, 0.3, 0.02],
        lambda l, c: np.sqrt(c[0] + c[1] / (l**2 - c[2]) + c[3] * (l - c[4]) / ((l - c[4])**2 + c[5]))),
}


@pytest.mark.parametrize("number", sorted(CASES))
def test_formula_against_its_published_definition(number):
    c, closed_form = CASES[number]
    n = FORMULAS[number].n(c, LAM)
    # both sides are a few tens of double operations on terms of order 1, away from any
    # pole (no cancellation): they agree to a few ulp, far inside 1e-13
    np.testing.assert_allclose(n, closed_form(LAM, c), rtol=1e-13, atol=0)
    assert n.shape == LAM.shape and np.all(n > 1)


def test_the_registry_is_refractiveindex_info_s_numbering():
    assert sorted(FORMULAS) == list(range(1, 10))
    assert all(f.number == k for k, f in FORMULAS.items())
    # the two Sellmeier conventions are one class, differing only in how the pole is written
    assert type(FORMULAS[1]) is type(FORMULAS[2]) is Sellmeier
    assert FORMULAS[1].definition.endswith("C(2j+1)²)") and FORMULAS[2].definition.endswith("C(2j+1))")
    assert formula_by_number("5") is FORMULAS[5]
    for bad in (0, 10, "x", None):
        with pytest.raises(MaterialError, match=rf"unknown dispersion formula {bad!r} \(refractiveindex.info "
                                                r"knows 1-9\)"):
            formula_by_number(bad)


def test_sellmeier_poles_as_wavelengths_or_squared_are_the_same_index():
    c1, _ = CASES[1]
    c2 = [c1[0], c1[1], c1[2] ** 2, c1[3], c1[4] ** 2, c1[5], c1[6] ** 2]
    # the squares round once (relative 1.1e-16), moving n by far less than 1e-14
    np.testing.assert_allclose(FORMULAS[1].n(c1, LAM), FORMULAS[2].n(c2, LAM), rtol=1e-14, atol=0)


def test_missing_coefficients_count_as_zero():
    lam = np.array([0.5, 1.0, 1.5])
    full = [2.2, 0.03, 0.04, 0.0, 0.0, 0.0]
    np.testing.assert_array_equal(FORMULAS[9].n(full[:3], lam), FORMULAS[9].n(full, lam))
    np.testing.assert_array_equal(FORMULAS[5].n([1.5, 0.01], lam), np.full(3, 1.51))  # a lone C2: λ^0
    # formula 4 with one resonance only: the second is absent, not 0 / (λ² - 0⁰), NaN at 1 µm
    np.testing.assert_allclose(FORMULAS[4].n([2.5, 0.3, 2, 0.2, 2], lam),
                               np.sqrt(2.5 + 0.3 * lam**2 / (lam**2 - 0.04)), rtol=1e-15)


def test_no_real_index_inside_a_resonance_is_nan_and_a_material_refuses_it(tmp_path):
    # n² = 1 + λ²/(λ² - 0.16): negative just below the pole at 0.4 µm, 1 + 0.1521/-0.0079 < 0
    assert np.isnan(FORMULAS[2].n([0, 1.0, 0.16], np.array([0.39]))[0])
    n, grad = FORMULAS[2].n_and_gradient([0, 1.0, 0.16], np.array([0.39, 0.6]))
    assert np.all(np.isnan(n[:1])) and np.all(np.isnan(grad[0])) and np.all(np.isfinite(grad[1]))
    p = tmp_path / "pole.yml"
    p.write_text("DATA:\n  - type: formula 2\n    wavelength_range: 0.3 0.9\n    coefficients: 0 1.0 0.16\n")
    mat = M.resolve(p, require_range=None)
    with pytest.raises(MaterialError, match=r"pole.*gives n = \(?nan.* at 390.0 nm"):
        mat.index(390.0)


@pytest.mark.parametrize("number, c", [
    (1, CASES[1][0]), (2, CASES[2][0]), (5, CASES[5][0]),
    (5, [1.5, 0.004, -2, 0.01]),               # a last amplitude without its exponent (λ⁰)
])
def test_gradients_against_central_differences(number, c):
    f = FORMULAS[number]
    assert isinstance(f, DifferentiableFormula)
    n, grad = f.n_and_gradient(c, LAM)
    np.testing.assert_array_equal(n, f.n(c, LAM))
    assert grad.shape == (LAM.size, len(c))
    for j in range(len(c)):
        h = 1e-6 * max(abs(c[j]), 1e-3)
        up, down = list(c), list(c)
        up[j] += h
        down[j] -= h
        fd = (f.n(up, LAM) - f.n(down, LAM)) / (2 * h)
        # truncation O(h²) ~ 1e-12 relative; rounding ~ 1e-16 · n / h <= 1e-7 for the smallest h
        # (1e-9, the Sellmeier's pole of 0.006 µm²): 1e-6 relative and 1e-6 absolute cover both
        np.testing.assert_allclose(grad[:, j], fd, rtol=1e-6, atol=1e-6, err_msg=f"formula {number}, C{j + 1}")


# -- the shipped formula files against published indices ---------------------------------------
# Fraunhofer lines (nm): F 486.1327, e 546.0740, d 587.5618, C 656.2725
@pytest.mark.parametrize("name, published, tol", [
    # SCHOTT N-BK7 datasheet: nF, ne, nd, nC = 1.52238, 1.51872, 1.51680, 1.51432, printed from this
    # Sellmeier to 5 decimals: within half a unit of the last digit
    ("BK7", (1.52238, 1.51872, 1.51680, 1.51432), 5e-6),
    # fused silica, Malitson, J. Opt. Soc. Am. 55, 1205 (1965), Table: nF, ne, nd, nC (5 decimals);
    # his Sellmeier reproduces his measurements to about 1e-5
    ("SiO2", (1.46313, 1.46008, 1.45846, 1.45637), 1e-5),
])
def test_shipped_formula_files_give_published_indices(name, published, tol):
    n = M.resolve(name).index([486.1327, 546.0740, 587.5618, 656.2725])
    np.testing.assert_allclose(n.real, published, rtol=0, atol=tol)
    assert np.all(n.imag < 1e-7)


def test_shipped_air_is_standard_air():
    # dry air at 15 °C and 101 325 Pa (Ciddor's formula): n - 1 = 2.77e-4 at the sodium D line,
    # the textbook value to its 3 digits
    n = M.resolve("air").index(589.29)
    assert abs((n.real - 1) / 2.77e-4 - 1) < 2e-3 and n.imag == 0
