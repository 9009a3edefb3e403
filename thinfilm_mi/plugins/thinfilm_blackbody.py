r"""
.. _spectrum-thinfilm_blackbody:

Black body radiance in every variant (:monosp:`thinfilm_blackbody`)
-------------------------------------------------------------------

.. pluginparameters::

 * - temperature
   - |float|
   - The black body's temperature in kelvin: a finite number > 0 (required).
   - |exposed|
 * - scale
   - |float|
   - Factor on the radiance, a finite number >= 0 (default: 1.0).
   - |exposed|
 * - wavelength_min, wavelength_max
   - |float|
   - The spectral range (nm) outside which the radiance is 0, as in Mitsuba's
     ``blackbody`` (default: 360 and 830).

Planck's spectral radiance in W/(m^2 sr nm), as Mitsuba's ``blackbody``
spectrum, in **every** variant; Mitsuba's own ``blackbody`` refuses RGB and mono
variants ("Not implemented for non-spectral modes").

* Spectral variants (``*_spectral``, ``*_spectral_polarized``): ``eval`` returns
  exactly what ``blackbody`` returns at the path's wavelengths (the same
  constants and float32 formula, 0 outside the spectral range), times
  ``scale``. ``sample_spectrum`` (used by emitters that sample wavelengths,
  e.g. when tracing rays from the light) draws wavelengths from a
  piecewise-linear fit of the spectrum (1 nm nodes) and returns radiance / pdf;
  ``pdf_spectrum`` is that pdf.
* RGB variants: the constant linear sRGB colour
  ``M · ∫ E(λ) [x̄, ȳ, z̄](λ) dλ / 106.75``: CIE 1931 2° colour matching
  (colour-science, 1 nm, trapezoid rule), ``M`` Mitsuba's ``xyz_to_srgb`` and
  Mitsuba's ``MI_CIE_Y_NORMALIZATION`` (1/106.75). This is what Mitsuba's
  spectral pipeline computes for the emitter with an RGB film, so a render in an
  RGB variant agrees with one in a spectral variant
  (tests/plugins/test_thinfilm_blackbody.py compares them from 2856 to 20000 K).
* Mono variants: the luminance ``Y`` of the same integral.

The radiance is not spatially varying. The temperature and scale can be changed
through ``mi.traverse`` (the colour is recomputed; the kernel is not).

.. tabs::
    .. code-tab:: xml

        <emitter type="area">
            <spectrum type="thinfilm_blackbody" name="radiance">
                <float name="temperature" value="2856"/>
            </spectrum>
        </emitter>

    .. code-tab:: python

        {'type': 'area', 'radiance': {'type': 'thinfilm_blackbody', 'temperature': 2856}}
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from thinfilm_mi.colour.cie import colour_weights, trapezoid_weights, xyz_to_srgb_matrix
from thinfilm_mi.errors import ThinFilmError, plugin_boundary
from thinfilm_mi.render.reader import PluginProperties, finite_number

__all__ = ["NAME", "C", "H", "K", "C0_F32", "C1_F32", "CIE_MIN", "CIE_MAX", "planck", "ThinFilmBlackbody"]

NAME = "thinfilm_blackbody"

# Mitsuba's constants (src/spectra/blackbody.cpp, CODATA 2014), as float32 there
C = 2.99792458e+8    # speed of light (m/s)
H = 6.62607004e-34   # Planck constant (J s)
K = 1.38064852e-23   # Boltzmann constant (J/K)
_f = np.float32
#: 1e-9 * 2 h c^2 and h c / k, rounded to float32 step by step as Mitsuba's
#: constexpr float expressions are
C0_F32 = float(_f(1e-9) * (((_f(2) * _f(H)) * _f(C)) * _f(C)))
C1_F32 = float((_f(H) * _f(C)) / _f(K))
#: the CIE tables' range (Mitsuba's MI_CIE_MIN, MI_CIE_MAX)
CIE_MIN, CIE_MAX = 360.0, 830.0


def planck(wavelength_nm, temperature: float) -> np.ndarray:
    """Planck's spectral radiance (W / (m^2 sr nm)) in float64."""
    lam = np.asarray(wavelength_nm, np.float64) * 1e-9
    with np.errstate(over="ignore"):
        return 1e-9 * 2.0 * H * C * C / (lam ** 5 * np.expm1(H * C / (K * lam * temperature)))


