"""The fit's model (thinfilm_mi/design/fitmodel.py): its Jacobian against finite
differences for every parameter kind (bandwidth, cone and back side included), and the
instrument's quadratures against fine sums of the same model."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tests.support.fit import write_spectrum
from thinfilm_mi.design import load_measurements
from thinfilm_mi.design.fitfile import DATA_SCALE, DISPERSION, THICKNESS
from thinfilm_mi.design.fitmodel import FitModel

GRADIENT_DOC = """
substrate: "1.5+0.00001j"
substrate_thickness_mm: 0.5
thickness: each
layers: "H 80; L 120; TiO2 40; Ag 12; K 60"
materials:
  H: {model: cauchy, A: 2.1, B: 0.02, C: 0.001, free: [A, B, C]}
  L: {model: sellmeier, B1: 1.1, C1: 0.01, free: [B1, C1]}
  TiO2: {model: catalogue, material: TiO2, shift: 0.01, scale: 0.98, free: [shift, scale]}
  K: {model: constant, n: 1.7, k: 0.05, free: [n, k]}
instrument: {bandwidth_nm: 4.0, cone_half_angle: 6.0}
data:
  - {file: a.csv, quantity: R, angle: 0, sigma: 0.01}
  - {file: b.csv, quantity: T, angle: 30, polarization: p, scale: free, sigma: 0.01}
  - {file: c.csv, quantity: R, polarization: s}
