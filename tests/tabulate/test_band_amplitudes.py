"""The first level's amplitudes (thinfilm_mi/tabulate/band_amplitudes.py): the resonance
search (``near_zeros``), the exact reflectance, and the range of the amplitudes at any
depth."""
import math

import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.band import resonant_side
from tests.support.stacks import benchmark_layers
from thinfilm_mi.render import kernel as K
from thinfilm_mi.tabulate import band_amplitudes
from thinfilm_mi.tabulate import base as tabulate_base
from thinfilm_mi.tabulate import exact as tables

pytestmark = pytest.mark.usefixtures("llvm")


def test_near_zeros_finds_a_narrow_pole():
    """A zero 0.01 sample steps off the axis, between samples of a smooth function,
    is found at its position and distance (the resonance search of the first
    level); a zero farther than RESOLVE_DISTANCE is not reported."""
    x = np.arange(40.0)
    for z0, found in ((17.3 + 0.01j, True), (25.6 - 0.4j, True), (10.2 + 9.0j, False)):
        f = (x - z0) * (1.0 + 0.02 * x)
        samples = np.stack([f.real, f.imag], axis=-1)[None]
        r, pos, dist = band_amplitudes.near_zeros(samples, 0)
        assert (r.size == 1) == found
        if found:
            assert abs(pos[0] - z0.real) < 1e-6 and abs(dist[0] - abs(z0.imag)) < 1e-6


def test_amplitudes_give_the_exact_reflectance(monkeypatch):
    """The first level's amplitudes (no resonant denominator) give R = |N|^2/|D|^2
    of the float64 Stack to the rounding of the inputs (measured 1.4e-8: the
    kernel's indices and thicknesses are float32 spectra and values; a wrong
    phase, sign or admittance errs by 1e-2 or more)."""
    side = resonant_side(monkeypatch, films=10)
    wl = np.linspace(400.0, 700.0, 301)
    cos = np.full(wl.size, 0.8)
    terms, _ = band_amplitudes.amplitudes(side, cos, np.arange(wl.size), wl, tabulate_base.side_indices(side, wl))
    R = band_amplitudes.powers_of(terms, False)[:, 0]
    layers = [(n(np.array([500.0]))[0].real, d) for n, d in side.films]
    ref = tf.Stack(layers=layers, substrate=complex(1.2, 7.0), ambient=1.0).rt(wl, math.acos(0.8)).R
    assert np.max(np.abs(R - ref)) < 1e-7


def test_near_zeros_with_exponents_match_the_unscaled_function():
    """The loop's power-of-two rescaling (samples ``f 2^E``, random exponents per
    sample) finds the same zeros, bit for bit, as the unscaled samples: the
    neighbours and the cubic are scaled by exact powers of two."""
    x = np.arange(60.0)
    f = (x - (31.3 + 0.02j)) * (x - (12.6 - 0.5j)) * (1.0 + 0.02 * x)
    E = np.random.default_rng(1).integers(-40, 40, x.size).astype(np.float64)
    plain = np.stack([f.real, f.imag], axis=-1)[None]
    scaled = np.stack([np.ldexp(f.real, -E.astype(int)), np.ldexp(f.imag, -E.astype(int))], axis=-1)[None]
    for a, b in zip(band_amplitudes.near_zeros(plain, 0), band_amplitudes.near_zeros(scaled, 0, E[None])):
        assert np.array_equal(a, b)
    assert band_amplitudes.near_zeros(plain, 0)[0].size == 2


def test_amplitudes_stay_in_range_at_any_depth(monkeypatch):
    """1000 films (MAX_FILMS; the amplitudes grow by up to ~2.8 per film, beyond
    float64's range for their squares from ~340 films without the rescaling, which
    is active here: exponents of hundreds): R = |N|^2/|D|^2 from the rescaled
    amplitudes matches the build's exact float64 evaluation (measured 7e-14; a lost
    exponent or an overflow errs by O(1) or gives NaN)."""
    captured = {}

    def capture(side, *args, **kwargs):
        captured["side"] = side

    monkeypatch.setattr(tables, "build_table", capture)
    layers = benchmark_layers(1000)
    K.TABLE_CACHE.clear()
    with pytest.warns(UserWarning):
        mi.load_dict({"type": "thinfilm_conductor", "eta": 1.2, "k": 7.0, "layers": layers,
                      "ext_ior": 1.0, "tabulate": True, "spectral_resolution": 0.0})
    K.TABLE_CACHE.clear()
    side = captured["side"]
    wl = np.linspace(400.0, 700.0, 301)
    cos = np.tile([1.0, 0.3], wl.size)
    rows = np.repeat(np.arange(wl.size), 2)
    idx = tabulate_base.side_indices(side, wl)
    terms, E = band_amplitudes.amplitudes(side, cos, rows, wl, idx)
    assert E.min() > 100.0
    R = band_amplitudes.powers_of(terms, False)[:, 0]
    ref = tabulate_base.evaluate_side(side, cos, rows, wl, idx)[:, 0]
    assert np.all(np.isfinite(R)) and np.max(np.abs(R - ref)) < 1e-10