def _check(temperature: float, scale: float) -> None:
    """``temperature`` (K) finite and > 0, ``scale`` finite and >= 0 (load and edits)."""
    finite_number("'temperature'", temperature, 0.0, strict=True, unit=" (K)")
    finite_number("'scale'", scale, 0.0)


def _scalar(value) -> float:
    return float(dr.ravel(value)[0]) if dr.is_array_v(value) else float(value)


class ThinFilmBlackbody(mi.Texture):
    def __init__(self, props):
        with plugin_boundary(NAME):
            read = PluginProperties(props)
            temperature = read.number("temperature", lo=0.0, strict=True, unit=" (K)",
                                      required="a black body temperature in kelvin, e.g. 2856")
            scale = read.number("scale", 1.0, 0.0)
            lo = read.number("wavelength_min", CIE_MIN, unit=" (nm)")
            hi = read.number("wavelength_max", CIE_MAX, unit=" (nm)")
            if not 0 < lo < hi:
                raise ThinFilmError(f"'wavelength_min' and 'wavelength_max' must be finite "
                                    f"with 0 < wavelength_min < wavelength_max (nm), got {lo!r} "
                                    f"and {hi!r}")
            read.check_unqueried()
            self.range = (lo, hi)
            self.spectral = bool(mi.is_spectral)
            self.temperature = mi.Float(temperature)
            self.scale = mi.Float(scale)
            self._valid = (temperature, scale)
            self._update(temperature, scale)
        self._make_opaque()
        # registered once complete: from here on every thread's symbolic calls trace it
        mi.Texture.__init__(self, props)

    # -- precomputation (float64) -----------------------------------------------------

    def _nodes(self) -> np.ndarray:
        lo, hi = self.range
        return np.linspace(lo, hi, max(2, int(math.ceil(hi - lo)) + 1))

    def _update(self, temperature: float, scale: float) -> None:
        """Validate ``temperature``/``scale`` and recompute what ``eval`` reads."""
        _check(temperature, scale)
        lam = self._nodes()
        # the spectral variants' float32 formula must stay finite (exp(x) - 1 rounds
        # to 0 above ~1e11 K), and so must the colour: the same temperatures load in
        # every variant
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            l32 = lam.astype(np.float32) * _f(1e-9)
            f32 = _f(C0_F32) / (l32 ** 5 * (np.exp(_f(C1_F32) / (l32 * _f(temperature))) - 1))
            f32 = f32 * _f(scale)
        colour = self.colour(temperature, scale, self.range)
        if not (np.all(np.isfinite(f32)) and np.all(np.isfinite(colour.astype(np.float32)))):
            raise ThinFilmError(f"'temperature' = {temperature!r} K (scale {scale!r}) "
                                f"gives a radiance beyond float32 range")
        radiance = scale * planck(lam, temperature)
        if self.spectral:
            self._mean = float(radiance @ trapezoid_weights(lam) / (lam[-1] - lam[0]))
            self._max = float(radiance.max())
            # wavelength sampling: a piecewise-linear fit of the radiance; a black body
            # too cold to radiate in the range (all zeros) is sampled uniformly
            pdf = radiance if self._max > 0 else np.ones_like(radiance)
            array = mi.Float if dr.is_array_v(mi.Float) else dr.scalar.ArrayXf
            self.distr = mi.ContinuousDistribution(mi.ScalarVector2f(*self.range),
                                                   array(pdf.astype(np.float32)))
        else:
            if mi.is_monochromatic:
                colour = colour[1:2]          # the luminance Y
            else:
                colour = xyz_to_srgb_matrix() @ colour
            self.value = mi.UnpolarizedSpectrum(*[float(c) for c in colour])
            if dr.is_jit_v(self.value):
                dr.make_opaque(self.value)
            self._mean = float(np.mean(colour))
            self._max = float(np.max(colour))

    @staticmethod
    def colour(temperature: float, scale: float = 1.0,
               wavelength_range: tuple[float, float] = (CIE_MIN, CIE_MAX)) -> np.ndarray:
        """CIE XYZ of the radiance with Mitsuba's normalisation: what a spectral
        render with an RGB film converts it to (before ``xyz_to_srgb``)."""

        W = colour_weights()                  # 1 nm, 360-830 nm
        lam, cmf = W[:, 0], W[:, 1:4].T
        inside = (lam >= wavelength_range[0]) & (lam <= wavelength_range[1])
        lam, cmf = lam[inside], cmf[:, inside]
        if lam.size < 2:
            return np.zeros(3)
        xyz = cmf @ (scale * planck(lam, temperature) * trapezoid_weights(lam))
        return xyz * float(mi.MI_CIE_Y_NORMALIZATION)

    # -- Texture interface ----------------------------------------------------------

    def _radiance(self, wavelengths, active=True):
        """Mitsuba's float32 formula (src/spectra/blackbody.cpp) times ``scale``."""
        lam = wavelengths * 1e-9
        lam2 = dr.square(lam)
        lam5 = dr.square(lam2) * lam
        P = C0_F32 / (lam5 * (dr.exp(C1_F32 / (lam * self.temperature)) - 1.0))
        inside = (wavelengths >= self.range[0]) & (wavelengths <= self.range[1]) & active
        return dr.select(inside, P * self.scale, 0.0)

    def eval(self, si, active=True):
        if self.spectral:
            return self._radiance(si.wavelengths, active)
        return dr.select(active, self.value, 0.0)

    def sample_spectrum(self, si, sample, active=True):
        if not self.spectral:
            return si.wavelengths, dr.select(active, self.value, 0.0)
        lam = type(sample)(*[self.distr.sample(sample[i], active) for i in range(len(sample))])
        pdf = self._pdf(lam, active)
        value = self._radiance(lam, active)
        return lam, dr.select(pdf > 0, value / pdf, 0.0)

    def _pdf(self, lam, active=True):
        return type(lam)(*[self.distr.eval_pdf_normalized(lam[i], active)
                           for i in range(len(lam))])

    def pdf_spectrum(self, si, active=True):
        if not self.spectral:
            raise ThinFilmError(f"{NAME}: pdf_spectrum is defined in spectral variants only")
        return self._pdf(si.wavelengths, active)

    def mean(self):
        return self._mean

    def max(self):
        return self._max

    def is_spatially_varying(self):
        return False

    def wavelength_range(self):
        return mi.ScalarVector2f(*self.range)

    def spectral_resolution(self):
        return 0.0

    def traverse(self, callback):
        callback.put("temperature", self.temperature, mi.ParamFlags.NonDifferentiable)
        callback.put("scale", self.scale, mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys=None):
        with plugin_boundary(NAME):
            self._changed()

    def _changed(self):
        """Validate an edit of ``temperature``/``scale``; a rejected one is undone."""
        temperature, scale = _scalar(self.temperature), _scalar(self.scale)
        try:
            self._update(temperature, scale)
        except ThinFilmError:
            # write the last valid values back (in place: mi.traverse holds these
            # arrays), so a rejected edit leaves a working emitter
            for attr, value in zip(("temperature", "scale"), self._valid):
                if dr.is_array_v(getattr(self, attr)):
                    mi.set_property(getattr(self, attr), mi.Float(value))
                else:
                    setattr(self, attr, mi.Float(value))
            self._update(*self._valid)
            self._make_opaque()
            raise
        self._valid = (temperature, scale)
        self._make_opaque()

    def _make_opaque(self):
        # kernel inputs, not literals: an edit does not recompile the render kernel
        for v in (self.temperature, self.scale):
            if dr.is_jit_v(v):
                dr.make_opaque(v)

    def to_string(self):
        return (f"ThinFilmBlackbody[\n  temperature = {_scalar(self.temperature)},\n"
                f"  scale = {_scalar(self.scale)},\n  range = {list(self.range)}\n]")
