"""A resonant 10-film side and the brute-force fine-grid convolution ``R_σ`` that the
band-limited tables are checked against (tests/tabulate/)."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

from tests.support.stacks import benchmark_layers
from thinfilm_mi.render import kernel as K
from thinfilm_mi.tabulate import base as tabulate_base
from thinfilm_mi.tabulate import exact as tables


def resonant_side(monkeypatch, films=10):
    """The ambient side of a resonant stack (2.3/1.46 films on a constant metal):
    the SideData the kernel hands to the build (captured; spectral_resolution 0, so
    the build only tries, and fails, a table of the exact values)."""
    layers = benchmark_layers(films)
    captured = {}
    build = tables.build_table

    def capture(side, *args, **kwargs):
        captured["side"] = side
        return build(side, *args, **kwargs)

    monkeypatch.setattr(tables, "build_table", capture)
    K.TABLE_CACHE.clear()
    with pytest.warns(UserWarning):
        mi.load_dict({"type": "thinfilm_conductor", "eta": 1.2, "k": 7.0, "layers": layers,
                      "ext_ior": 1.0, "tabulate": True, "spectral_resolution": 0.0})
    K.TABLE_CACHE.clear()
    return captured["side"]


def brute_force(side, cos, nu_out, sigma_nu, step=0.0005):
    """R at one angle convolved by direct summation with the Gaussian in wavenumber,
    on a grid of ``step`` nm (exact R of the build's float64 evaluator)."""
    out = []
    for nu in nu_out:
        half = 7.0 * sigma_nu
        lam = np.arange(1.0 / (nu + half), 1.0 / (nu - half), step)
        R = tabulate_base.evaluate_side(side, np.full(lam.size, cos), np.arange(lam.size), lam,
                             tabulate_base.side_indices(side, lam))[:, 0]
        x = 1.0 / lam
        g = np.exp(-0.5 * ((x - nu) / sigma_nu) ** 2) * x * x   # dν = dλ / λ²
        out.append(float(np.sum(R * g) / np.sum(g)))
    return np.array(out)
