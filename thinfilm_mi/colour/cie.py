"""CIE colour data and colour differences used by the tables and the render kernel.

* :func:`colour_weights`: the CIE 1931 2° colour-matching functions with the D65, A
  and F11 illuminants on a 1 nm grid over 360-830 nm (shipped data, made from
  colour-science by ``scripts/make_colour_weights.py``);
* :func:`channel_weights`, :func:`normalised_weights`: linear sRGB or luminance
  weights under D65 (the convention of Mitsuba's spectral pipeline);
* :func:`lab`, :func:`delta_e2000`, :func:`colour_differences`: CIE L*a*b* and
  CIEDE2000, vectorised over numpy arrays;
* :func:`trapezoid_weights`: the quadrature every colour integral uses.

The colour report for designers (with colour-science) is :mod:`thinfilm_mi.colour.report`.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from thinfilm_mi.optics.choices import choose

__all__ = ["Channels", "CHANNELS", "channel_weights", "colour_differences", "colour_weights", "delta_e2000", "lab",
           "normalised_weights", "trapezoid_weights", "xyz_to_srgb_matrix"]


# -- colour data (the band-limited and colour tables' checks) ------------------------
_COLOUR = None


def colour_weights() -> np.ndarray:
    """Columns wavelength (nm, 360-830 every 1 nm), xbar, ybar, zbar, D65, A, F11
    (thinfilm_mi/data/colour_weights.csv, from colour-science by
    scripts/make_colour_weights.py)."""
    global _COLOUR
    if _COLOUR is None:
        import importlib.resources
        text = importlib.resources.files("thinfilm_mi.data").joinpath("colour_weights.csv")
        _COLOUR = np.loadtxt(str(text), delimiter=",")
    return _COLOUR


def lab(XYZ: np.ndarray, white: np.ndarray) -> np.ndarray:
    """CIE L*a*b* of ``XYZ`` (last axis) relative to ``white``."""
    t = XYZ / white
    d = 6.0 / 29.0
    f = np.where(t > d ** 3, np.cbrt(np.maximum(t, 0.0)), t / (3 * d * d) + 4.0 / 29.0)
    return np.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]),
                     200.0 * (f[..., 1] - f[..., 2])], axis=-1)


def delta_e2000(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    """CIEDE2000 colour difference (Sharma, Wu and Dalal, Color Res. Appl. 30, 2005;
    kL = kC = kH = 1) between L*a*b* arrays (last axis): the package's one CIEDE2000
    of plain numbers (the designer's derivatives use
    :func:`thinfilm_mi.design.colourmath.delta_e2000_residuals`).

    The same formula as colour-science's ``colour.delta_E(..., method="CIE 2000")``,
    equal to it on random and edge-case pairs (tests/colour/test_cie.py), written out
    in numpy because importing colour-science takes ~1.5 s, which a scene load that
    builds a table would pay."""
    L1, a1, b1 = np.moveaxis(lab1, -1, 0)
    L2, a2, b2 = np.moveaxis(lab2, -1, 0)
    Cb = 0.5 * (np.hypot(a1, b1) + np.hypot(a2, b2))
    G = 0.5 * (1.0 - np.sqrt(Cb ** 7 / (Cb ** 7 + 25.0 ** 7)))
    a1p, a2p = (1.0 + G) * a1, (1.0 + G) * a2
    C1p, C2p = np.hypot(a1p, b1), np.hypot(a2p, b2)
    h1p = np.degrees(np.arctan2(b1, a1p)) % 360.0
    h2p = np.degrees(np.arctan2(b2, a2p)) % 360.0
    dLp, dCp = L2 - L1, C2p - C1p
    dh = h2p - h1p
    dh = np.where(dh > 180.0, dh - 360.0, np.where(dh < -180.0, dh + 360.0, dh))
    dh = np.where(C1p * C2p == 0.0, 0.0, dh)
    dHp = 2.0 * np.sqrt(C1p * C2p) * np.sin(np.radians(dh / 2.0))
    Lbp, Cbp = 0.5 * (L1 + L2), 0.5 * (C1p + C2p)
    hs = h1p + h2p
    hbp = np.where(np.abs(h1p - h2p) > 180.0,
                   np.where(hs < 360.0, (hs + 360.0) / 2.0, (hs - 360.0) / 2.0), hs / 2.0)
    hbp = np.where(C1p * C2p == 0.0, hs, hbp)
    T = (1.0 - 0.17 * np.cos(np.radians(hbp - 30.0)) + 0.24 * np.cos(np.radians(2.0 * hbp))
         + 0.32 * np.cos(np.radians(3.0 * hbp + 6.0)) - 0.20 * np.cos(np.radians(4.0 * hbp - 63.0)))
    dtheta = 30.0 * np.exp(-(((hbp - 275.0) / 25.0) ** 2))
    Rc = 2.0 * np.sqrt(Cbp ** 7 / (Cbp ** 7 + 25.0 ** 7))
    SL = 1.0 + 0.015 * (Lbp - 50.0) ** 2 / np.sqrt(20.0 + (Lbp - 50.0) ** 2)
    SC = 1.0 + 0.045 * Cbp
    SH = 1.0 + 0.015 * Cbp * T
    RT = -np.sin(np.radians(2.0 * dtheta)) * Rc
    return np.sqrt((dLp / SL) ** 2 + (dCp / SC) ** 2 + (dHp / SH) ** 2
                   + RT * (dCp / SC) * (dHp / SH))


def xyz_to_srgb_matrix() -> np.ndarray:
    """Mitsuba's XYZ -> linear sRGB matrix (rows: R, G, B)."""
    import mitsuba as mi
    cols = [np.array(mi.xyz_to_srgb(mi.ScalarColor3f(*e)), np.float64).ravel()
            for e in np.eye(3)]
    return np.stack(cols, axis=1)


