"""Targets files (thinfilm_mi/design/targets.py): bad targets fail in one error that names
the entry."""
from __future__ import annotations

import pytest

from thinfilm_mi.design import (
    load_problem,
)
from thinfilm_mi.errors import ThinFilmError


# ---------------------------------------------------------------------------
# bad targets files
# ---------------------------------------------------------------------------
def _doc(**change):
    doc = {"substrate": "1.52", "materials": ["1.38", "2.35"],
           "targets": [{"quantity": "R", "wavelengths": "420:680:10", "value": 0, "tolerance": 0.01},
                       {"quantity": "colour", "angles": [0], "Lab": [50, 0, 0], "tolerance": 2}]}
    for key, value in change.items():
        if key.startswith("t1_"):
            doc["targets"][1] = {**doc["targets"][1], key[3:]: value}
        elif key.startswith("t0_"):
            doc["targets"][0] = {**doc["targets"][0], key[3:]: value}
        else:
            doc[key] = value
    return doc


@pytest.mark.parametrize("doc, match", [
    (_doc(t1_quantity="Rx"), r"targets\[1\]: unknown quantity 'Rx'"),
    (_doc(t0_tolerance=-0.01), r"targets\[0\] \(R\): tolerance must be > 0, got -0.01"),
    (_doc(materials=["ITO", "2.35"], t0_wavelengths="900:1200:50"),
     r"targets\[0\] \(R\): wavelength 1200 nm is out of reach: materials\[0\] 'ITO'"),
    (_doc(materials=["1.38", "Unobtainium"]), r"materials\[1\]: unknown material 'Unobtainium'"),
    (_doc(substrate="Unobtainium"), r"substrate: unknown material 'Unobtainium'"),
    (_doc(t0_wavelenghts="400"), r"targets\[0\] \(R\): unknown key 'wavelenghts'"),
    (_doc(t1_tolerance=None) | {"targets": [{"quantity": "Y", "value": 0.5}]},
     r"targets\[0\] \(Y\): missing 'tolerance'"),
    (_doc(t1_angles=[0, 90]), r"targets\[1\] \(colour\): angles: .*got 90"),
    (_doc(t1_kind="<="), r"targets\[1\] \(colour\): kind: colour targets are '=' only"),
    (_doc(t0_value=1.5), r"targets\[0\] \(R\): value must be a fraction in \[0, 1\], got 1.5"),
    (_doc(substrate="Au", t0_side="back"), r"targets\[0\] \(R\): side: back .* the substrate Au absorbs"),
    (_doc(materials=[{"index": "SiO2", "free": True}]), r"materials\[0\]: free: only a numeric index"),
    (_doc(start="1.38 100; 2.35 20; 1.38 50", max_layers=2), r"start: 3 films, more than max_layers = 2"),
    (_doc(t0_wavelengths="680:420:5"), r"targets\[0\] \(R\): wavelengths '680:420:5': need STOP >= START"),
    (_doc(colour=1), r"colour: unknown key"),
    (_doc(t1_illuminant="D99"), r"targets\[1\] \(colour\): illuminant: unknown illuminant 'D99'"),
])


def test_bad_targets_name_the_entry(doc, match):
    with pytest.raises(ThinFilmError, match=match):
        load_problem(doc)
