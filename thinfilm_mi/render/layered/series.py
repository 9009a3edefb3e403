"""The estimator over a diffuse bottom (no plugin classes here): ``thinfilm_diffuse``'s
model, a :class:`~thinfilm_mi.render.layered.top.SmoothTop` (the films, and for the paper's
models an absorbing innermost film ``N`` under it) over a
:class:`~thinfilm_mi.render.layered.bottom.DiffuseBottom`, its sum over paths in the
closed form of a :class:`~thinfilm_mi.render.layered.models.DiffuseModel` (the physics are
written in ``thinfilm_diffuse``'s doc block).

As pbrt-v4's ``CoatedDiffuseBxDF`` is its ``LayeredBxDF`` over a diffuse bottom, a
:class:`SeriesEstimator` gives the BSDF's samples, values and pdfs, its load-time terms
(``R_dh``, ``T_hemi``, the RGB/mono tables, ``R_dh``'s derivatives), film ``N``'s
parameters and their edits; :func:`series_parts` makes its top, medium (film ``N``) and
options from the films, for the engine's
:func:`~thinfilm_mi.render.layered.engine.layered`.
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import GRID
from thinfilm_mi.optics.core import Cx, film_attenuation
from thinfilm_mi.render.colour_variants import (
    GradientSampler,
    attach_gradient,
    colour_channels,
    index_on_wavelengths,
    prepare_gradients,
)
from thinfilm_mi.render.kernel import KernelStack
from thinfilm_mi.render.layered.factors import (
    IndexGradients,
    SpectralTerms,
    colour_diffuse,
    constant_albedo,
    factor_table,
    texture_gradients_refused,
    with_derivatives,
)
from thinfilm_mi.render.layered.top import SmoothTop
from thinfilm_mi.render.textures import mitsuba_module
from thinfilm_mi.render.variant import spectral_mean
from thinfilm_mi.tabulate.hemispherical import DerivativeTable
from thinfilm_mi.tabulate.policy import COATING_RT_MIN_FILMS

__all__ = ["SeriesEstimator", "series_parts"]


def series_parts(model, films, ext, base, options: dict, mode):
    """``(top, medium, own)``: the parts of ``model``'s (a
    :class:`~thinfilm_mi.render.layered.models.DiffuseModel`) layer for ``films``
    (``[(SpectralIndex, thickness nm)]``, outside in) between the ambient ``ext`` and the
    base medium ``base`` (``SpectralIndex``), for
    :func:`~thinfilm_mi.render.layered.engine.layered`: the
    :class:`~thinfilm_mi.render.layered.top.SmoothTop` of its coating, the paper's film ``N``
    under it (``(SpectralIndex, thickness)``, or ``(None, None)``) and the
    :class:`SeriesEstimator`'s own options; ``options``: the stack's
    (:meth:`~thinfilm_mi.render.reader.PluginProperties.stack_options`); ``mode``: the
    variant's :mod:`~thinfilm_mi.render.modes` mode."""
    coating, exit_medium, film_n, film_n_thickness = model.split(films, ext, base)
    # RGB/mono: only k_r from the colour table; t enters through the diffuse table
    stack = KernelStack(coating, ext, exit_medium, sides={False: not mode.integrated},
                        rt_min_films=COATING_RT_MIN_FILMS, **options)
    base_ratio = model.base_ratio(ext, base)
    bare = not films and (not base_ratio or np.array_equal(
        base.spectral_values(GRID, real=True), ext.spectral_values(GRID, real=True)))
    return SmoothTop(stack, mode), (film_n, film_n_thickness), dict(
        model=model, base_ratio=base_ratio, bare=bare, texture=options["thickness_texture"])


class _FilmParameters:
    """A traversal callback that collects the Dr.Jit values of the films' parameters
    (``layers.*``; a texture's own parameters included)."""

    def __init__(self):
        self.values = []

    def put(self, key, value, flags):
        if not key.startswith("layers."):
            return
        mi = mitsuba_module()
        if isinstance(value, mi.Object):
            params = mi.traverse(value)
            self.values.extend(params[k] for k in params.keys())
        else:
            self.values.append(value)