class Channels(ABC):
    """The colour channels a render or table holds (Mitsuba's ``rgb`` or ``mono`` variants)."""

    name: str

    @abstractmethod
    def weights(self, cmf: np.ndarray, d65: np.ndarray) -> np.ndarray:
        """``w_c(λ)`` (C, n) from the colour-matching functions ``cmf`` (3, n) and D65 (n,)."""


class _Rgb(Channels):
    """Linear sRGB."""

    name = "rgb"

    def weights(self, cmf, d65):
        return (xyz_to_srgb_matrix() @ cmf) * d65[None, :]


class _Mono(Channels):
    """Luminance Y."""

    name = "mono"

    def weights(self, cmf, d65):
        return (cmf[1] * d65)[None, :]


#: The channel sets by name.
CHANNELS: dict[str, Channels] = {c.name: c for c in (_Rgb(), _Mono())}


def channel_weights(channels: Channels | Any, wavelengths: np.ndarray) -> np.ndarray:
    """``w_c(λ)`` at ``wavelengths`` (shape ``(C, n)``; not normalised): linear sRGB
    (``channels="rgb"``) or luminance Y (``"mono"``) under D65 (a name or a
    :class:`Channels` of :data:`CHANNELS`). The 1 nm data are interpolated
    linearly, as Mitsuba interpolates its CMF table."""
    if not isinstance(channels, Channels):
        channels = choose(CHANNELS, channels, "channels")
    W = colour_weights()
    lam = W[:, 0]
    cmf = np.stack([np.interp(wavelengths, lam, W[:, i]) for i in (1, 2, 3)])
    d65 = np.interp(wavelengths, lam, W[:, 4])
    return channels.weights(cmf, d65)


_WHITE = None


def colour_differences(a: np.ndarray, b: np.ndarray, channels: int) -> np.ndarray:
    """CIEDE2000 between colours ``a`` and ``b`` (last axis: ``k * channels``
    values, ``k`` colours of linear sRGB, or Y, relative to a perfect reflector):
    shape ``a.shape[:-1] + (k,)``."""
    global _WHITE
    if _WHITE is None:
        _WHITE = np.linalg.inv(xyz_to_srgb_matrix())
    a = a.reshape(a.shape[:-1] + (-1, channels))
    b = b.reshape(b.shape[:-1] + (-1, channels))
    if channels == 1:
        a, b = np.repeat(a, 3, axis=-1), np.repeat(b, 3, axis=-1)
    white = _WHITE.sum(axis=1)          # XYZ of RGB (1, 1, 1)
    return delta_e2000(lab(a @ _WHITE.T, white), lab(b @ _WHITE.T, white))


def trapezoid_weights(x: np.ndarray) -> np.ndarray:
    """Weights of the trapezoid rule on the increasing nodes ``x``."""
    x = np.asarray(x, np.float64)
    w = np.empty_like(x)
    w[1:-1] = 0.5 * (x[2:] - x[:-2])
    w[0] = 0.5 * (x[1] - x[0])
    w[-1] = 0.5 * (x[-1] - x[-2])
    return w


def normalised_weights(kind: str) -> np.ndarray:
    """``ŵ_c`` on the 1 nm grid of the colour data (shape ``(C, 471)``): the channel
    weights of :func:`channel_weights` scaled to a unit integral."""
    lam = colour_weights()[:, 0]
    w = channel_weights(kind, lam)
    return w / (w * trapezoid_weights(lam)[None, :]).sum(axis=1, keepdims=True)