"""


def _gradient_files(folder: Path):
    wl = np.arange(420.0, 761.0, 20.0)
    for name in ("a", "b"):
        write_spectrum(folder, name, wl, np.full(wl.size, 0.3))
    with open(folder / "c.csv", "w") as f:          # several angles in one file, with sigma
        f.write("angle,wavelength,value,sigma\n")
        for a in (10.0, 60.0):
            for w in wl:
                f.write(f"{a},{w},0.2,0.01\n")


@pytest.mark.parametrize("thickness", ["each", "scale"])
def test_jacobian_matches_finite_differences(tmp_path, thickness):
    """Issue 43, check 4: every parameter kind, with bandwidth, cone and back side."""
    _gradient_files(tmp_path)
    (tmp_path / "m.yml").write_text(GRADIENT_DOC.replace("thickness: each", f"thickness: {thickness}"))
    model = FitModel(load_measurements(tmp_path / "m.yml"))
    x = model.x0 * (1 + 0.01 * np.arange(model.x0.size) / model.x0.size)
    e, J = model.residuals(x)
    assert J.shape == (e.size, x.size) and np.all(np.isfinite(J))
    for k, p in enumerate(model.m.parameters):
        h = 1e-6 * max(abs(x[k]), 1e-2)
        up, down = x.copy(), x.copy()
        up[k] += h
        down[k] -= h
        fd = (model.residuals(up, False)[0] - model.residuals(down, False)[0]) / (2 * h)
        # central differences of step 1e-6 relative: truncation ~h^2 |e'''| and rounding
        # ~1e-16 |e| / h stay below 1e-6 of the column's scale
        scale = np.max(np.abs(J[:, k]))
        assert scale > 0, p.name
        np.testing.assert_allclose(J[:, k], fd, rtol=0, atol=1e-6 * scale, err_msg=p.name)
    # the model's column groups follow each parameter's kind
    kinds = {k.name: [i for i, p in enumerate(model.m.parameters) if p.kind is k]
             for k in (THICKNESS, DISPERSION, DATA_SCALE)}
    assert kinds["thickness"] == model.thick_cols and kinds["thickness"]
    assert sorted(model.disp_cols.values()) == kinds["dispersion"] and kinds["dispersion"]
    assert sorted(model.scale_cols.values()) == kinds["data_scale"] and kinds["data_scale"]


def test_instrument_quadratures_match_brute_force(tmp_path):
    """The bandwidth's Gauss-Hermite nodes and the cone's rings against fine sums of the same model."""

    def model(wl, angles, bandwidth=0.0, cone=0.0):
        with open(tmp_path / "p.csv", "w") as f:
            f.write("wavelength,angle,value\n" + "".join(f"{w},{a},0\n" for w, a in zip(wl, angles)))
        doc = {"substrate": 1.52, "layers": "2.3 150; 1.46 200; 2.3 150", "data": [{"file": "p.csv",
               "quantity": "R"}], "instrument": {"bandwidth_nm": bandwidth, "cone_half_angle": cone}}
        m = load_measurements({**doc, "data": [{**doc["data"][0], "file": str(tmp_path / "p.csv")}]})
        fm = FitModel(m)
        return fm.predict(fm.x0, jac=False)[0][0]

    wl = np.arange(450.0, 651.0, 25.0)
    fwhm = 6.0
    s = fwhm / (2 * math.sqrt(2 * math.log(2)))
    u = np.linspace(-5 * s, 5 * s, 401)
    g = np.exp(-0.5 * (u / s) ** 2)
    fine = model((wl[:, None] + u).ravel(), np.full(wl.size * u.size, 30.0)).reshape(wl.size, u.size)
    # 7 Gauss-Hermite nodes against 401 points over ±5σ: R is smooth on the scale of 6 nm here
    np.testing.assert_allclose(model(wl, np.full(wl.size, 30.0), bandwidth=fwhm), fine @ g / g.sum(), atol=2e-5)
    half = 8.0
    psi = np.radians(np.linspace(0.0, half, 41))
    phi = np.linspace(0.0, 2 * math.pi, 61)[:-1]
    P, F = np.meshgrid(psi, phi, indexing="ij")
    t0 = math.radians(30.0)
    theta = np.degrees(np.arccos(math.cos(t0) * np.cos(P) + math.sin(t0) * np.sin(P) * np.cos(F))).ravel()
    w = (np.sin(P) * np.gradient(psi)[:, None]).ravel()         # the solid angle of each (psi, phi) cell
    fine = model(np.tile(wl, theta.size), np.repeat(theta, wl.size)).reshape(theta.size, wl.size)
    # 3 rings x 4 azimuths against a 41 x 60 grid over the cone (whose own error is ~1e-4)
    np.testing.assert_allclose(model(wl, np.full(wl.size, 30.0), cone=half), w @ fine / w.sum(), atol=5e-4)


def test_chi2_of_many_stacks_matches_the_residuals(tmp_path):
    """FitModel.chi2 (S stacks at once, by fitmodel.powers) against the residuals of each stack
    alone (by matrices.stack_response), with bandwidth, cone, back side, dispersion and a free
    scale; and powers against stack_response for absorbing films at a steep angle, s and p, lit
    from either side."""
    from thinfilm_mi.design.fitmodel import film_matrix, powers
    from thinfilm_mi.design.matrices import stack_response
    from thinfilm_mi.optics.polarization import P, S

    _gradient_files(tmp_path)
    (tmp_path / "m.yml").write_text(GRADIENT_DOC)
    model = FitModel(load_measurements(tmp_path / "m.yml"))
    x = model.x0
    D = model.thicknesses(x)[0][:, None] * np.random.default_rng(0).uniform(0.6, 1.4, (5, 7))
    each = [model.residuals(np.r_[D[:, i], x[5:]])[0] for i in range(7)]     # with jac: by stack_response
    assert model.thick_cols == [0, 1, 2, 3, 4]
    # the same R and T by two products of the same matrices, summed in another order: rounding only
    np.testing.assert_allclose(model.chi2(x, D), [e @ e for e in each], rtol=1e-12)
    wl = np.linspace(400.0, 800.0, 9)[:, None]
    films = [np.full(wl.shape, n) for n in (2.3 + 0.05j, 1.46 + 0j, 0.2 + 3.0j)]
    d = [np.array([50.0, 120.0]), np.array([200.0, 90.0]), np.array([15.0, 30.0])]
    n_in, n_out, beta2 = np.ones(wl.shape), np.full(wl.shape, 1.52 + 1e-4j), np.full(wl.shape, 0.7)
    for pol in (S, P):
        m11, m12, m21, m22 = film_matrix(films, d, wl, beta2, pol)
        # both sides from one product: the reverse order swaps its diagonal
        for a, b in ((powers((m11, m12, m21, m22), n_in, n_out, beta2, pol),
                      stack_response(n_in, n_out, films, d, wl, beta2, pol, derivatives=False)),
                     (powers((m22, m12, m21, m11), n_out.real, n_in + 0j, beta2, pol),
                      stack_response(n_out.real, n_in + 0j, films[::-1], d[::-1], wl, beta2, pol, derivatives=False))):
            assert a.R.shape == (9, 2)
            np.testing.assert_allclose(a.R, b.R, atol=1e-14)
            np.testing.assert_allclose(a.T, b.T, atol=1e-14)
