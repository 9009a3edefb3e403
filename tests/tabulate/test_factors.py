"""The coated-diffuse model's factor table in spectral variants (``FactorTable`` in
``thinfilm_mi/tabulate/factors.py``).

Reference: the exact float64 factors (``DiffuseFactors.rt``, the stack's recursion that
tmm is checked against in ``tests/render/layered/test_series.py``) and hemispherical
terms; the kernel's reads must be within ``table_error`` of them (see each test).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")

import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from thinfilm_mi.tabulate import factors as factor_tables  # noqa: E402
from thinfilm_mi.tabulate.base import GRAZING_COS  # noqa: E402


def spectral_coated(layers, model, **extra):
    """The ``CoatedDiffuse`` of a ``thinfilm_diffuse`` loaded in ``llvm_ad_spectral``."""
    mi.set_variant("llvm_ad_spectral")
    return mi.load_dict({"type": "thinfilm_diffuse", "layers": layers, "model": model,
                     **extra}).coated


@pytest.mark.parametrize("layers, model", [
    ("SiO2 500; Au 5", "exact"),      # a band of finer wavelengths towards grazing
    ("SiO2 500; Au 5", "single"),
    ("SiO2 100", "exact"),            # no band
])
def test_factor_table_within_table_error_off_its_checks(layers, model):
    """The kernel's lookup (float32) against the exact float64 factors at random points
    outside the grazing sliver, none of them a node or a check of the build: within
    ``table_error`` (the build's criterion, ``err_u + err_w`` at the midpoints, bounds the
    bilinear error; float32 storage and arithmetic add ~1e-7)."""
    coated = spectral_coated(layers, model)
    table = coated.table
    assert table is not None, "expected a table for this stack"
    factors = coated.factors()
    rng = np.random.default_rng(3)
    n = 20000
    cos = rng.uniform(GRAZING_COS, 1.0, n)
    wl = rng.uniform(360.0, 830.0, (n, 4))
    cells = table.cells(mi.Spectrum(*(mi.Float(w) for w in wl.T)))
    k_r, t, _, _ = table.lookup(mi.Float(cos), cells)
    got = np.stack([np.array(k_r).T, np.array(t).T], axis=-1)          # (n, 4, 2)
    want = np.empty_like(got)
    for j in range(4):
        # one wavelength per point: the exact values' diagonal in blocks
        for b in range(0, n, 500):
            R, T = factors.rt(cos[b:b + 500], wl[b:b + 500, j])
            idx = np.arange(min(500, n - b))
            want[b:b + 500, j, 0], want[b:b + 500, j, 1] = R[idx, idx], T[idx, idx]
    err = np.abs(got - want).max()
    assert err <= coated.coating.table_error + 2e-6, (err, table.report)


def test_factor_table_terms_are_the_hemispherical_terms():
    """``R_dh``, ``T_hemi`` read with ``k_r`` and ``t``: the float64 hemispherical terms on
    the 1 nm grid, linear between (as the ``regular`` spectra of ``SpectralTerms``), at
    any angle (inside the band of finer wavelengths too), within float32; and a read of
    ``t`` alone is the full read's ``t``."""
    coated = spectral_coated("SiO2 500; Au 5", "multiple")
    table = coated.table
    assert table.band > 0
    wl = np.array([360.0, 500.5, 612.25, 829.9])
    cells = table.cells(mi.Spectrum(*(mi.Float([w, w]) for w in wl)))
    cos = mi.Float([0.03, 0.8])               # in the band, beyond it
    _, t, r_dh, t_hemi = table.lookup(cos, cells)
    _, t_alone, _, _ = table.lookup(cos, cells, reflectance=False)
    grid = np.arange(360.0, 831.0)
    r_ref, t_ref = coated.factors().hemispherical(grid)
    for got, ref in ((r_dh, r_ref), (t_hemi, t_ref)):
        want = np.interp(wl, grid, ref)
        assert np.allclose(np.array(got), want[:, None], rtol=0, atol=1e-6)
    assert np.array_equal(np.array(t), np.array(t_alone))


def test_factor_table_refused_over_its_floats(monkeypatch):
    """A table that needs more than FACTOR_MAX_FLOATS floats is not built (the report
    says why), and the plugin evaluates the factors exactly."""
    monkeypatch.setattr(factor_tables, "FACTOR_MAX_FLOATS", 2 * 33 * 471 - 1)
    coated = spectral_coated("SiO2 500; Au 5", "exact")
    assert coated.table is None
    factors = coated.factors()
    table = factor_tables.FactorTable(factors.rt, factors.hemispherical, 1e-3)
    assert not table.built and "floats" in table.report["result"]


@pytest.mark.parametrize("extra", [{"tabulate": False}, {"thickness": 0.8}])
def test_factor_table_not_built(extra):
    """No table with ``tabulate=false``, nor under a ``thickness`` texture (the factors
    vary over the surface), nor in RGB variants (the colour tables)."""
    assert spectral_coated("SiO2 500; Au 5", "exact", **extra).table is None
    mi.set_variant("llvm_ad_rgb")
    try:
        rgb = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"}).coated
        assert rgb.table is None and rgb.colour is not None
    finally:
        mi.set_variant("llvm_ad_spectral")
