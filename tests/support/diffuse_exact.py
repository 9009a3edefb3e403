"""Helpers of the exact diffuse model's tests: wavelengths, interactions and directions."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

mi.set_variant("llvm_ad_spectral")

import thinfilm_mi  # noqa: E402,F401  (registers the plugins)

WL = (450.0, 520.0, 600.0, 680.0)


def make_si(n, wi, wavelengths=WL):
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = wi
    si.uv = mi.Point2f(0.3, 0.7)
    si.wavelengths = mi.Spectrum(*wavelengths)
    return si


def direction(theta_deg):
    t = math.radians(theta_deg)
    return mi.Vector3f(math.sin(t), 0.0, math.cos(t))
