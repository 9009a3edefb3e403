r"""
.. _bsdf-thinfilm_roughconductor:

Thin-film coated rough conductor (:monosp:`thinfilm_roughconductor`)
--------------------------------------------------------------------

.. shared-rows: conductor
.. pluginparameters::

 * - layers
   - |string|
   - The film stack from the outside in, ``"MATERIAL THICKNESS_NM; ..."``, e.g.
     ``"SiO2 300; TiO2 60"``. Default: ``""`` (no films: exactly Mitsuba's
     ``roughconductor``).
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
 * - material
   - |string|
   - The substrate: a material name, e.g. ``Au``, ``Cu``, ``Si`` (default: ``Au``).
     Not together with ``eta``/``k``.
 * - eta, k
   - |spectrum| or |texture|
   - The substrate's index ``eta + i k`` given directly, as Mitsuba's
     ``roughconductor`` takes it (both must be given).
 * - ext_ior
   - |float| or |string|
   - Exterior index (real), a number or a non-absorbing material name
     (default: 1.000277, air).
 * - distribution
   - |string|
   - The microfacet normal distribution: ``beckmann`` (default) or ``ggx``.
 * - alpha, alpha_u, alpha_v
   - |float| or |texture|
   - Roughness (RMS slope for Beckmann, as in Mitsuba), isotropic (``alpha``,
     default 0.1) or along the tangent and bitangent (``alpha_u`` and
     ``alpha_v``, both or neither, not with ``alpha``). Numbers must be > 0
     (use ``thinfilm_conductor`` for a smooth surface). Exposed as ``alpha``
     or ``alpha_u``/``alpha_v``, |differentiable|, |discontinuous|.
 * - sample_visible
   - |bool|
   - Sample only the visible normals (Heitz and d'Eon), as Mitsuba (default: true).
 * - specular_reflectance
   - |spectrum| or |texture|
   - Optional factor on the reflectance; physically it should stay 1 (default: 1.0).
 * - tabulate
   - |string| or |bool|
   - ``auto`` (default), ``true`` or ``false``: whether ``R`` (and ``T``) is read from a
     verified table over (angle, wavelength), whose cost does not grow with the films,
     instead of the recursion. ``auto`` tabulates every stack with films in vectorised
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

A rough conductor (metal or semiconductor substrate) under a stack of thin films,
with the microfacet model of Mitsuba's ``roughconductor`` (Walter et al. 2007;
Smith shadowing-masking, visible-normal sampling): the films follow the
microsurface, so each microfacet reflects with the exact composite reflectance
``R(λ, cos θ_m)`` of the multilayer at its own angle of incidence
``cos θ_m = dot(ω_i, m)``::

    f(ω_i, ω_o) cos θ_o = R(λ, dot(ω_i, m)) D(m) G(ω_i, ω_o, m) / (4 cos θ_i)

with ``m`` the half vector. ``D``, ``G``, the sampling routine and its density
are Mitsuba's ``MicrofacetDistribution``; ``R`` is the thin-film recursion
(Hirayama et al. eq. 1-5) for unpolarised light, evaluated at the path's
wavelengths in the render kernel. The layer parameters appear in
``mi.traverse`` as for ``thinfilm_conductor``. In ``*_spectral_polarized``
variants ``R`` becomes the Mueller matrix of the stack's amplitudes (exact or
tabulated, see ``tabulate``) at the microfacet, rotated about ``m`` as Mitsuba's ``roughconductor`` does (with no
films: its matrix).

In RGB and mono variants (``*_rgb``, ``*_mono``; polarized ones are refused) each
microfacet's Fresnel term is the spectral reflectance integrated against colour
matching: CIE 1931 2° under D65 to linear sRGB, normalised so that a perfect
reflector gives (1, 1, 1), or the luminance Y in mono; this is the convention of
Mitsuba's spectral pipeline, so an RGB render and a spectral render of a scene
agree. It is tabulated over the angle at scene load with the float64 recursion
(``thinfilm_mi/tabulate/integrated.py``; over the angle and the thickness scale with a
``thickness`` texture), so a deep stack costs what one film costs at render time;
``tabulate``, ``table_error`` and ``spectral_resolution`` do not apply.
``eta``/``k`` given as ``rgb`` evaluate per channel, as in ``roughconductor``; films
over them are integrated per channel with that channel's constant index.
``specular_reflectance`` multiplies per channel. Gradients of thicknesses and
numeric indices in ``llvm_ad_rgb``: the value is the table's, and the gradient that
of an unbiased estimate of the same integral at stratified wavelengths per hit (the
exact recursion through every film), traced only when a parameter carries gradients.

.. tabs::
    .. code-tab:: xml

        <bsdf type="thinfilm_roughconductor">
            <string name="material" value="Au"/>
            <string name="layers" value="SiO2 300; TiO2 60"/>
            <string name="distribution" value="ggx"/>
            <float name="alpha" value="0.15"/>
        </bsdf>

    .. code-tab:: python

        {'type': 'thinfilm_roughconductor', 'material': 'Au',
         'layers': 'SiO2 300; TiO2 60', 'distribution': 'ggx', 'alpha': 0.15}
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from thinfilm_mi.errors import plugin_boundary
from thinfilm_mi.render import modes
from thinfilm_mi.render.kernel import build_stack
from thinfilm_mi.render.microfacet import Microfacet, rough_bsdf_base
from thinfilm_mi.render.params import ParameterGuard
from thinfilm_mi.render.reader import PluginProperties
from thinfilm_mi.render.variant import check_variant

__all__ = ["NAME", "ThinFilmRoughConductor"]

NAME = "thinfilm_roughconductor"


class ThinFilmRoughConductor(rough_bsdf_base()):
    def __init__(self, props):
        with plugin_boundary(NAME):
            check_variant(NAME)
            self.mode = modes.current()
            read = PluginProperties(props)
            self.microfacet = Microfacet(read)
            substrate = read.substrate()
            spec = read.stack_spec(substrate)
            self.specular_reflectance = read.factor("specular_reflectance")
            read.check_unqueried()
            self.stack = build_stack(spec, plugin=NAME)
        # registered once complete: from here on every thread's symbolic calls trace it
        mi.BSDF.__init__(self, props)
        flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | self.microfacet.flags
        self.m_components = [flags]
        self.m_flags = flags
        self.guard = ParameterGuard(self, NAME)

    def _reflectance(self, si, cos_theta_m, active):
        """Composite reflectance of the films at the microfacet angle (times the factor),
        and its lobe for :meth:`modes.SpectralMode.value`."""
        resp = self.mode.response(self.stack, si, dr.clip(cos_theta_m, 0.0, 1.0), active)
        value = resp.R
        if self.specular_reflectance is not None:
            value *= self.specular_reflectance.eval(si, active)
        return value, resp.reflection

    def sample(self, ctx, si, sample1, sample2, active=True):
        bs = dr.zeros(mi.BSDFSample3f)
        if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection):
            return bs, mi.Spectrum(0.0)
        cos_i = mi.Frame3f.cos_theta(si.wi)
        active = mi.Bool(active) & (cos_i > 0)
        distr = self.microfacet.distribution(si, active)
        m, bs.pdf = distr.sample(si.wi, sample2)
        bs.wo = mi.reflect(si.wi, m)
        bs.eta = 1.0
        bs.sampled_component = mi.UInt32(0)
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        cos_m = dr.dot(si.wi, m)
        active &= (bs.pdf != 0) & (mi.Frame3f.cos_theta(bs.wo) > 0) & (cos_m > 0)
        if self.microfacet.sample_visible:
            weight = distr.smith_g1(bs.wo, m)
        else:
            weight = distr.G(si.wi, bs.wo, m) * cos_m / (cos_i * mi.Frame3f.cos_theta(m))
        # Jacobian of the half-direction mapping
        bs.pdf = dr.select(active, bs.pdf / (4.0 * dr.dot(bs.wo, m)), 0.0)
        # A rejected sample has no direction (wo = 0, as Mitsuba's roughdielectric
        # leaves it): a blendbsdf re-weighting by the other lobe's eval/pdf at wo
        # then finds 0 there, as it finds 0 below the horizon for roughconductor.
        bs.wo = dr.select(active, bs.wo, 0.0)
        R, lobe = self._reflectance(si, cos_m, active)
        value = self.mode.value(R * weight, lobe, ctx, si.wi, bs.wo, m)
        return bs, dr.select(active, value, 0.0)

    def _eval_pdf(self, ctx, si, wo, active, want_value: bool):
        if not ctx.is_enabled(mi.BSDFFlags.GlossyReflection):
            return mi.Spectrum(0.0), mi.Float(0.0)
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        m = dr.normalize(wo + si.wi)
        # Filter the cases where the micro- and macrosurface disagree on the side
        # (smith_g1 zeroes them in eval and sample; the density must agree).
        active = mi.Bool(active) & (cos_i > 0) & (cos_o > 0) \
            & (dr.dot(si.wi, m) > 0) & (dr.dot(wo, m) > 0)
        distr = self.microfacet.distribution(si, active)
        D = distr.eval(m)
        if self.microfacet.sample_visible:
            pdf = D * distr.smith_g1(si.wi, m) / (4.0 * cos_i)
        else:
            pdf = distr.pdf(si.wi, m) / (4.0 * dr.dot(wo, m))
        pdf = dr.select(active, pdf, 0.0)
        if not want_value:
            return None, pdf
        active &= D != 0
        R, lobe = self._reflectance(si, dr.dot(si.wi, m), active)
        value = self.mode.value(R * (D * distr.G(si.wi, wo, m) / (4.0 * cos_i)), lobe, ctx,
                                si.wi, wo, m)
        return dr.select(active, value, 0.0), pdf

    def to_string(self):
        return (f"ThinFilmRoughConductor[\n{self.microfacet.describe()}"
                f"  layers = {self.stack.describe()},\n"
                f"  substrate = {self.stack.substrate.label},\n"
                f"  ext_ior = {self.stack.ambient.label}\n]")
