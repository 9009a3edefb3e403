"""Write thinfilm_mi/data/colour_weights.csv: the CIE 1931 2-degree colour-matching
functions and the illuminants D65, A and F11 on a 1 nm grid over 360-830 nm, from
colour-science (``colour.MSDS_CMFS``, ``colour.SDS_ILLUMINANTS``).

Table builds (``thinfilm_mi.tabulate.exact``) check the colour error of a band-limited
table against the exact reflectance under these illuminants. They read this file
instead of importing colour-science, whose import takes ~1.6 s (once per process,
at the first table build: the first image). tests/colour/test_cie.py checks the file
against colour-science.

    python scripts/make_colour_weights.py
"""
import os

import colour
import numpy as np

OUT = os.path.join(os.path.dirname(__file__), "..", "thinfilm_mi", "data", "colour_weights.csv")
ILLUMINANTS = ("D65", "A", "FL11")


def weights() -> np.ndarray:
    """Columns: wavelength (nm), xbar, ybar, zbar, D65, A, F11 (relative power;
    illuminants interpolated onto the grid and held constant beyond their data, as
    colour-science aligns them)."""
    shape = colour.SpectralShape(360, 830, 1)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    cols = [cmfs.wavelengths, *cmfs.values.T]
    for name in ILLUMINANTS:
        cols.append(colour.SDS_ILLUMINANTS[name].copy().align(shape).values)
    return np.stack(cols, axis=1)


if __name__ == "__main__":
    np.savetxt(OUT, weights(), fmt="%.8g", delimiter=",",
               header="wavelength_nm,xbar,ybar,zbar,D65,A,F11 (CIE 1931 2 deg; colour-science "
                      + colour.__version__ + ", scripts/make_colour_weights.py)")
    print("wrote", os.path.normpath(OUT))
