"""The table over the thickness scale (thinfilm_mi/tabulate/diffuse_scale.py) against the
terms computed directly at scales between its nodes."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")

import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from tests.support.bsdf import WAVELENGTHS as WL
from tests.support.bsdf import direction, make_si


def test_scale_table_against_direct_terms():
    """The table over the scale (linear in s, within SCALE_ABS at the check) against
    the terms computed at scales between its nodes."""
    from thinfilm_mi.tabulate.diffuse_scale import SCALE_ABS
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                      "thickness": {"type": "checkerboard", "color0": 0.2, "color1": 1.4}})
    table = b.terms.table
    assert table.s_max == pytest.approx(1.4, rel=1e-6)
    s = np.array([0.37, 0.91, 1.33])
    n = s.size
    si = make_si(n, direction(0.0))
    r, t, _ = table.lookup(si.wavelengths, mi.Float(s))
    from thinfilm_mi.render.diffuse_exact import ExactFactors
    R, T = ExactFactors(b.coating).hemispherical_scales(np.array(WL), s)
    np.testing.assert_allclose(np.array(r), R.T, atol=SCALE_ABS / 2 + 1e-6)
    np.testing.assert_allclose(np.array(t), T.T, atol=SCALE_ABS / 2 + 1e-6)
