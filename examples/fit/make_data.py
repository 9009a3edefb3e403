"""Write the example's "measured" spectra (examples/fit/*.csv) with tmm, independently of thinfilm_mi's optics.

    .venv/bin/python examples/fit/make_data.py

The stack as built: Cauchy high-index films (A = 2.25, B = 0.03 µm²) and SiO2,
14.2 / 33.5 / 118 / 93.7 nm from the air side, on 1 mm BK7 whose back side
counts (tmm's ``inc_tmm``). Each spectrum is averaged over a Gaussian slit of
2 nm FWHM (21 wavelengths over ±3σ) and carries noise of σ 0.002 (seed 43); the
45° reflectance is read 2 % low, as a spectrophotometer baseline may be. The
nominal stack the measurements file starts from is 15 / 30 / 120 / 90 nm with
A = 2.2, B = 0.02.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import tmm

from thinfilm_mi.materials import refractive_index

HERE = Path(__file__).resolve().parent
WL = np.arange(400.0, 801.0, 2.0)
FWHM, SIGMA = 2.0, 0.002
A, B = 2.25, 0.03
D = [14.2, 33.5, 118.0, 93.7]
#: file: (quantity, angle, polarisations averaged, scale)
SPECTRA = {"r8.csv": ("R", 8.0, ("s", "p"), 1.0), "t0.csv": ("T", 0.0, ("s",), 1.0),
           "r45s.csv": ("R", 45.0, ("s",), 0.98)}


def value(q: str, angle: float, pols, lam: float) -> float:
    h = A + B / (lam * 1e-3) ** 2
    sio2 = complex(refractive_index("SiO2", lam))
    bk7 = complex(refractive_index("BK7", lam))
    n = [1.0, h, sio2, h, sio2, bk7, 1.0]
    d = [np.inf] + D + [1e6, np.inf]
    c = ["i", "c", "c", "c", "c", "i", "i"]
    return float(np.mean([tmm.inc_tmm(p, n, d, c, math.radians(angle), lam)[q] for p in pols]))


def main() -> None:
    rng = np.random.default_rng(43)
    s = FWHM / (2.0 * math.sqrt(2.0 * math.log(2.0)))
    u = np.linspace(-3.0 * s, 3.0 * s, 21)
    g = np.exp(-0.5 * (u / s) ** 2)
    g /= g.sum()
    for name, (q, angle, pols, scale) in SPECTRA.items():
        v = np.array([g @ [value(q, angle, pols, lam + du) for du in u] for lam in WL])
        v = scale * v + SIGMA * rng.standard_normal(WL.size)
        with open(HERE / name, "w") as f:
            f.write(f"# {q} at {angle:g} deg, made by examples/fit/make_data.py with tmm.inc_tmm\n")
            f.write("wavelength,value\n")
            f.writelines(f"{w:g},{x:.6f}\n" for w, x in zip(WL, v))


if __name__ == "__main__":
    main()
