"""The design API (thinfilm_mi/design/api.py): every value a design reports agrees with
tmm's ``coh_tmm``, for every kind of target."""
from __future__ import annotations

import numpy as np

from tests.support.design import ALL_KINDS, cs_colour, numeric_layers, tmm_rt
from thinfilm_mi.colour.cie import delta_e2000
from thinfilm_mi.colour.report import integration_wavelengths
from thinfilm_mi.design import (
    evaluate,
)


def test_reported_values_agree_with_tmm_for_every_kind_of_target():
    layers = "1.38 90; 2.3+0.01j 50; 0.2+3.2j 8; 2.3+0.01j 120; 1.38 70"
    result = evaluate(ALL_KINDS, layers)
    films = numeric_layers(result.layers)
    for rec, v in zip(result.target_records(), result.values):
        t = v.target
        quantity, pol, side = rec["quantity"], rec["polarization"], rec["side"]    # as the JSON names them
        for a, angle in enumerate(t.angles):
            if quantity in ("R", "T", "A"):
                R, T = tmm_rt(films, 1.52, 1.0, t.wavelengths, angle, pol, side)
                want = {"R": R, "T": T, "A": 1 - R - T}[quantity]
                np.testing.assert_allclose(v.achieved[a], want, atol=1e-10)
            else:
                wl = integration_wavelengths(t.illuminant)
                R, T = tmm_rt(films, 1.52, 1.0, wl, angle, pol, side)
                XYZ, xy, Lab = cs_colour(R if rec["of"] == "R" else T, t.illuminant, t.observer)
                if quantity == "Y":
                    assert abs(v.achieved[a] - XYZ[1]) < 1e-10
                elif rec["space"] == "xy":
                    np.testing.assert_allclose(v.achieved[a], xy, atol=1e-10)
                else:
                    assert delta_e2000(Lab, v.achieved[a]) < 1e-6
                    assert abs(rec["delta_e2000"][a] - delta_e2000(t.reference, Lab)) < 1e-6
