"""What a thin-film stack returns in each colour mode: the plugins' one variant seam.

Every plugin asks its mode (:func:`current`, chosen once from the Mitsuba variant
when the plugin is built) two things, and writes no ``if variant`` of its own:

* :meth:`SpectralMode.response` — the stack's unpolarized ``R`` (and ``T``) at the
  hit, for the weights and lobe probabilities, together with whatever the mode
  needs to form its value later (nothing, or the polarization of each lobe);
* :meth:`SpectralMode.value` — the plugin's unpolarized weight of a lobe (``R``
  or ``T`` times its factors, as a spectrum) turned into the variant's return
  value for the directions of the sample.

Modes:

* ``spectral`` (``*_spectral``): ``R``/``T`` from the stack's tables or film loops
  (:meth:`KernelStack.reflectance`); the value is the weight itself.
* ``polarized`` (``*_spectral_polarized``): ``R``/``T`` and the s/p polarization
  from the exact complex amplitudes (:mod:`thinfilm_mi.render.amplitudes`); the value is
  the Mueller matrix ``weight * shape``, rotated from the s/p frame of the plane
  of incidence into the implicit Stokes bases of the incident and outgoing
  directions, exactly as Mitsuba's ``conductor``, ``dielectric`` and
  ``roughconductor`` do (``mueller.rotate_mueller_basis``; light arrives along
  ``-wo_hat`` and leaves along ``wi_hat``, which swap with ``ctx.mode``).
  Diffuse lobes are Mitsuba's ``depolarizer`` of the weight.

* ``colour`` (RGB and mono variants: ``*_rgb``, ``*_mono``): ``R``/``T`` are the
  spectral values integrated against colour matching (linear sRGB or Y under
  D65), read from the stack's colour tables (:meth:`KernelStack.colour`,
  :mod:`thinfilm_mi.tabulate.integrated`); the value is the weight itself. Factors the
  user gives as colours multiply per channel, as in Mitsuba's own plugins.
  Products of spectral factors (``thinfilm_diffuse``'s film-in x base x
  film-out) are integrated as products by the plugin's own tables.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import drjit as dr

from thinfilm_mi.render.amplitudes import Shape, depolarizing_shape, polarized_response
from thinfilm_mi.render.colour_variants import colour_channels
from thinfilm_mi.render.kernel import KernelStack
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["ColourMode", "PolarizedMode", "Response", "SpectralMode", "current", "sp_matrix"]


@dataclass
class Response:
    """A stack's unpolarized ``R`` and ``T`` at a hit, and per lobe what the mode
    needs to form its value (``None`` in the spectral mode)."""

    R: Any
    T: Any | None = None
    reflection: Any = None
    transmission: Any = None


class SpectralMode:
    """Unpolarized spectral variants: spectra in, spectra out."""

    name = "spectral"
    polarized = False
    #: Whether values are integrated over wavelengths at load time (RGB and mono)
    integrated = False
    #: The lobe of a diffuse (depolarizing) component.
    depolarized = None

    def response(self, stack: KernelStack, si, cos_theta, active=True, *,
                 inside: bool | Any = False, transmission: bool = False) -> Response:
        out = stack.reflectance(si, cos_theta, active, inside=inside, transmission=transmission)
        return Response(*out) if transmission else Response(out)

    def select(self, mask, a, b):
        """The lobe ``a`` where ``mask``, else ``b``."""
        return None

    def value(self, weight, lobe, ctx, wi, wo, normal=None):
        """The return value of a sample or evaluation with the unpolarized ``weight``
        (``mi.Spectrum``) on ``lobe`` (a :class:`Response`'s ``reflection`` or
        ``transmission``, or :attr:`depolarized`) between ``wi`` and ``wo`` about
        ``normal`` (default: the shading normal). Here: ``weight`` as a ``mi.Spectrum``
        (arithmetic on the spectra of a film-free stack or of a scalar variant makes a
        plain ``Array4f``, which a caller's loop over a nested BSDF refuses as a
        different type)."""
        return mitsuba_module().Spectrum(weight)


class PolarizedMode(SpectralMode):
    """``*_spectral_polarized``: Mueller matrices from the exact amplitudes."""

    name = "polarized"
    polarized = True
    depolarized = depolarizing_shape()

    def response(self, stack, si, cos_theta, active=True, *, inside=False,
                 transmission=False) -> Response:
        p = polarized_response(stack, si, cos_theta, active, inside=inside,
                               transmission=transmission)
        return Response(p.R, p.T, p.reflection, p.transmission)

    def select(self, mask, a: Shape, b: Shape) -> Shape:
        return a.select(mask, b)

    def value(self, weight, lobe: Shape, ctx, wi, wo, normal=None):
        mi = mitsuba_module()
        if lobe is self.depolarized:
            return mi.depolarizer(mi.UnpolarizedSpectrum(weight))
        M = sp_matrix(weight, lobe)
        # Light arrives along -wo_hat and leaves along wi_hat (Mitsuba's pBSDFs).
        radiance = ctx.mode == mi.TransportMode.Radiance
        wo_hat, wi_hat = (wo, wi) if radiance else (wi, wo)
        n = mi.Vector3f(0, 0, 1) if normal is None else normal
        s_in, s_out = dr.cross(n, -wo_hat), dr.cross(n, wi_hat)
        # Singular when the directions are collinear with the normal
        collinear = dr.all(s_in == mi.Vector3f(0))
        s_in = dr.select(collinear, mi.Vector3f(1, 0, 0), dr.normalize(s_in))
        s_out = dr.select(collinear, mi.Vector3f(1, 0, 0), dr.normalize(s_out))
        return mi.mueller.rotate_mueller_basis(
            M, -wo_hat, s_in, mi.mueller.stokes_basis(-wo_hat),
            wi_hat, s_out, mi.mueller.stokes_basis(wi_hat))


def sp_matrix(weight, shape: Shape):
    """The Mueller matrix ``weight * shape`` in the s/p frame of the plane of
    incidence (``mi.Spectrum`` of a polarized variant)."""
    mi = mitsuba_module()
    w = mi.UnpolarizedSpectrum(weight)
    zero = dr.zeros(mi.UnpolarizedSpectrum)
    b, c_re, c_im = w * shape.b, w * shape.c_re, w * shape.c_im
    return mi.Spectrum([[w, b, zero, zero],
                        [b, w * shape.d, zero, zero],
                        [zero, zero, c_re, -c_im],
                        [zero, zero, c_im, c_re]])


class ColourMode(SpectralMode):
    """RGB and mono variants: colours integrated over wavelengths at load time."""

    name = "colour"
    #: integrated products of spectral factors are the plugin's business
    integrated = True

    def response(self, stack, si, cos_theta, active=True, *, inside=False,
                 transmission=False) -> Response:
        out = stack.colour(si, cos_theta, active, inside=inside, transmission=transmission)
        return Response(*out) if transmission else Response(out)


_MODES = {"spectral": SpectralMode(), "polarized": PolarizedMode(), "colour": ColourMode()}


def current() -> SpectralMode:
    """The mode of the current Mitsuba variant (checked by :func:`thinfilm_mi.render.variant.check_variant`)."""
    mi = mitsuba_module()
    if colour_channels() is not None:
        return _MODES["colour"]
    return _MODES["polarized" if mi.is_polarized else "spectral"]
