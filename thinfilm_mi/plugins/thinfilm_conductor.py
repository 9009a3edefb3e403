r"""
.. _bsdf-thinfilm_conductor:

Thin-film coated smooth conductor (:monosp:`thinfilm_conductor`)
----------------------------------------------------------------

.. shared-rows: conductor
.. pluginparameters::

 * - layers
   - |string|
   - The film stack from the outside in, ``"MATERIAL THICKNESS_NM; ..."``, e.g.
     ``"SiO2 500"`` or ``"1.46 500; 0.42+2.47j 20"``. A material is a number,
     a complex number ``n+kj``, or a material name (``python -m thinfilm_mi
     materials`` lists them). Default: ``""`` (no films: a bare conductor).
 * - thin_film_ior, thin_film_thickness
   - |string| or |float|, |float|
   - Shorthand for one film (index or material name, thickness in nm), named as
     in Blender and OpenPBR. Not together with ``layers``.
 * - material
   - |string|
   - The substrate: a material name, e.g. ``Au``, ``Cu``, ``Si`` (default: ``Au``).
     Not together with ``eta``/``k``.
 * - eta, k
   - |spectrum| or |texture|
   - The substrate's index ``eta + i k`` given directly, as Mitsuba's
     ``conductor`` takes it (both must be given).
 * - ext_ior
   - |float| or |string|
   - Exterior index (real), a number or a non-absorbing material name
     (default: 1.000277, air).
 * - specular_reflectance
   - |spectrum| or |texture|
   - Optional factor on the reflectance; physically it should stay 1 (default: 1.0).
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

A perfectly smooth conductor (metal or semiconductor substrate) under a stack of
thin films, each of which may be dielectric, metallic or semiconducting (complex
index). The reflectance is the exact composite reflectance of the multilayer
(Rouard's recursion, Hirayama et al. eq. 1-5), evaluated at the path's
wavelengths in the render kernel, for unpolarised light in ``*_spectral``
variants. In ``*_spectral_polarized`` variants it returns the Mueller matrix of
the stack's complex amplitudes ``r_s``, ``r_p`` (exact, or its components read
from a table, see ``tabulate``), rotated
into Mitsuba's Stokes bases as Mitsuba's ``conductor`` does; with no films it
equals ``conductor``'s matrix.

In RGB and mono variants (``*_rgb``, ``*_mono``; polarized ones are refused) the
reflectance is the spectral reflectance integrated against colour matching: CIE 1931
2° under D65 to linear sRGB, normalised so that a perfect reflector gives (1, 1, 1),
or the luminance Y in mono; this is the convention of Mitsuba's spectral pipeline,
so an RGB render and a spectral render of a scene agree. It is tabulated over the
angle at scene load with the float64 recursion (``thinfilm_mi/tabulate/integrated.py``; over
the angle and the thickness scale with a ``thickness`` texture), so a deep stack
costs what one film costs at render time; ``tabulate``, ``table_error`` and
``spectral_resolution`` do not apply. ``eta``/``k`` given as ``rgb`` evaluate per
channel, as in ``conductor`` (with no films the plugin *is* ``conductor``); films
over them are integrated per channel with that channel's constant index.
``specular_reflectance`` multiplies per channel. Gradients of thicknesses and
numeric indices in ``llvm_ad_rgb``: the value is the table's, and the gradient that
of an unbiased estimate of the same integral at stratified wavelengths per hit (the
exact recursion through every film), traced only when a parameter carries gradients.

The layer thicknesses (``layers.N.thickness``, nm) and numeric indices
(``layers.N.eta.value``, ``layers.N.k.value``) are exposed to ``mi.traverse``
as differentiable, opaque parameters: changing them does not recompile the
render kernel (a table is rebuilt, ~10-30 ms, and its shape is a kernel input
too). In exact mode the kernel reads the films' indices and thicknesses from
buffers, film by film below 4 films and by a loop from 4 films on, so the kernel
and its compile time do not grow with the number of films.

.. tabs::
    .. code-tab:: xml

        <bsdf type="thinfilm_conductor">
            <string name="material" value="Si"/>
            <string name="layers" value="SiO2 500"/>
        </bsdf>

    .. code-tab:: python

        {'type': 'thinfilm_conductor', 'material': 'Si', 'layers': 'SiO2 500'}
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from thinfilm_mi.errors import plugin_boundary
from thinfilm_mi.render import modes
from thinfilm_mi.render.kernel import build_stack
from thinfilm_mi.render.params import ParameterGuard
from thinfilm_mi.render.reader import PluginProperties
from thinfilm_mi.render.variant import check_variant

__all__ = ["NAME", "ThinFilmConductor"]

NAME = "thinfilm_conductor"


class ThinFilmConductor(mi.BSDF):
    def __init__(self, props):
        with plugin_boundary(NAME):
            check_variant(NAME)
            self.mode = modes.current()
            read = PluginProperties(props)
            substrate = read.substrate()
            spec = read.stack_spec(substrate)
            self.specular_reflectance = read.factor("specular_reflectance")
            read.check_unqueried()
            self.stack = build_stack(spec, plugin=NAME)
        # registered once complete: from here on every thread's symbolic calls trace it
        mi.BSDF.__init__(self, props)
        flags = mi.BSDFFlags.DeltaReflection | mi.BSDFFlags.FrontSide
        self.m_components = [flags]
        self.m_flags = flags
        self.guard = ParameterGuard(self, NAME)

    def sample(self, ctx, si, sample1, sample2, active=True):
        bs = dr.zeros(mi.BSDFSample3f)
        if not ctx.is_enabled(mi.BSDFFlags.DeltaReflection):
            return bs, mi.Spectrum(0.0)
        cos_i = mi.Frame3f.cos_theta(si.wi)
        active = mi.Bool(active) & (cos_i > 0)
        resp = self.mode.response(self.stack, si, cos_i, active)
        value = resp.R
        if self.specular_reflectance is not None:
            value *= self.specular_reflectance.eval(si, active)
        bs.wo = mi.reflect(si.wi)
        bs.eta = 1.0
        bs.pdf = 1.0
        bs.sampled_component = mi.UInt32(0)
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DeltaReflection)
        return bs, dr.select(active, self.mode.value(value, resp.reflection, ctx, si.wi, bs.wo),
                             0.0)

    def eval(self, ctx, si, wo, active=True):
        return mi.Spectrum(0.0)

    def pdf(self, ctx, si, wo, active=True):
        return mi.Float(0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return mi.Spectrum(0.0), mi.Float(0.0)

    def traverse(self, callback):
        self.stack.traverse(callback)
        if self.specular_reflectance is not None:
            callback.put("specular_reflectance", self.specular_reflectance,
                         mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        self.guard.changed(self, self.stack.parameters_changed, keys)

    def to_string(self):
        return (f"ThinFilmConductor[\n  layers = {self.stack.describe()},\n"
                f"  substrate = {self.stack.substrate.label},\n"
                f"  ext_ior = {self.stack.ambient.label}\n]")
