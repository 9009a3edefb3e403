"""The fit's dispersion models (thinfilm_mi/design/dispersion.py): their names and parameters
as measurement files write them, their conventions against closed forms and the shipped
N-BK7 file, and their derivatives against central differences."""
from __future__ import annotations

import numpy as np
import pytest

from thinfilm_mi.design.dispersion import MODELS, model_class
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials import catalog as M

WL = np.array([400.0, 550.0, 700.0, 1000.0])  # nm
# SCHOTT N-BK7's Sellmeier coefficients (its datasheet; C in µm²)
BK7 = {"B1": 1.03961212, "C1": 0.00600069867, "B2": 0.231792344, "C2": 0.0200179144,
       "B3": 1.01046945, "C3": 103.560653}


def _model(name, **params):
    return model_class(name, "test")(params, "test", lambda spec, where: M.resolve(spec))


def test_model_names_and_parameters_are_those_files_use():
    assert {k: v.parameters for k, v in MODELS.items()} == {
        "constant": ("n", "k"), "cauchy": ("A", "B", "C"), "sellmeier": ("B1", "C1", "B2", "C2", "B3", "C3"),
        "catalogue": ("shift", "scale"), "catalog": ("shift", "scale")}
    with pytest.raises(ThinFilmError, match="test: unknown model 'lorentz'; expected one of constant, cauchy"):
        model_class("lorentz", "test")


def test_sellmeier_poles_are_in_square_micrometres_as_schott_writes_them():
    """The fit's sellmeier is refractiveindex.info formula 2: N-BK7's catalogue coefficients
    give the shipped N-BK7 file's index exactly (one code evaluates both) and its nd."""
    fitted = _model("sellmeier", **BK7)
    shipped = M.resolve("BK7")
    np.testing.assert_array_equal(fitted.index(WL), shipped.index(WL).real + 0j)
    # SCHOTT's datasheet nd = 1.51680 (5 decimals) at the d line
    assert abs(fitted.index(np.array([587.5618]))[0].real - 1.51680) < 5e-6
    lam2 = (WL * 1e-3) ** 2
    closed = np.sqrt(1 + sum(BK7[f"B{i}"] * lam2 / (lam2 - BK7[f"C{i}"]) for i in (1, 2, 3)))
    # a few ulp of double arithmetic on terms of order 1 away from the poles
    np.testing.assert_allclose(fitted.index(WL).real, closed, rtol=1e-14)


def test_cauchy_closed_form():
    params = {"A": 2.1, "B": 0.02, "C": 0.001}
    lam = WL * 1e-3
    n = _model("cauchy", **params).index(WL)
    # a few ulp of three terms of order 1
    np.testing.assert_allclose(n.real, 2.1 + 0.02 / lam**2 + 0.001 / lam**4, rtol=1e-14)
    assert np.all(n.imag == 0)


@pytest.mark.parametrize("name, params", [
    ("cauchy", {"A": 2.1, "B": 0.02, "C": 0.001}),
    ("sellmeier", BK7),
    ("constant", {"n": 1.7, "k": 0.05}),
    ("catalogue", {"material": "TiO2", "shift": 0.01, "scale": 0.98}),
])
def test_derivatives_against_central_differences(name, params):
    model = _model(name, **params)
    values = dict(model.values)
    n, dn = model.index_and_derivatives(WL, values)
    assert dn.shape == (WL.size, len(model.parameters))
    for i, p in enumerate(model.parameters):
        h = 1e-6 * max(abs(values[p]), 1e-3)
        up, down = dict(values, **{p: values[p] + h}), dict(values, **{p: values[p] - h})
        fd = (model.index(WL, up) - model.index(WL, down)) / (2 * h)
        # truncation O(h²) ~ 1e-12 relative, rounding ~ 1e-16 · n / h <= 1e-7: 1e-6 covers both
        np.testing.assert_allclose(dn[:, i], fd, rtol=1e-6, atol=1e-6, err_msg=f"{name}.{p}")


def test_sellmeier_inside_a_resonance_gives_nan_not_an_index():
    # pole at 400 nm (C1 = 0.16 µm²): n² = 1 + λ²/(λ² - 0.16) < 0 at 390 nm
    model = _model("sellmeier", B1=1.0, C1=0.16)
    n, dn = model.index_and_derivatives(np.array([390.0, 600.0]), model.values)
    assert np.isnan(n[0]) and np.all(np.isnan(dn[0])) and np.isfinite(n[1]) and np.all(np.isfinite(dn[1]))
