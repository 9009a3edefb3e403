"""The sheared angle axis (thinfilm_mi/tabulate/shear.py): the shear follows the films,
refuses bad data, and a sheared table of R and T matches a brute-force convolution."""
import math

import mitsuba as mi
import numpy as np
import pytest

from tests.support.stacks import benchmark_layers, benchmark_thicknesses
from thinfilm_mi.render import kernel as K
from thinfilm_mi.tabulate import band as band_tables
from thinfilm_mi.tabulate import band_rows
from thinfilm_mi.tabulate import base as tabulate_base

pytestmark = pytest.mark.usefixtures("llvm")


def test_a_sheared_table_of_r_and_t_matches_a_brute_force_convolution():
    """30 films on glass, lit from the ambient: a band-limited table of ``R`` and ``T``
    on the sheared axis (``tabulate.shear``). Its lookups agree with ``R_σ`` and
    ``T_σ`` convolved by direct summation (measured 4.2e-5 over 25 points, the
    verified error 2.5e-4) within the verified error plus 1e-4 (the float32 texture
    and the brute force's σ/400 steps); an axis sheared the wrong way, or nodes
    sampled at the plain wavenumbers, errs by 1e-2 or more."""
    b = mi.load_dict({"type": "thinfilm_dielectric", "layers": benchmark_layers(30), "int_ior": 1.5,
                      "tabulate": False})
    side = K.side_data(b.stack.plan[False], True)
    table = band_tables.build_band_table(side, 1e-3, K.GRID, tabulate_base.MAX_TEXELS, 1.0)
    assert table is not None and table.shear is not None and table.channels == 2
    sig = band_rows.sigma_nu(1.0)
    for theta in (0.0, 50.0, 75.0):
        cos = math.cos(math.radians(theta))
        for wl in (405.3, 561.2, 781.4):
            nu = 1.0 / wl
            lam = 1.0 / np.arange(nu - 6 * sig, nu + 6 * sig, sig / 400)
            vals = tabulate_base.evaluate_side(side, np.full(lam.size, cos), np.arange(lam.size), lam,
                                               tabulate_base.side_indices(side, lam))
            g = np.exp(-0.5 * ((1.0 / lam - nu) / sig) ** 2)
            ref = (vals * g[:, None]).sum(axis=0) / g.sum()
            got = table.lookup(mi.Float(cos), mi.Spectrum(1.0), mi.Spectrum(1.0), mi.Spectrum(wl))
            got = np.array([float(got[c][0][0]) for c in range(2)])
            np.testing.assert_allclose(got, ref, atol=table.error + 1e-4, rtol=0)


def test_the_shear_follows_the_films_and_refuses_bad_data():
    """``P(s)`` is the films' ``Σ d_j Re sqrt(n_j² - n0² s) / Σ d_j n_j`` within the
    cubic's fit (measured 1.9e-5 for the 2.3/1.46 stack; bound 1e-4), 1 at normal incidence and
    falling to grazing; a stored shear that is not one raises (the table store then
    rebuilds)."""
    from thinfilm_mi.tabulate.shear import Shear

    d = benchmark_thicknesses(30)
    films = [((lambda wl, n=2.3 if i % 2 == 0 else 1.46: np.full(np.shape(wl), n + 0j)), float(d[i]))
             for i in range(30)]
    shear = Shear.of(films, 1.0)
    s = np.linspace(0.0, 1.0, 101)
    n = np.array([2.3 if i % 2 == 0 else 1.46 for i in range(30)])
    want = (d[None, :] * np.sqrt(n[None, :] ** 2 - s[:, None])).sum(1) / (d * n).sum()
    np.testing.assert_allclose(shear.factor_np(s), want, atol=1e-4, rtol=0)
    assert abs(shear.factor_np(0.0) - 1.0) < 1e-4 and np.all(np.diff(shear.factor_np(s)) < 0)
    assert shear.low == pytest.approx(tabulate_base.SIGMA_MIN * shear.factor_np(1.0), rel=1e-3)
    assert Shear.from_plain(shear.to_plain()).coeffs == shear.coeffs
    for bad in ({"coeffs": [1.0, 0.1], "low": 0.001}, {"coeffs": [1.0, float("nan"), 0, 0], "low": 0.001},
                {"coeffs": [1.0, 0, 0, 0], "low": -1.0}):
        with pytest.raises(ValueError):
            Shear.from_plain(bad)
    assert Shear.of([], 1.0) is None
