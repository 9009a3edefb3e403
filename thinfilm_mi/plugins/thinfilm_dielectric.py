r"""
.. _bsdf-thinfilm_dielectric:

Thin-film coated smooth dielectric (:monosp:`thinfilm_dielectric`)
------------------------------------------------------------------

.. shared-rows: dielectric
.. pluginparameters::

 * - layers
   - |string|
   - The film stack from the outside in, ``"MATERIAL THICKNESS_NM; ..."``, e.g.
     ``"Au 20"`` or ``"1.46 500; Au 20; Al 10"`` (default: ``""``, no films:
     a bare dielectric interface).
 * - thin_film_ior, thin_film_thickness
   - |string| or |float|, |float|
   - Shorthand for one film (index or material name, thickness in nm). Not
     together with ``layers``.
 * - int_ior
   - |float| or |string|
   - Interior index: a real number or a non-absorbing material name such as
     ``BK7`` or ``water`` (default: 1.5046, BK7 at 589 nm as in Mitsuba).
 * - ext_ior
   - |float| or |string|
   - Exterior index, real (default: 1.000277, air).
 * - specular_reflectance, specular_transmittance
   - |spectrum| or |texture|
   - Optional factors on reflection and transmission; physically they should
     stay 1 (default: 1.0).
 * - thickness
   - |float| or |texture|
   - Optional scale on every film's thickness at the hit, e.g. a ``bitmap`` with
     ``raw="true"`` (clamped to >= 0; default: 1). In spectral variants the stack is
     then evaluated exactly (no table); RGB and mono variants tabulate the colour over
     its range, read at load.
 * - tabulate
   - |string| or |bool|
   - ``auto`` (default), ``true`` or ``false``: whether ``R`` (and ``T``) is read from a
     verified table over (angle, wavelength), whose cost does not grow with the films,
     instead of the recursion. ``auto`` tabulates stacks of absorbing films from 4
     films, of other films from 1 (4 between media of constant index) in vectorised
     variants, without a ``thickness`` texture or gradients, where a table within budget
     meets ``table_error``; ``true`` tabulates every stack it can, with 10x the build
     budget. When and why: :ref:`the tables guide <tabulate-policy>`.
 * - table_error
   - |float|
   - Target max abs error of a table in ``R`` and ``T`` (default: 0.001).
 * - spectral_resolution
   - |float|
   - Spectral resolution (nm) tables may assume where no table resolves the exact values
     (deep stacks on a metal): ``R`` and ``T`` are then tabulated convolved with a
     Gaussian in wavenumber of this standard deviation at 560 nm, if that keeps the
     colour (default: 1; 0: exact values only). Under lasers or line spectra narrower
     than this pass 0; see :ref:`the tables guide <tabulate-policy>`.
 * - coherence_thickness
   - |float|
   - Films thicker than this (nm) are averaged incoherently, as tmm's ``inc_tmm`` does,
     instead of showing ~1 nm fringes no broadband light shows (default: 5000).

The interface between two dielectrics (``ext_ior`` outside, ``int_ior`` inside)
coated with a stack of thin films that may absorb. Component 0 is the delta
reflection and component 1 the delta transmission. Reflection and transmission
are chosen in proportion to their energy: with ``R`` and ``T`` the composite
reflectance and transmittance of the multilayer (averaged over the path's
wavelengths for the choice), reflection is picked with probability
``R / (R + T)``; the weight of a reflected sample is then ``R / P(reflect)``
and that of a transmitted sample ``T / P(transmit)`` times the usual
``(eta_ext / eta_int)^2`` radiance scaling. When the context enables only one
component, that component is returned with weight ``R`` (or the scaled ``T``).

Rays arriving from inside see the reversed stack, computed exactly: with
absorbing films the reflectance differs between the two sides (only ``T`` is
reciprocal). Refraction directions and ``bs.eta`` follow Mitsuba's
``dielectric``; for a dispersive ``int_ior``/``ext_ior`` the *direction* uses the
mean index over 360-830 nm (a path has one direction for all its wavelengths)
while ``R`` and ``T`` use the exact index at each wavelength.

In ``*_spectral_polarized`` variants the weights are Mueller matrices of the
stack's complex amplitudes (``r_s, r_p`` and ``t_s, t_p`` with the
``n cos θ`` power factor; exact, or their components read from a table, see
``tabulate``), from the side the ray arrives on, rotated into
Mitsuba's Stokes bases as Mitsuba's ``dielectric`` does (the transmission
matrix is the same from both sides by reciprocity); lobe choice and radiance
scaling are as above, with ``R`` and ``T`` the matrices' ``M00``. With no films
they equal ``dielectric``'s matrices.

In RGB and mono variants (``*_rgb``, ``*_mono``; polarized ones are refused) the
reflectance and transmittance (from both sides) are the spectral values integrated
against colour matching: CIE 1931 2° under D65 to linear sRGB, normalised so that a
perfect reflector gives (1, 1, 1), or the luminance Y in mono; this is the
convention of Mitsuba's spectral pipeline, so an RGB render and a spectral render of
a scene agree. They are tabulated over the angle at scene load with the float64
recursion (``thinfilm_mi/tabulate/integrated.py``; over the angle and the thickness scale
with a ``thickness`` texture), so a deep stack costs what one film costs at render
time; ``tabulate``, ``table_error`` and ``spectral_resolution`` do not apply.
``specular_reflectance`` and ``specular_transmittance`` multiply per channel.
Gradients of thicknesses and numeric indices in ``llvm_ad_rgb``: the value is the
table's, and the gradient that of an unbiased estimate of the same integral at
stratified wavelengths per hit (the exact recursion through every film), traced only
when a parameter carries gradients.

.. tabs::
    .. code-tab:: xml

        <bsdf type="thinfilm_dielectric">
            <float name="int_ior" value="1.6"/>
            <string name="layers" value="SiO2 500; Au 20; Al 10"/>
        </bsdf>

    .. code-tab:: python

        {'type': 'thinfilm_dielectric', 'int_ior': 1.6, 'layers': 'SiO2 500; Au 20; Al 10'}
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from thinfilm_mi.errors import plugin_boundary
from thinfilm_mi.render import modes
from thinfilm_mi.render.kernel import build_stack
from thinfilm_mi.render.lobe_choice import chosen_weight, reflection_probability
from thinfilm_mi.render.media import DEFAULT_EXT_IOR, DEFAULT_INT_IOR
from thinfilm_mi.render.params import ParameterGuard
from thinfilm_mi.render.reader import PluginProperties
from thinfilm_mi.render.variant import check_variant

__all__ = ["NAME", "ThinFilmDielectric"]

NAME = "thinfilm_dielectric"


class ThinFilmDielectric(mi.BSDF):
    def __init__(self, props):
        with plugin_boundary(NAME):
            check_variant(NAME)
            self.mode = modes.current()
            read = PluginProperties(props)
            interior, ambient = read.indices(("int_ior", DEFAULT_INT_IOR), ("ext_ior", DEFAULT_EXT_IOR))
            spec = read.stack_spec(interior, ambient)
            self.eta = interior.mean_real() / ambient.mean_real()
            self.specular_reflectance = read.factor("specular_reflectance")
            self.specular_transmittance = read.factor("specular_transmittance")
            read.check_unqueried()
            self.stack = build_stack(spec, sides={False: True, True: True}, plugin=NAME)
        # registered once complete: from here on every thread's symbolic calls trace it
        mi.BSDF.__init__(self, props)
        self.m_components = [
            mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide,
            mi.BSDFFlags.DeltaTransmission | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            | mi.BSDFFlags.NonSymmetric,
        ]
        self.m_flags = self.m_components[0] | self.m_components[1]
        self.guard = ParameterGuard(self, NAME)

    def sample(self, ctx, si, sample1, sample2, active=True):
        has_r = ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0)
        has_t = ctx.is_enabled(mi.BSDFFlags.DeltaTransmission, 1)
        bs = dr.zeros(mi.BSDFSample3f)
        if not (has_r or has_t):
            return bs, mi.Spectrum(0.0)
        active = mi.Bool(active)
        cos_i = mi.Frame3f.cos_theta(si.wi)
        inside = cos_i < 0
        # Directions only (Mitsuba's real-index Fresnel is not used for amplitudes).
        _, cos_t, eta_it, eta_ti = mi.fresnel(cos_i, mi.Float(self.eta))
        tir = cos_t == 0
        # (no transmission work when only reflection is enabled)
        resp = self.mode.response(self.stack, si, dr.abs(cos_i), active, inside=inside,
                                  transmission=has_t)
        R = resp.R
        if has_t:
            T = dr.select(tir, 0.0, resp.T)

        if has_r and has_t:
            prob_r = reflection_probability(R, T)
            selected_r = (sample1 <= prob_r) & active
            # The choice is a detached sampling decision: its probability divides
            # the weight as a constant, so the weight's gradient is dR/p (dT/(1-p))
            # per wavelength and its expectation d(R + T).
            prob_r = dr.detach(prob_r)
            bs.pdf = dr.select(selected_r, prob_r, 1.0 - prob_r)
            weight = chosen_weight(selected_r, prob_r, R, T)
        elif has_r:
            selected_r = mi.Bool(True) & active
            bs.pdf = 1.0
            weight = R
        else:
            selected_r = mi.Bool(False)
            bs.pdf = 1.0
            weight = T
        selected_t = ~selected_r & active

        bs.sampled_component = dr.select(selected_r, mi.UInt32(0), mi.UInt32(1))
        bs.sampled_type = dr.select(selected_r, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                    mi.UInt32(+mi.BSDFFlags.DeltaTransmission))
        bs.wo = dr.select(selected_r, mi.reflect(si.wi), mi.refract(si.wi, cos_t, eta_ti))
        bs.eta = dr.select(selected_r, 1.0, eta_it)

        if self.specular_reflectance is not None:
            weight = dr.select(selected_r, weight * self.specular_reflectance.eval(si, selected_r),
                               weight)
        if self.specular_transmittance is not None:
            weight = dr.select(selected_t, weight * self.specular_transmittance.eval(si, selected_t),
                               weight)
        if ctx.mode == mi.TransportMode.Radiance:
            weight = dr.select(selected_t, weight * dr.square(eta_ti), weight)
        lobe = resp.reflection if not has_t else \
            self.mode.select(selected_r, resp.reflection, resp.transmission)
        return bs, dr.select(active & (selected_r | ~tir),
                             self.mode.value(weight, lobe, ctx, si.wi, bs.wo), 0.0)

    def eval(self, ctx, si, wo, active=True):
        return mi.Spectrum(0.0)

    def pdf(self, ctx, si, wo, active=True):
        return mi.Float(0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return mi.Spectrum(0.0), mi.Float(0.0)

    def traverse(self, callback):
        self.stack.traverse(callback)
        for name in ("specular_reflectance", "specular_transmittance"):
            tex = getattr(self, name)
            if tex is not None:
                callback.put(name, tex, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        self.guard.changed(self, self.stack.parameters_changed, keys)

    def to_string(self):
        return (f"ThinFilmDielectric[\n  layers = {self.stack.describe()},\n"
                f"  int_ior = {self.stack.substrate.label},\n"
                f"  ext_ior = {self.stack.ambient.label}\n]")
