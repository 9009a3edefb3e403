"""Helpers of the design tests: tmm's R and T of a layers string, colour-science's colour
of a spectrum, numeric layers, the kinds of targets, the issue's AR target."""
from __future__ import annotations

import colour
import numpy as np
import tmm

from tests.support import ROOT
from thinfilm_mi import parse_layers
from thinfilm_mi.colour.report import integration_wavelengths

REPO = ROOT
AR = REPO / "examples" / "design" / "ar.yml"


# ---------------------------------------------------------------------------
# independent references
# ---------------------------------------------------------------------------
def tmm_rt(layers, substrate, ambient, wavelengths, angle_deg, pol="unpolarized", side="front"):
    """R and T with tmm's coh_tmm; ``layers`` as [(index, nm)], indices numbers."""
    n = [complex(ambient)] + [complex(m) for m, _ in layers] + [complex(substrate)]
    d = [np.inf] + [float(t) for _, t in layers] + [np.inf]
    if side == "back":
        n, d = n[::-1], d[::-1]
    pols = ("s", "p") if pol == "unpolarized" else (pol,)
    R, T = np.zeros(len(wavelengths)), np.zeros(len(wavelengths))
    for i, w in enumerate(wavelengths):
        for p in pols:
            out = tmm.coh_tmm(p, n, d, np.radians(angle_deg), float(w))
            R[i] += out["R"] / len(pols)
            T[i] += out["T"] / len(pols)
    return R, T


def cs_colour(spectrum, illuminant="D65", observer=2):
    """XYZ (Y = 1 for the white), xy and L*a*b* of a spectrum on the 1 nm
    integration grid, straight from colour-science."""
    obs = {2: "CIE 1931 2 Degree Standard Observer", 10: "CIE 1964 10 Degree Standard Observer"}[observer]
    wl = integration_wavelengths(illuminant)
    shape = colour.SpectralShape(wl[0], wl[-1], 1)
    cmfs = colour.MSDS_CMFS[obs].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS[{"D65": "D65", "A": "A"}[illuminant]].copy().align(shape)
    XYZ = colour.sd_to_XYZ(colour.SpectralDistribution(spectrum, wl), cmfs, ill, method="Integration") / 100
    white = colour.sd_to_XYZ(colour.SpectralDistribution(np.ones(wl.size), wl), cmfs, ill,
                             method="Integration") / 100
    return XYZ, colour.XYZ_to_xy(XYZ), colour.XYZ_to_Lab(XYZ, colour.XYZ_to_xy(white))


def numeric_layers(text):
    return [(complex(m.replace("i", "j")), d) for m, d in parse_layers(text)]


def labs(films, angles):
    """L*a*b* (colour-science, D65, 2°) of the reflectance (tmm) of ``films`` on glass of
    1.52 in air, at each of ``angles`` (degrees)."""
    wl = integration_wavelengths("D65")
    return np.array([cs_colour(tmm_rt(films, 1.52, 1.0, wl, a)[0])[2] for a in angles])


#: Every kind of target: R, T (back side, p), A (s) with an absorbing film,
#: colour as Lab and as xy (back side, T, illuminant A, 10° observer), Y with
#: a kind, and a free index.
ALL_KINDS = {
    "ambient": 1.0, "substrate": "1.52",
    "materials": ["1.38", {"index": "2.35+0.01j", "free": True}, "0.2+3.2j"],
    "targets": [
        {"quantity": "R", "wavelengths": "420:680:20", "angles": [0, 30], "value": 0.0, "tolerance": 0.005},
        {"quantity": "T", "wavelengths": "550", "angles": [0, 40], "value": 0.9, "tolerance": 0.01,
         "kind": ">=", "side": "back", "polarization": "p"},
        {"quantity": "colour", "illuminant": "D65", "angles": [0, 45], "Lab": [60, 10, -40], "tolerance": 2.0},
        {"quantity": "colour", "illuminant": "A", "observer": 10, "angles": [20], "xy": [0.3, 0.35],
         "tolerance": 0.01, "of": "T", "side": "back"},
        {"quantity": "Y", "illuminant": "D65", "angles": [0], "value": 0.95, "tolerance": 0.01, "kind": ">=",
         "of": "T"},
        {"quantity": "A", "wavelengths": [450, 500], "angles": 10, "value": 0.1, "tolerance": 0.05,
         "polarization": "s"},
    ]}
ALL_KINDS_FILMS = [0, 1, 2, 1, 0]
ALL_KINDS_D = np.array([90.0, 50.0, 8.0, 120.0, 70.0])
