"""Helpers of the fitting tests: spectra by tmm and measurement files written from them."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

tmm = pytest.importorskip("tmm")

from thinfilm_mi.materials import refractive_index

SIGMA = 0.002
#: 380-800 nm every 10 nm: 43 points a spectrum, four spectra, enough to fix 7 films
WL = np.arange(380.0, 801.0, 10.0)
#: (quantity, angle, polarization) of the issue's measurements: R at 0° and at 45° s and p, T at 0°
SPECTRA = {"R0": ("R", 0.0, "s"), "T0": ("T", 0.0, "s"), "R45s": ("R", 45.0, "s"), "R45p": ("R", 45.0, "p")}


def coherent_spectra(specs, d, substrate="BK7", wl=WL, which=SPECTRA, index=None):
    """{name: R or T} by tmm.coh_tmm (normal incidence: s and p are the same)."""
    nk = [np.ones(wl.size)] + (index or [refractive_index(s, wl) for s in specs]) + \
        [refractive_index(substrate, wl)]
    dl = [np.inf] + list(d) + [np.inf]
    out = {}
    for name, (q, angle, pol) in which.items():
        out[name] = np.array([tmm.coh_tmm(pol, [x[i] for x in nk], dl, math.radians(angle), lam)[q]
                              for i, lam in enumerate(wl)])
    return out


def write_spectrum(folder: Path, name: str, wl, value, sigma=None) -> str:
    path = folder / f"{name}.csv"
    cols = np.c_[wl, value] if sigma is None else np.c_[wl, value, np.full(wl.size, sigma)]
    np.savetxt(path, cols, delimiter=",", header="wavelength,value" + (",sigma" if sigma else ""), comments="")
    return str(path)


def measurement_files(folder, spectra, rng, sigma=SIGMA, which=SPECTRA, wl=WL, tag=""):
    out = []
    for name, (q, angle, pol) in which.items():
        v = spectra[name] + sigma * rng.standard_normal(wl.size)
        out.append({"file": write_spectrum(folder, tag + name, wl, v), "quantity": q, "angle": angle,
                    "polarization": pol, "sigma": sigma})
    return out
