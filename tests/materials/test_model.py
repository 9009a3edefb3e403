"""The uniform resampling of datasets (thinfilm_mi/materials/model.py,
``DispersiveMaterial.uniform_resampling``): every named material that renders is held
within ``RESAMPLE_TOL`` of its own interpolation, and the materials guide states the
grid and the deviation of each.

The reference is the dataset's own interpolation (``Material.index``: numpy's linear
interpolation of the file's rows, or the formula), probed independently of the fit's
own probe: at the data's knots, where the difference of two piecewise-linear functions
peaks, and at seeded random wavelengths, where a formula's curvature shows.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from thinfilm_mi.materials import catalog
from thinfilm_mi.materials.model import RESAMPLE_STEPS, RESAMPLE_TOL, SPECTRAL_RANGE

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guides" / "materials.md"


def _rendering_datasets():
    return [mat for _, mat in catalog.rendering_materials() if mat.constant is None]


def test_every_resampled_material_stays_within_the_bound():
    lo, hi = SPECTRAL_RANGE
    rng = np.random.default_rng(53)
    resampled = 0
    for mat in _rendering_datasets():
        fit = mat.uniform_resampling()
        if fit is None:
            continue
        resampled += 1
        assert fit.step in RESAMPLE_STEPS
        knots = mat.knots()
        probe = np.concatenate([knots[(knots >= lo) & (knots <= hi)], rng.uniform(lo, hi, 20000)])
        exact = mat.index(probe)
        got = np.interp(probe, fit.grid, fit.values.real) + 1j * np.interp(probe, fit.grid,
                                                                           fit.values.imag)
        # float64 throughout: the bound itself, nothing added
        assert np.abs(got.real - exact.real).max() <= RESAMPLE_TOL, mat.name
        assert np.abs(got.imag - exact.imag).max() <= RESAMPLE_TOL, mat.name
        # the stated deviation is what this probe finds, up to where the probes differ
        assert np.abs(got.real - exact.real).max() <= fit.deviation[0] * 1.05 + 1e-12, mat.name
    # every named default dataset is resampled (none of them needs its own knots)
    assert resampled >= 21


def test_the_coarsest_grid_that_meets_the_bound_is_chosen():
    # Au's Johnson & Christy rows are ~20 nm apart with slope jumps of ~0.01/nm: a
    # kink between two grid nodes is cut by up to |jump| * step / 4, so a 1 nm grid
    # misses it by ~1e-3 and only a fine one holds it
    fit = catalog.resolve("Au").uniform_resampling()
    coarser = fit.step * 2
    grid = np.arange(SPECTRAL_RANGE[0], SPECTRAL_RANGE[1] + 1e-9, coarser)
    mat = catalog.resolve("Au")
    knots = mat.knots()
    v = mat.index(grid)
    dev = np.abs(np.interp(knots[(knots > 360) & (knots < 830)], grid, v.real)
                 - mat.index(knots[(knots > 360) & (knots < 830)]).real).max()
    assert dev > RESAMPLE_TOL
    assert catalog.resolve("SiO2").uniform_resampling().step == 1.0


def test_the_guide_states_each_materials_grid_and_deviation():
    text = GUIDE.read_text()
    m = re.search(r"<!-- resampling table: start -->\n(.*?)\n<!-- resampling table: end -->", text,
                  re.S)
    assert m, "docs/guides/materials.md lacks its resampling table"
    assert m.group(1).strip() == catalog.format_resampling_table().strip(), (
        "the guide's table is stale: python benchmarks/resampling_table.py --write")
