r"""
.. _bsdf-thinfilm_roughdielectric:

Thin-film coated rough dielectric (:monosp:`thinfilm_roughdielectric`)
----------------------------------------------------------------------

.. shared-rows: dielectric
.. pluginparameters::

 * - layers
   - |string|
   - The film stack from the outside in, ``"MATERIAL THICKNESS_NM; ..."``, e.g.
     ``"SiO2 500; Au 20"``. Default: ``""`` (no films: exactly Mitsuba's
     ``roughdielectric``).
 * - thin_film_ior, thin_film_thickness
   - |string| or |float|, |float|
   - Shorthand for one film (index or material name, thickness in nm). Not
     together with ``layers``.
 * - thickness
   - |float| or |texture|
   - Optional scale on every film's thickness at the hit, e.g. a ``bitmap`` with
     ``raw="true"`` (clamped to >= 0; default: 1). In spectral variants the stack is
     then evaluated exactly (no table); RGB and mono variants tabulate the colour over
     its range, read at load.
 * - int_ior
   - |float| or |string|
   - Interior index: a real number or a non-absorbing material name such as
     ``BK7`` or ``water`` (default: 1.5046, BK7 at 589 nm as in Mitsuba).
 * - ext_ior
   - |float| or |string|
   - Exterior index, real (default: 1.000277, air). Must differ from ``int_ior``
     (with equal indices a rough interface does not bend light: use
     ``thinfilm_dielectric``, e.g. for a soap film).
 * - distribution
   - |string|
   - The microfacet normal distribution: ``beckmann`` (default) or ``ggx``.
 * - alpha, alpha_u, alpha_v
   - |float| or |texture|
   - Roughness, isotropic (``alpha``, default 0.1) or along the tangent and
     bitangent (``alpha_u`` and ``alpha_v``), as in Mitsuba; numbers must be
     > 0. Exposed as ``alpha`` or ``alpha_u``/``alpha_v``.
 * - sample_visible
   - |bool|
   - Sample only the visible normals, as Mitsuba (default: true). With ``false``
     the normals are drawn from a widened ``D`` (Walter et al.'s trick, as in
     Mitsuba) and the weights are ``eval / pdf`` exactly (Mitsuba 3.9's
     ``roughdielectric`` omits the ratio of ``D`` to the widened density there).
 * - specular_reflectance, specular_transmittance
   - |spectrum| or |texture|
   - Optional factors on reflection and transmission; physically they should
     stay 1 (default: 1.0).
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

A rough interface between two dielectrics coated with a stack of thin films
that may absorb, with the microfacet model of Mitsuba's ``roughdielectric``
(Walter et al. 2007). The films follow the microsurface: a microfacet with
normal ``m`` reflects ``R(λ, cos θ_m)`` and transmits ``T(λ, cos θ_m)``, the
exact composite reflectance and transmittance of the multilayer at
``cos θ_m = |dot(ω_i, m)|``, where Mitsuba's ``roughdielectric`` has ``F`` and
``1 - F``. With absorbing films ``R + T < 1``. Rays arriving from inside see the
reversed stack, computed exactly; beyond the critical angle ``T = 0``.

Component 0 is the glossy reflection, component 1 the glossy transmission.
After sampling a microfacet normal (Mitsuba's ``MicrofacetDistribution``),
reflection is chosen with probability ``P = R̄ / (R̄ + T̄)`` (bars: averages over
the path's wavelengths), as in ``thinfilm_dielectric``; the weights are then
``R G₁ / P`` and ``T G₁ / (1 - P)`` (times ``(η_i/η_t)²`` for transmitted
radiance) and ``pdf()`` includes the same ``P``. Refraction directions use the
mean real indices over 360-830 nm, as in ``thinfilm_dielectric``.

In ``*_spectral_polarized`` variants ``R`` and ``T`` become the Mueller matrices
of the stack's amplitudes (exact or tabulated, see ``tabulate``) at the microfacet, rotated about ``m`` as
Mitsuba's ``roughconductor`` rotates its reflection. Unlike Mitsuba's
``roughdielectric``, which depolarizes, this plugin keeps the polarization.

In RGB and mono variants (``*_rgb``, ``*_mono``; polarized ones are refused) each
microfacet's reflectance and transmittance (from both sides) are the spectral values
integrated against colour matching: CIE 1931 2° under D65 to linear sRGB, normalised
so that a perfect reflector gives (1, 1, 1), or the luminance Y in mono; this is the
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

        <bsdf type="thinfilm_roughdielectric">
            <float name="int_ior" value="1.5"/>
            <string name="layers" value="TiO2 90; SiO2 150"/>
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.1"/>
        </bsdf>

    .. code-tab:: python

        {'type': 'thinfilm_roughdielectric', 'int_ior': 1.5,
         'layers': 'TiO2 90; SiO2 150', 'distribution': 'ggx', 'alpha': 0.1}
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from thinfilm_mi.errors import ThinFilmError, plugin_boundary
from thinfilm_mi.render import modes
from thinfilm_mi.render.kernel import build_stack
from thinfilm_mi.render.lobe_choice import chosen_weight, reflection_probability
from thinfilm_mi.render.media import DEFAULT_EXT_IOR, DEFAULT_INT_IOR
from thinfilm_mi.render.microfacet import Microfacet, rough_bsdf_base
from thinfilm_mi.render.params import ParameterGuard
from thinfilm_mi.render.reader import PluginProperties
from thinfilm_mi.render.variant import check_variant

__all__ = ["NAME", "GLOSSY_R", "GLOSSY_T", "ThinFilmRoughDielectric"]

NAME = "thinfilm_roughdielectric"

GLOSSY_R = mi.BSDFFlags.GlossyReflection
GLOSSY_T = mi.BSDFFlags.GlossyTransmission


class ThinFilmRoughDielectric(rough_bsdf_base()):
    TEXTURES = ("specular_reflectance", "specular_transmittance")

    def __init__(self, props):
        with plugin_boundary(NAME):
            check_variant(NAME)
            self.mode = modes.current()
            read = PluginProperties(props)
            self.microfacet = Microfacet(read)
            interior, ambient = read.indices(("int_ior", DEFAULT_INT_IOR), ("ext_ior", DEFAULT_EXT_IOR))
            spec = read.stack_spec(interior, ambient)
            n_int, n_ext = interior.mean_real(), ambient.mean_real()
            if n_int == n_ext:
                raise ThinFilmError(f"'int_ior' ({interior.label}) and 'ext_ior' "
                                    f"({ambient.label}) must differ (mean index "
                                    f"{n_int:g} on both sides: a rough interface without "
                                    "refraction is undefined; use thinfilm_dielectric)")
            #: Relative index for directions (mean real indices, as thinfilm_dielectric).
            self.eta = n_int / n_ext
            self.specular_reflectance = read.factor("specular_reflectance")
            self.specular_transmittance = read.factor("specular_transmittance")
            read.check_unqueried()
            self.stack = build_stack(spec, sides={False: True, True: True}, plugin=NAME)
        # registered once complete: from here on every thread's symbolic calls trace it
        mi.BSDF.__init__(self, props)
        sides = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide | self.microfacet.flags
        self.m_components = [GLOSSY_R | sides, GLOSSY_T | sides | mi.BSDFFlags.NonSymmetric]
        self.m_flags = self.m_components[0] | self.m_components[1]
        self.guard = ParameterGuard(self, NAME)

    def _rt(self, si, dot_wi_m, cos_i, active, transmission: bool):
        """``R`` and ``T`` (or ``None``) of the films at the microfacet angle, and the
        :class:`modes.Response` they come from (its lobes).

        ``dot_wi_m`` has the sign of ``cos θ_i`` on every valid configuration;
        from inside (``cos θ_i < 0``) the reversed stack is used. ``T`` is set to
        0 where the mean-index direction is totally reflected, so directions and
        weights agree for dispersive media.
        """
        cos_m = dr.clip(dr.abs(dot_wi_m), 0.0, 1.0)
        inside = cos_i < 0
        resp = self.mode.response(self.stack, si, cos_m, active, inside=inside,
                                  transmission=transmission)
        if not transmission:
            return resp.R, None, resp
        _, cos_t, _, _ = mi.fresnel(dot_wi_m, mi.Float(self.eta))
        return resp.R, dr.select(cos_t == 0, 0.0, resp.T), resp

    def _factor(self, name, si, active):
        tex = getattr(self, name)
        return 1.0 if tex is None else tex.eval(si, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        has_r = ctx.is_enabled(GLOSSY_R, 0)
        has_t = ctx.is_enabled(GLOSSY_T, 1)
        bs = dr.zeros(mi.BSDFSample3f)
        if not (has_r or has_t):
            return bs, mi.Spectrum(0.0)
        cos_i = mi.Frame3f.cos_theta(si.wi)
        active = mi.Bool(active) & (cos_i != 0)
        distr = self.microfacet.distribution(si, active)
        sample_distr = self.microfacet.distribution(si, active, cos_theta_i=cos_i)
        m, pdf_m = sample_distr.sample(dr.mulsign(si.wi, cos_i), sample2)
        bs.pdf = pdf_m
        dot_wi_m = dr.dot(si.wi, m)
        active &= (bs.pdf != 0) & (dot_wi_m * cos_i > 0)
        _, cos_t, eta_it, eta_ti = mi.fresnel(dot_wi_m, mi.Float(self.eta))
        R, T, resp = self._rt(si, dot_wi_m, cos_i, active, transmission=has_t)

        if has_r and has_t:
            # detached: a sampling decision divides the weight as a constant
            # (see thinfilm_dielectric)
            prob_r = dr.detach(reflection_probability(R, T))
            selected_r = (sample1 <= prob_r) & active
            selected_t = (sample1 > prob_r) & active
            bs.pdf *= dr.select(selected_r, prob_r, 1.0 - prob_r)
            weight = chosen_weight(selected_r, prob_r, R, T)
        elif has_r:
            selected_r, selected_t = active, active & False
            weight = R
        else:
            selected_r, selected_t = active & False, active
            weight = T

        bs.sampled_component = dr.select(selected_r, mi.UInt32(0), mi.UInt32(1))
        bs.sampled_type = dr.select(selected_r, mi.UInt32(+GLOSSY_R), mi.UInt32(+GLOSSY_T))
        # No refraction beyond the critical angle (T = 0 there): no transmitted sample,
        # and the unused lane keeps a unit vector.
        selected_t &= cos_t != 0
        bs.eta = dr.select(selected_t, eta_it, 1.0)
        bs.wo = dr.select(selected_t, mi.refract(si.wi, m, cos_t, eta_ti), mi.reflect(si.wi, m))
        dot_wo_m = dr.dot(bs.wo, m)
        # Jacobians of the half-direction mappings (reflection, refraction)
        dwh_dwo = dr.select(selected_r, dr.rcp(4.0 * dot_wo_m),
                            dr.square(bs.eta) * dot_wo_m
                            / dr.square(dot_wi_m + bs.eta * dot_wo_m))
        bs.pdf *= dr.abs(dwh_dwo)

        weight = dr.select(selected_r, weight * self._factor("specular_reflectance", si, active),
                           weight * self._factor("specular_transmittance", si, active))
        if ctx.mode == mi.TransportMode.Radiance:
            weight = dr.select(selected_t, weight * dr.square(eta_ti), weight)
        if self.microfacet.sample_visible:
            weight *= distr.smith_g1(bs.wo, m)
        else:
            # D G |wi.m| / (pdf(m) |cos_i|): m was drawn from the widened D, so its
            # density is not D cos(theta_m). (Mitsuba 3's roughdielectric leaves out
            # D / pdf(m) * cos(theta_m) here, so its weights are not eval / pdf.)
            weight *= distr.eval(m) * distr.G(si.wi, bs.wo, m) * dr.abs(dot_wi_m) \
                / (dr.select(pdf_m > 0, pdf_m, 1.0) * dr.abs(cos_i))
        active &= selected_r | selected_t
        # Lanes without a sample: wo = 0 (Mitsuba's convention: no lobe of a
        # blendbsdf evaluates there), eta = 1, pdf = 0, weight 0.
        bs.wo = dr.select(active, bs.wo, 0.0)
        bs.pdf = dr.select(active, bs.pdf, 0.0)
        lobe = resp.reflection if not has_t else \
            self.mode.select(selected_r, resp.reflection, resp.transmission)
        return bs, dr.select(active, self.mode.value(weight, lobe, ctx, si.wi, bs.wo, m), 0.0)

    def _eval_pdf(self, ctx, si, wo, active, want_value: bool):
        has_r = ctx.is_enabled(GLOSSY_R, 0)
        has_t = ctx.is_enabled(GLOSSY_T, 1)
        if not (has_r or has_t):
            return mi.Spectrum(0.0), mi.Float(0.0)
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        reflect = cos_i * cos_o > 0
        refract = cos_i * cos_o < 0
        active = mi.Bool(active) & (cos_i != 0) & ((reflect & has_r) | (refract & has_t))
        # Relative index seen from the incident side, and the generalised half vector
        eta = dr.select(cos_i > 0, self.eta, 1.0 / self.eta)
        m = dr.normalize(si.wi + wo * dr.select(reflect, 1.0, eta))
        m = dr.mulsign(m, mi.Frame3f.cos_theta(m))
        dot_wi_m, dot_wo_m = dr.dot(si.wi, m), dr.dot(wo, m)
        # The micro- and macrosurface must agree on the side of both directions
        # (smith_g1 zeroes these in eval and sample; the density must agree).
        active &= (dot_wi_m * cos_i > 0) & (dot_wo_m * cos_o > 0)
        dwh_dwo = dr.select(reflect, dr.rcp(4.0 * dot_wo_m),
                            eta * eta * dot_wo_m / dr.square(dot_wi_m + eta * dot_wo_m))
        sample_distr = self.microfacet.distribution(si, active, cos_theta_i=cos_i)
        pdf = sample_distr.pdf(dr.mulsign(si.wi, cos_i), m) * dr.abs(dwh_dwo)
        # The films are needed for the value, and for the density when R and T compete.
        if not (want_value or (has_r and has_t)):
            return None, dr.select(active, pdf, 0.0)
        R, T, resp = self._rt(si, dot_wi_m, cos_i, active, transmission=has_t)
        if has_r and has_t:
            prob_r = reflection_probability(R, T)
            pdf *= dr.select(reflect, prob_r, 1.0 - prob_r)
        pdf = dr.select(active, pdf, 0.0)
        if not want_value:
            return None, pdf

        distr = self.microfacet.distribution(si, active)
        DG = distr.eval(m) * distr.G(si.wi, wo, m)
        value_r = R * self._factor("specular_reflectance", si, active) \
            * (DG / (4.0 * dr.abs(cos_i)))
        if has_t:
            # (eta_i / eta_t)^2 for radiance: the solid-angle compression on refraction
            scale = dr.square(1.0 / eta) if ctx.mode == mi.TransportMode.Radiance else 1.0
            value_t = T * self._factor("specular_transmittance", si, active) * dr.abs(
                scale * DG * eta * eta * dot_wi_m * dot_wo_m
                / (cos_i * dr.square(dot_wi_m + eta * dot_wo_m)))
            value = dr.select(reflect, value_r, value_t)
            lobe = self.mode.select(reflect, resp.reflection, resp.transmission)
        else:
            value, lobe = value_r, resp.reflection
        return dr.select(active, self.mode.value(value, lobe, ctx, si.wi, wo, m), 0.0), pdf

    def to_string(self):
        return (f"ThinFilmRoughDielectric[\n{self.microfacet.describe()}"
                f"  layers = {self.stack.describe()},\n"
                f"  int_ior = {self.stack.substrate.label},\n"
                f"  ext_ior = {self.stack.ambient.label}\n]")