class SeriesEstimator:
    """The closed form of ``model`` (a :class:`~thinfilm_mi.render.layered.models.DiffuseModel`)
    for ``top`` (a :class:`~thinfilm_mi.render.layered.top.SmoothTop`) over the medium
    ``medium``, the paper's film ``N`` (``(SpectralIndex, thickness)``, or ``(None, None)``),
    and ``bottom`` (a :class:`~thinfilm_mi.render.layered.bottom.DiffuseBottom`);
    ``base_ratio``: whether ``t`` carries ``n_0/n_b``; ``bare``: no films and no interface;
    ``texture``: the ``thickness`` texture or ``None`` (:func:`series_parts` gives the
    parts).

    Component 0 is the top's delta reflection, component 1 the diffuse lobe. :attr:`bare`:
    no films and no interface (the base medium is the ambient): exactly Mitsuba's
    ``diffuse`` (or the rough base alone), with no stack work."""

    def __init__(self, top, bottom, medium, mode, plugin: str, model, base_ratio: bool,
                 bare: bool, texture):
        self.model, self.mode, self.plugin = model, mode, plugin
        self.top, self.bottom = top, bottom
        self.texture = texture
        self.film_n, self.film_n_thickness = medium
        #: t carries n_0/n_b (a base medium unlike the ambient)
        self.base_ratio = base_ratio
        #: no films and no interface (a base medium of the ambient's index): Mitsuba's diffuse
        self.bare = bare
        #: spectral variants: R_dh and T_hemi (SpectralTerms)
        self.terms = None
        #: RGB/mono variants: the diffuse term integrated as a product (ColourDiffuse)
        self.colour = None
        #: R_dh's derivative table, while a film parameter carries gradients
        self.r_dh_grad = None
        #: spectral JIT variants: the model's table (``factors.factor_table``) or None
        self.table = None
        self.index_gradients = IndexGradients()   #: whether an index carries gradients
        self.update()

    coating = property(lambda self: self.top.stack, doc="The top's ``KernelStack``.")

    # -- load-time terms -------------------------------------------------------
    def factors(self):
        """The spectral factors at the current parameters (``None`` when :attr:`bare`)."""
        if self.bare:
            return None
        return self.model.factors(self.coating, self.film_n, self.film_n_thickness)

    def update(self) -> None:
        """Recompute ``T_hemi`` and ``R_dh`` (float64) from the current parameters; in
        RGB/mono variants the integrated diffuse tables instead. In AD variants also
        ``R_dh``'s derivatives (:attr:`r_dh_grad`)."""
        factors = self.factors()
        self.index_gradients.collect(self.media())
        self.r_dh_grad = None
        self.update_derivatives()
        if self.mode.integrated:
            if factors is not None:
                self.colour = colour_diffuse(factors, self.texture, self.model, colour_channels(),
                                             constant_albedo(self.bottom.reflectance, self.bottom.rough),
                                             self.plugin)
                if self.film_n is not None and dr.is_diff_v(mitsuba_module().Float):
                    prepare_gradients([self.film_n])
            return
        self.terms = SpectralTerms(factors, self.texture, self.plugin, self.terms)
        self.table = None
        self.update_table(factors)

    def update_table(self, factors) -> None:
        """Build a missing :attr:`table` unless a film parameter carries gradients (unread)."""
        if self.table is None and not self.film_gradients():
            self.table = factor_table(factors, self.coating, self.texture, self.media())

    def media(self):
        """The indices of the ambient, the base medium, the films and film ``N``."""
        c = self.coating
        return [c.ambient, c.substrate] + c.indices + ([] if self.film_n is None else [self.film_n])

    def table_at(self, si, active):
        """``(table, the hit's wavelength cells)``; ``None`` without a table or where a film
        parameter carries gradients (:attr:`index_gradients`: no texture evaluated, so that
        Dr.Jit merges the reads at ``θ_i`` of ``eval_pdf`` and ``sample``)."""
        coating = self.coating
        if self.table is None or coating.current_plan(False, True) is not coating.plan.get(False) \
                or (self.film_n is not None and dr.grad_enabled(self.film_n_thickness)) \
                or any(self.index_gradients(ix, si, active) for ix in self.media()):
            return None
        return self.table, self.table.cells(si.wavelengths)

    def film_gradients(self) -> bool:
        """Whether a film parameter (a ``layers.*`` value) carries gradients."""
        mi = mitsuba_module()
        if not dr.is_diff_v(mi.Float):
            return False
        found = _FilmParameters()
        self.top.traverse(found)
        self.traverse(found)
        return any(dr.is_diff_v(v) and dr.grad_enabled(v) for v in found.values)

    def update_derivatives(self) -> None:
        """``R_dh``'s derivative table: built if a film parameter carries gradients and it is
        missing, kept if it is there, dropped when nothing carries gradients (or for a
        model without interreflection, or no stack). Never needed at scene load, where
        nothing carries gradients: the reverse-mode pass then never runs on Mitsuba's
        loader threads."""
        factors = self.factors()
        if factors is None or not self.model.interreflection or not self.film_gradients():
            self.r_dh_grad = None
        elif self.r_dh_grad is None:
            self.r_dh_grad = DerivativeTable(factors.r_dh_partials(GRID))
        if self.r_dh_grad is not None and self.texture is not None:
            self.r_dh_grad = None
            raise ThinFilmError(texture_gradients_refused(self.plugin, self.model))

    # -- kernel pieces ---------------------------------------------------------
    def transmission(self, si, cos_theta, k_t, active):
        """``t`` at the hit from the coating's ``k_t`` (``mi.UnpolarizedSpectrum``): times
        ``k_a`` of film ``N`` (its thickness times the texture's scale), times ``n_0/n_b``
        over a base medium unlike the ambient."""
        mi = mitsuba_module()
        n0 = self.coating.ambient.eval_real(si, active)
        if self.film_n is not None:
            scale = self.coating.thickness_scale_at(si, active)
            d = self.film_n_thickness if scale is None else self.film_n_thickness * scale
            grid = self.terms.film_n if self.terms is not None else None
            if grid is None or self.film_n.carries_gradients(si, active):
                n_film = self.film_n.eval(si, active)
            else:
                n_film = grid.index(si.wavelengths)
            k_t = k_t * film_attenuation(n0, cos_theta, n_film, d, si.wavelengths)
        if self.base_ratio:
            k_t = k_t * n0 / self.coating.substrate.eval_real(si, active)
        # (the polarized amplitudes of a scaled stack come back as plain Array4f)
        return mi.UnpolarizedSpectrum(k_t)

    def factors_at(self, si, cos_theta, active, transmission: bool, lobe: bool = False,
                   reflectance: bool = True):
        """``k_r``, (if asked) ``t = k_t k_a`` at ``cos_theta`` (ambient side), (if ``lobe``)
        the lobe of ``k_r`` for :meth:`modes.SpectralMode.value`. From the :attr:`table`
        where it applies (``k_r`` ``None`` unless ``reflectance``; a polarized lobe's shape
        from the stack's amplitudes)."""
        mi = mitsuba_module()
        table = self.table_at(si, active)
        if table is not None:
            k_r, t, _, _ = table[0].lookup(cos_theta, table[1], active,
                                           reflectance or not transmission)
            shape = self.top.response(si, cos_theta, active).reflection \
                if lobe and self.mode.polarized else None   # (k_r: the table's, as eval_pdf's)
            return k_r, t if transmission else None, shape
        resp = self.top.response(si, cos_theta, active, transmission=transmission)
        k_r = mi.UnpolarizedSpectrum(resp.R)
        if not transmission:
            return k_r, None, resp.reflection
        return k_r, self.transmission(si, cos_theta, resp.T, active), resp.reflection

    def terms_at(self, si, active):
        """``(R_dh, T_hemi)`` at the hit's wavelengths (without ``R_dh``'s derivatives): from
        the :attr:`table`'s read at ``θ_i`` where it applies, else :attr:`terms`."""
        table = self.table_at(si, active)
        if table is not None:
            return table[0].lookup(mitsuba_module().Frame3f.cos_theta(si.wi), table[1], active)[2:]
        return self.terms.lookup(si, self.coating, active)

    def r_dh_with_derivatives(self, r_dh, si, wavelengths, index_at, active):
        """``R_dh`` carrying its derivatives (:func:`~thinfilm_mi.render.layered.factors.with_derivatives`;
        as is without interreflection or stack)."""
        if not self.model.interreflection or self.bare:
            return r_dh
        films = list(zip(self.coating.indices, self.coating.thickness))
        if self.film_n is not None:
            films.append((self.film_n, self.film_n_thickness))
        return with_derivatives(self.r_dh_grad, r_dh, films, si, wavelengths, index_at, active,
                                self.coating.plugin, self.index_gradients)

    def r_dh(self, si, active):
        """``R_dh`` at the hit's wavelengths, with its derivatives."""
        return self.r_dh_with_derivatives(self.terms_at(si, active)[0], si,
                                          si.wavelengths, lambda ix: ix.eval(si, active), active)

    def series(self, si, kd, active):
        """``G(k_d, R_dh) / k_d`` at the hit (spectral variants)."""
        return self.model.kernel_series(kd, lambda: self.r_dh(si, active))

    def colour_scale(self, si, active):
        """The thickness scale at the hit for the colour table if it is one over the
        scale, else ``None``."""
        return self.coating.thickness_scale_at(si, active) if self.colour.scaled else None

    def colour_gradients(self, si, active) -> bool:
        """RGB/mono AD variants: whether a film thickness or index carries gradients."""
        n = self.film_n
        return self.coating.colour_gradients(si, active) or (n is not None and (
            dr.grad_enabled(self.film_n_thickness) or n.carries_gradients(si, active)))

    def colour_estimate(self, si, cos_i, cos_o, active, g):
        """An unbiased estimate of the integrated diffuse term at stratified wavelengths
        (:class:`~thinfilm_mi.render.colour_variants.GradientSampler`), whose gradients the table's
        value takes; ``g(c, R_dh)``: the base's term of channel ``c`` (``G(k_d,c, R_dh)``
        for Lambert's), ``R_dh`` with its derivatives; the thickness texture scales every
        film."""
        mi = mitsuba_module()
        coating, film_n = self.coating, self.film_n
        sampler = GradientSampler.get()
        wl = sampler.wavelengths(si)
        scale = coating.thickness_scale_at(si, active)
        n0, _ = index_on_wavelengths(coating.ambient, si, wl, active)

        def t(cos):
            _, k_t = coating.at_wavelengths(False, si, cos, active, True, scale, wl)
            if self.base_ratio:
                k_t = k_t * n0 / index_on_wavelengths(coating.substrate, si, wl, active)[0]
            if film_n is None:
                return k_t
            d = self.film_n_thickness if scale is None else self.film_n_thickness * scale
            return k_t * film_attenuation(n0, cos, Cx(*index_on_wavelengths(film_n, si, wl, active)),
                                          d, wl)
        product = t(cos_i) * t(cos_o)
        r_dh = self.r_dh_with_derivatives(self.colour.r_dh_at(wl, active), si, wl,
                                          lambda ix: Cx(*index_on_wavelengths(ix, si, wl, active)), active)
        channels = [sampler.estimate(wl, product * g(c, r_dh))[c] for c in range(dr.size_v(mi.Spectrum))]
        return mi.Spectrum(*channels)

    def diffuse(self, si, kd, cos_i, wo, t_i, series, active):
        """``π f`` towards ``wo``: ``k_d t_i t_o S`` per wavelength (over a rough base:
        ``t_i t_o`` times the model's :meth:`DiffuseModel.rough_series`), or its integral
        over wavelengths in RGB/mono variants."""
        cos_o = mitsuba_module().Frame3f.cos_theta(wo)
        base = self.bottom.terms(si, kd, wo, active) if self.bottom.rough else None
        if self.colour is not None:
            scale = self.colour_scale(si, active)
            if base is None:
                value = self.colour.value(cos_i, cos_o, kd, active, scale)
                g = lambda c, r_dh: self.colour.series(kd[c], r_dh)
            else:
                value = self.model.rough_integrated(self.colour.node_values(cos_i, cos_o, active, scale),
                                                    base)
                g = lambda c, r_dh: self.model.rough_series(base.channel(c), lambda: r_dh)
            if self.colour_gradients(si, active):
                value = attach_gradient(value, self.colour_estimate(si, cos_i, cos_o, active, g))
            return value
        _, t_o, _ = self.factors_at(si, cos_o, active, transmission=True, reflectance=False)
        if base is not None:
            return t_i * t_o * self.model.rough_series(base, lambda: self.r_dh(si, active))
        return kd * t_i * t_o * series

    def prob_specular(self, si, k_r, t_i, kd, series, active, cos_i):
        """The probability of choosing the delta component: the spectral mean of ``k_r``
        against that of the diffuse albedo estimate ``t_i k_d T_hemi S`` (the colour
        table's in RGB/mono variants)."""
        spec = spectral_mean(k_r)
        if self.colour is not None:
            diff = spectral_mean(self.colour.albedo(cos_i, kd, active, self.colour_scale(si, active)))
        else:
            diff = spectral_mean(t_i * kd * self.terms_at(si, active)[1] * series)
        total = spec + diff
        return dr.select(total > 0, spec / dr.select(total > 0, total, 1.0), 0.0)

    # -- the BSDF --------------------------------------------------------------
    def sample(self, ctx, si, sample1, sample2, active, has_spec: bool, has_diff: bool):
        """``(BSDFSample3f, weight)`` as Mitsuba's ``BSDF.sample``, with the components
        ``has_spec`` (0) and ``has_diff`` (1) enabled."""
        mi = mitsuba_module()
        self.bottom.check()
        bs = dr.zeros(mi.BSDFSample3f)
        cos_i = mi.Frame3f.cos_theta(si.wi)
        active = mi.Bool(active) & (cos_i > 0)
        if not (has_spec or has_diff) or (self.bare and not has_diff):
            return bs, mi.Spectrum(0.0)

        if self.bare:  # exactly Mitsuba's diffuse (component index 1 here)
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            bs.sampled_component = mi.UInt32(1)
            value = self.mode.value(self.bottom.bare_value(si, bs.wo, active), self.mode.depolarized,
                                    ctx, si.wi, bs.wo)
            return bs, dr.select(active & (bs.pdf > 0), value, 0.0)

        spectral = self.colour is None
        k_r, t_i, spec_lobe = self.factors_at(si, cos_i, active, transmission=has_diff and spectral,
                                              lobe=True)
        kd = series = None
        if has_diff:
            kd = self.bottom.reflectance.eval(si, active)
            series = self.series(si, kd, active) if spectral else None
        if has_spec and has_diff:
            # detached: a sampling decision divides the weight as a constant
            # (the weight's gradient is then that of k_r, resp. the diffuse term)
            prob_spec = dr.detach(self.prob_specular(si, k_r, t_i, kd, series, active, cos_i))
        else:
            prob_spec = mi.Float(1.0 if has_spec else 0.0)
        sel_spec = active & (sample1 < prob_spec)
        sel_diff = active & (sample1 >= prob_spec)   # not ~sel_spec: a Python bool in scalar variants

        wo_diff = mi.warp.square_to_cosine_hemisphere(sample2)
        bs.wo = dr.select(sel_spec, mi.reflect(si.wi), wo_diff)
        bs.eta = 1.0
        bs.sampled_component = dr.select(sel_spec, mi.UInt32(0), mi.UInt32(1))
        bs.sampled_type = dr.select(sel_spec, mi.UInt32(+mi.BSDFFlags.DeltaReflection),
                                    mi.UInt32(+mi.BSDFFlags.DiffuseReflection))
        pdf_diff = mi.warp.square_to_cosine_hemisphere_pdf(wo_diff)
        bs.pdf = dr.select(sel_spec, prob_spec, (1.0 - prob_spec) * pdf_diff)

        weight = mi.UnpolarizedSpectrum(0.0)
        # the chosen component's probability, inverted once per lane
        p = dr.select(sel_spec, prob_spec, 1.0 - prob_spec)
        inv_p = dr.rcp(dr.select(p > 0, p, 1.0))
        if has_spec:
            weight = dr.select(sel_spec, k_r * inv_p, weight)
        if has_diff:
            # f cos / pdf with f = k_d t_i t_o series / pi and pdf = (1 - P_spec) cos / pi
            w_diff = self.diffuse(si, kd, cos_i, wo_diff, t_i, series, sel_diff) * inv_p
            weight = dr.select(sel_diff & (pdf_diff > 0), w_diff, weight)
        # the film's reflection is polarized, the light through the base depolarized
        lobe = self.mode.select(sel_spec, spec_lobe, self.mode.depolarized)
        return bs, dr.select(active & (bs.pdf > 0),
                             self.mode.value(weight, lobe, ctx, si.wi, bs.wo), 0.0)

    def eval_pdf(self, ctx, si, wo, active, has_spec: bool, has_diff: bool,
                 want_value: bool = True, want_pdf: bool = True):
        """``(value, pdf)`` as Mitsuba's ``BSDF.eval_pdf`` (the parts not wanted are 0), with
        the components ``has_spec`` and ``has_diff`` enabled."""
        mi = mitsuba_module()
        if not has_diff:
            return mi.Spectrum(0.0), mi.Float(0.0)
        self.bottom.check()
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        active = mi.Bool(active) & (cos_i > 0) & (cos_o > 0)
        pdf = mi.warp.square_to_cosine_hemisphere_pdf(wo) if want_pdf else mi.Float(0.0)

        if self.bare:  # exactly Mitsuba's diffuse
            value = (self.bottom.bare_value(si, wo, active) * dr.inv_pi * cos_o) if want_value \
                else mi.UnpolarizedSpectrum(0.0)
            value = self.mode.value(value, self.mode.depolarized, ctx, si.wi, wo)
            return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

        need_prob = want_pdf and has_spec
        value = mi.Spectrum(0.0)
        if want_value or need_prob:
            spectral = self.colour is None
            kd = self.bottom.reflectance.eval(si, active)
            series = self.series(si, kd, active) if spectral else None
            k_r, t_i, _ = self.factors_at(si, cos_i, active, transmission=spectral)
        if want_value:
            value = self.mode.value(
                self.diffuse(si, kd, cos_i, wo, t_i, series, active) * dr.inv_pi * cos_o,
                self.mode.depolarized, ctx, si.wi, wo)
        if need_prob:
            pdf = pdf * (1.0 - self.prob_specular(si, k_r, t_i, kd, series, active, cos_i))
        return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

    # -- parameters ------------------------------------------------------------
    def traverse(self, callback) -> None:
        """Expose film ``N`` (``layers.N.*``; the top and the bottom expose their own)."""
        mi = mitsuba_module()
        if self.film_n is not None:
            i = len(self.coating)
            callback.put(f"layers.{i}.thickness", self.film_n_thickness, mi.ParamFlags.Differentiable)
            self.film_n.traverse(callback, f"layers.{i}.")

    def parameters_changed(self, changed) -> None:
        """Refresh after an edit of the keys ``changed`` (``None``: any; the top refreshed
        first)."""
        if self.film_n is not None:
            self.film_n.parameters_changed(self.plugin, f"layers.{len(self.coating)}.")
        if self.film_n_thickness is not None and dr.is_jit_v(self.film_n_thickness):
            dr.make_opaque(self.film_n_thickness)
        colour_albedo = self.colour is not None and self.colour.fixed
        if self.bottom.refresh() or changed is None or any(
                k.startswith(("layers.", "thickness")) or (colour_albedo and k.startswith("reflectance"))
                for k in changed):
            self.update()
        else:
            # gradients enabled or disabled on an unchanged value (the guard
            # compares values, not their AD state)
            self.index_gradients.collect(self.media())
            self.update_derivatives()
            if self.terms is not None:
                self.update_table(self.factors())

    def describe(self) -> str:
        """The model, the base's roughness and the stack, for ``to_string``."""
        layers = self.coating.describe()
        if self.film_n is not None:
            d = self.film_n_thickness
            d = float(dr.ravel(d)[0]) if dr.is_array_v(d) else d
            layers = f"{layers} over absorbing film {self.film_n.label} {d:g} nm"
        return (f"  model = {self.model.name},\n{self.bottom.describe()}  layers = {layers},\n"
                f"  ext_ior = {self.coating.ambient.label}\n")
