"""Colour targets with exact derivatives: XYZ -> L*a*b* -> CIEDE2000, and xy.

A colour is linear in the spectrum (``XYZ = Q @ W``, the weights of
:func:`thinfilm_mi.colour.report.spectrum_colour`), so only the few non-linear
steps after it need derivatives. They are carried forward by :class:`Dual`
numbers: a value and its derivatives with respect to the three components of
XYZ. The formulas are the CIE's (L*a*b* with the linear segment below
``(6/29)^3``; CIEDE2000 as in Sharma, Wu & Dalal 2005, the test data set of
which colour-science also follows); tests/design/test_colourmath.py compares both with
colour-science. A CIEDE2000 without derivatives is
:func:`thinfilm_mi.colour.cie.delta_e2000`.

A CIEDE2000 difference is returned as three residuals whose squares sum to
``dE00^2`` (the rotation term folded in, see :func:`delta_e2000_residuals`): a
least-squares solver then sees a smooth problem where ``dE00`` itself has a
kink at 0.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

# CIEDE2000 of plain numbers (no derivatives) is the colour layer's; it is named here too
# for the callers that import it from here (benchmarks/design_bench.py, notebook 06).
from thinfilm_mi.colour.cie import delta_e2000

__all__ = ["Dual", "colour_weights", "lab", "delta_e2000_residuals", "delta_e2000", "xy_of"]


class Dual:
    """``val`` (any shape S) and ``der`` (S + (K,)): a value and its gradient."""

    __slots__ = ("val", "der")

    def __init__(self, val, der):
        self.val = np.asarray(val, dtype=np.float64)
        self.der = der

    @staticmethod
    def variables(x: np.ndarray) -> "Dual":
        """The last axis of ``x`` (size K) as K independent variables."""
        x = np.asarray(x, dtype=np.float64)
        return Dual(x, np.broadcast_to(np.eye(x.shape[-1]), x.shape + (x.shape[-1],)))

    def _lift(self, o):
        return o if isinstance(o, Dual) else Dual(o, np.zeros(np.shape(o) + self.der.shape[-1:]))

    def __getitem__(self, i: int) -> "Dual":
        """Component ``i`` of the last value axis."""
        return Dual(self.val[..., i], self.der[..., i, :])

    def __add__(self, o):
        if not isinstance(o, Dual):
            return Dual(self.val + o, np.broadcast_to(self.der, np.shape(self.val + o) + self.der.shape[-1:]))
        return Dual(self.val + o.val, self.der + o.der)

    __radd__ = __add__

    def __neg__(self):
        return Dual(-self.val, -self.der)

    def __sub__(self, o):
        return self + (-self._lift(o))

    def __rsub__(self, o):
        return self._lift(o) - self

    def __mul__(self, o):
        if not isinstance(o, Dual):
            return Dual(self.val * o, self.der * np.asarray(o)[..., None])
        return Dual(self.val * o.val, self.der * o.val[..., None] + o.der * self.val[..., None])

    __rmul__ = __mul__

    def __truediv__(self, o):
        o = self._lift(o)
        return Dual(self.val / o.val,
                    (self.der * o.val[..., None] - o.der * self.val[..., None]) / (o.val ** 2)[..., None])

    def __rtruediv__(self, o):
        return self._lift(o) / self

    def _chain(self, val, slope):
        return Dual(val, self.der * np.asarray(slope)[..., None])

    def __pow__(self, p: float):
        return self._chain(self.val ** p, p * self.val ** (p - 1))

    def sqrt(self):
        v = np.sqrt(self.val)
        return self._chain(v, 0.5 / np.where(v > 0, v, np.inf))

    def exp(self):
        v = np.exp(self.val)
        return self._chain(v, v)

    def sin(self):
        return self._chain(np.sin(self.val), np.cos(self.val))

    def cos(self):
        return self._chain(np.cos(self.val), -np.sin(self.val))

    @staticmethod
    def atan2(y: "Dual", x: "Dual") -> "Dual":
        r2 = x.val ** 2 + y.val ** 2
        inv = 1.0 / np.where(r2 > 0, r2, np.inf)
        return Dual(np.arctan2(y.val, x.val),
                    (y.der * x.val[..., None] - x.der * y.val[..., None]) * inv[..., None])

    @staticmethod
    def where(cond, a: "Dual", b: "Dual") -> "Dual":
        return Dual(np.where(cond, a.val, b.val), np.where(np.asarray(cond)[..., None], a.der, b.der))


@lru_cache(maxsize=32)
def colour_weights(illuminant: str, observer: int, step: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(wavelengths, W, white_XYZ)``: ``XYZ = spectrum @ W`` on the integration
    grid of :func:`thinfilm_mi.colour.report.integration_wavelengths` (Y = 1 for the
    perfect reflector), read off :func:`~thinfilm_mi.colour.report.spectrum_colour`
    (which is linear in the spectrum) so that the two agree to rounding.

    ``step`` > 1: every ``step``-th wavelength of that grid (and its last one),
    with the weights of a spectrum interpolated linearly between them (a cheap
    approximation for screening many stacks)."""
    if step > 1:
        wl, W, white = colour_weights(illuminant, observer)
        nodes = np.unique(np.r_[np.arange(0, wl.size, step), wl.size - 1])
        hat = np.stack([np.interp(wl, wl[nodes], np.eye(nodes.size)[k]) for k in range(nodes.size)])
        return wl[nodes], hat @ W, white
    from thinfilm_mi.colour.report import integration_wavelengths, spectrum_colour

    wl = integration_wavelengths(illuminant)
    values = spectrum_colour(np.eye(wl.size), wl, illuminant, observer, chromatic_adaptation=None)
    return wl, np.ascontiguousarray(values.XYZ), np.asarray(values.white_XYZ, dtype=np.float64)


