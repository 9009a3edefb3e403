"""What the BSDF tests build to query a plugin: a context, an interaction, a direction;
and a Monte Carlo directional albedo.

The plugin test modules and the render tests of the shared BSDF code (Oren–Nayar,
the exact diffuse model, the microfacets) query BSDFs the same way; these are the
helpers they share.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

#: Four wavelengths (nm) across the visible, the default of :func:`make_si`.
WAVELENGTHS = (450.0, 520.0, 600.0, 680.0)


def context(component=None, type_mask=None, mode=None):
    """A ``BSDFContext`` in transport ``mode`` (Mitsuba's default: radiance), for one
    ``component`` and a ``type_mask`` if given."""
    ctx = mi.BSDFContext(mode) if mode is not None else mi.BSDFContext()
    if component is not None:
        ctx.component = component
    if type_mask is not None:
        ctx.type_mask = type_mask
    return ctx


def make_si(n, wi, wavelengths=WAVELENGTHS, uv=(0.3, 0.7)):
    """``n`` surface interactions with incident direction ``wi`` at ``uv``; in spectral
    variants their four wavelength channels are ``wavelengths``."""
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = wi
    si.uv = mi.Point2f(*uv)
    if mi.is_spectral:
        si.wavelengths = mi.UnpolarizedSpectrum(*wavelengths)
    return si


def direction(theta_deg, phi_deg=0.0):
    """The unit ``mi.Vector3f`` at polar angle ``theta_deg`` and azimuth ``phi_deg``."""
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return mi.Vector3f(math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def unit_vector(theta_deg, phi_deg=0.0):
    """The same direction as :func:`direction`, as a float64 numpy array."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def mc_albedo(bsdf, theta_deg, n=1 << 18, seed=1, ctx=None):
    """Per channel, the mean of ``n`` sample() weights at incidence ``theta_deg`` (the
    directional albedo, in ``ctx``'s components) and its standard error."""
    rng = mi.PCG32(size=n, initstate=seed)
    s1 = rng.next_float32()
    s2 = mi.Point2f(rng.next_float32(), rng.next_float32())
    _, w = bsdf.sample(ctx or mi.BSDFContext(), make_si(n, direction(theta_deg)), s1, s2)
    w = np.array(w, np.float64).reshape(-1, n)
    return w.mean(axis=1), w.std(axis=1) / math.sqrt(n)


def to_np(x):
    """A Dr.Jit value as a float64 numpy array."""
    return np.array(x, dtype=np.float64)
