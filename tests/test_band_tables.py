"""Band-limited tables (``spectral_resolution``): the convolved reflectance ``R_σ``
against a brute-force fine-grid convolution, the colour check's data and colour
difference against colour-science, and the option's validation."""
import math

import numpy as np
import pytest

import mitsuba as mi

import thinfilm_mi as tf
from thinfilm_mi import kernel as K
from thinfilm_mi import tables


@pytest.fixture(autouse=True)
def llvm():
    mi.set_variant("llvm_ad_spectral")


def _resonant_side(monkeypatch, films=10):
    """The ambient side of a resonant stack (2.3/1.46 films on a constant metal):
    the SideData the kernel hands to the build (captured; spectral_resolution 0, so
    the build only tries, and fails, a table of the exact values)."""
    d = np.random.default_rng(6).uniform(50.0, 200.0, films)
    layers = "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(films))
    captured = {}
    build = tables.build_table

    def capture(side, *args, **kwargs):
        captured["side"] = side
        return build(side, *args, **kwargs)

    monkeypatch.setattr(tables, "build_table", capture)
    K._TABLE_CACHE.clear()
    with pytest.warns(UserWarning):
        mi.load_dict({"type": "thinfilm_conductor", "eta": 1.2, "k": 7.0, "layers": layers,
                      "ext_ior": 1.0, "tabulate": True, "spectral_resolution": 0.0})
    K._TABLE_CACHE.clear()
    return captured["side"]


def test_band_limited_values_match_a_brute_force_convolution(monkeypatch):
    """R_σ at a few (angle, wavelength) points against the exact R of the same
    evaluator on a 0.001 nm grid, convolved by direct summation. The stack has
    resonances ~0.1 nm wide and narrower (R drops by up to 0.3 within them), far
    below the build's coarse step (~0.4 nm). Measured difference <= 5e-6 (30
    films, 30 points); the tolerance 3e-5 is 30x below the default table_error,
    and a build that missed a resonance or misplaced its area errs by 1e-3."""
    sigma = 1.0
    side = _resonant_side(monkeypatch)
    pts = tables._BandPoints(side, "plain", sigma)
    s = np.array([0.0, 60.0, 85.0])          # u nodes of a 101-node axis
    t = np.array([300.0, 340.0, 380.0])      # v nodes of a 600-node axis
    pts.add(s, t, 101, 600)
    ((vals, cos),) = pts.evaluate()
    assert pts.exact_points > 0   # resonances were met and integrated on exact values
    wl_out = tables._v_nodes_wl(t, 600)
    worst = 0.0
    for j in range(s.size):
        for i, lo in enumerate(wl_out):
            x = np.arange(lo - 7.0 * sigma, lo + 7.0 * sigma, 0.001)
            idx = tables._indices(side, x)
            R = tables._powers_of(tables._smooth_terms(side, np.full(x.size, cos[i, j]),
                                                       np.arange(x.size), x, idx), False)[:, 0]
            g = np.exp(-0.5 * ((x - lo) / sigma) ** 2)
            worst = max(worst, abs(vals[i, j, 0] - float(np.sum(R * g) / np.sum(g))))
    assert worst <= 3e-5, worst


def test_smooth_terms_give_the_exact_reflectance(monkeypatch):
    """The build's amplitudes (no resonant denominator) give R = |N|^2/|D|^2 of the
    float64 Stack to the rounding of the inputs (measured 1.4e-8: the kernel's
    indices and thicknesses are float32 spectra and values; a wrong phase, sign or
    admittance errs by 1e-2 or more)."""
    side = _resonant_side(monkeypatch, films=10)
    wl = np.linspace(400.0, 700.0, 301)
    cos = np.full(wl.size, 0.8)
    R = tables._powers_of(tables._smooth_terms(side, cos, np.arange(wl.size), wl,
                                               tables._indices(side, wl)), False)[:, 0]
    layers = [(n(np.array([500.0]))[0].real, d) for n, d in side.films]
    ref = tf.Stack(layers=layers, substrate=complex(1.2, 7.0), ambient=1.0).rt(wl, math.acos(0.8)).R
    assert np.max(np.abs(R - ref)) < 1e-7


def test_colour_weights_match_colour_science():
    colour = pytest.importorskip("colour")
    import importlib.util
    import pathlib
    path = pathlib.Path(__file__).parent.parent / "scripts" / "make_colour_weights.py"
    spec = importlib.util.spec_from_file_location("make_colour_weights", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    # the CSV holds 8 significant digits
    np.testing.assert_allclose(tables.colour_weights(), mod.weights(), rtol=1e-7, atol=1e-12)
    assert colour is not None


def test_delta_e2000_matches_colour_science():
    colour = pytest.importorskip("colour")
    rng = np.random.default_rng(3)
    lab1 = rng.uniform([0, -80, -80], [100, 80, 80], (500, 3))
    lab2 = lab1 + rng.normal(0.0, 3.0, (500, 3))
    ours = tables.delta_e2000(lab1, lab2)
    np.testing.assert_allclose(ours, colour.delta_E(lab1, lab2, method="CIE 2000"),
                               rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("value", [-1.0, float("nan"), float("inf"), 21.0, "1", True])
def test_bad_spectral_resolution_is_refused(value):
    with pytest.raises((tf.ThinFilmError, RuntimeError), match="spectral_resolution"):
        mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 300",
                      "spectral_resolution": value})