_EPS = (6.0 / 29.0) ** 3


def _f(t: Dual) -> Dual:
    cube = Dual(np.cbrt(t.val), t.der / (3.0 * np.cbrt(np.maximum(t.val, _EPS)) ** 2)[..., None])
    linear = t * (1.0 / (3.0 * (6.0 / 29.0) ** 2)) + 4.0 / 29.0
    return Dual.where(t.val > _EPS, cube, linear)


def lab(XYZ: Dual, white: np.ndarray) -> Dual:
    """CIE 1976 L*a*b* of ``XYZ`` (Y = 1 for the white) relative to ``white``
    ((3,), or one per colour, (..., 3)); components ``L, a, b`` on the last axis."""
    white = np.asarray(white, dtype=np.float64)
    fx, fy, fz = (_f(XYZ[i] * (1.0 / white[..., i])) for i in range(3))
    L, a, b = fy * 116.0 - 16.0, (fx - fy) * 500.0, (fy - fz) * 200.0
    return Dual(np.stack([L.val, a.val, b.val], axis=-1), np.stack([L.der, a.der, b.der], axis=-2))


def _g_factor(C: Dual) -> Dual:
    c7 = C ** 7
    return (c7 / (c7 + 25.0 ** 7)).sqrt()


def delta_e2000_residuals(Lab2: Dual, Lab1: np.ndarray) -> Dual:
    """Three residuals ``e`` with ``e0^2 + e1^2 + e2^2 = dE00(Lab1, Lab2)^2``.

    With ``l = dL'/S_L``, ``c = dC'/S_C``, ``h = dH'/S_H`` and the rotation term
    ``R_T``, ``dE00^2 = l^2 + c^2 + h^2 + R_T c h = l^2 + (c + R_T h / 2)^2 +
    (1 - R_T^2 / 4) h^2`` (``|R_T| <= 2``). ``Lab1`` is the fixed reference (the
    target), ``Lab2`` the colour being designed.
    """
    L1, a1, b1 = (np.asarray(Lab1, dtype=np.float64)[..., i] for i in range(3))
    L2, a2, b2 = Lab2[0], Lab2[1], Lab2[2]
    zero = L2 * 0.0
    L1, a1, b1 = zero + L1, zero + a1, zero + b1
    C1, C2 = (a1 * a1 + b1 * b1).sqrt(), (a2 * a2 + b2 * b2).sqrt()
    G = (1.0 - _g_factor((C1 + C2) * 0.5)) * 0.5
    a1p, a2p = a1 * (G + 1.0), a2 * (G + 1.0)
    C1p, C2p = (a1p * a1p + b1 * b1).sqrt(), (a2p * a2p + b2 * b2).sqrt()
    deg = 180.0 / np.pi
    h1 = Dual.atan2(b1, a1p) * deg
    h2 = Dual.atan2(b2, a2p) * deg
    h1 = Dual.where(h1.val < 0, h1 + 360.0, h1)
    h2 = Dual.where(h2.val < 0, h2 + 360.0, h2)
    achromatic = C1p.val * C2p.val == 0
    dh = h2 - h1
    dh = Dual.where(dh.val > 180.0, dh - 360.0, Dual.where(dh.val < -180.0, dh + 360.0, dh))
    dh = Dual.where(achromatic, zero, dh)
    dL, dC = L2 - L1, C2p - C1p
    dH = (C1p * C2p).sqrt() * (dh * (0.5 / deg)).sin() * 2.0
    Lm, Cm = (L1 + L2) * 0.5, (C1p + C2p) * 0.5
    hs = h1 + h2
    far = np.abs(h1.val - h2.val) > 180.0
    hm = Dual.where(far, Dual.where(hs.val < 360.0, hs + 360.0, hs - 360.0), hs) * 0.5
    hm = Dual.where(achromatic, hs, hm)
    rad = 1.0 / deg
    T = (1.0 - 0.17 * ((hm - 30.0) * rad).cos() + 0.24 * ((hm * 2.0) * rad).cos()
         + 0.32 * ((hm * 3.0 + 6.0) * rad).cos() - 0.20 * ((hm * 4.0 - 63.0) * rad).cos())
    dtheta = (-(((hm - 275.0) * (1.0 / 25.0)) ** 2)).exp() * 30.0
    RT = -(_g_factor(Cm) * 2.0) * ((dtheta * 2.0) * rad).sin()
    Lm50 = (Lm - 50.0) ** 2
    SL = 1.0 + 0.015 * Lm50 / (Lm50 + 20.0).sqrt()
    SC = 1.0 + 0.045 * Cm
    SH = 1.0 + 0.015 * Cm * T
    l, c, h = dL / SL, dC / SC, dH / SH
    e1 = c + RT * h * 0.5
    e2 = (1.0 - RT * RT * 0.25).sqrt() * h
    return Dual(np.stack([l.val, e1.val, e2.val], axis=-1), np.stack([l.der, e1.der, e2.der], axis=-2))


def xy_of(XYZ: Dual) -> Dual:
    """Chromaticity ``(x, y)`` of ``XYZ``."""
    s = XYZ[0] + XYZ[1] + XYZ[2]
    x, y = XYZ[0] / s, XYZ[1] / s
    return Dual(np.stack([x.val, y.val], axis=-1), np.stack([x.der, y.der], axis=-2))
