"""``thinfilm_diffuse``'s exact model and its ``thickness`` texture (no plugin classes here).

* :class:`ExactFactors` — the spectral factors of model ``"exact"`` (the whole stack,
  coherent, over a base medium of index ``base_ior``) for the colour tables and the
  load-time terms, as :class:`~thinfilm_mi.render.diffuse.DiffuseFactors` gives them
  for the paper's models. The radiance factor ``(n_0/n_b)²`` of a base medium that
  differs from the ambient is split evenly between the two crossings: ``t = T n_0/n_b``
  and ``T_hemi`` (the base's escape fraction) divided by ``n_0/n_b``, so that
  ``k_d t_i t_o S`` is the diffuse term and ``t_i k_d T_hemi S`` its albedo.
* :class:`SpectralTerms` — ``R_dh`` and ``T_hemi`` in the spectral kernels: ``regular``
  spectra (no texture), or a :class:`~thinfilm_mi.tabulate.diffuse_scale.ScaleTable`
  over the thickness scale with ``∂R_dh/∂s`` for the texture's gradients.
* :func:`scale_bounds` — the largest value of a ``thickness`` texture, read at load.
* :func:`coating_transmission` — ``t`` in the kernel: ``k_t`` times film ``N``'s attenuation
  (scaled by the texture) or the exact model's ``n_0/n_b``; :func:`prob_specular`, the
  lobe choice; :func:`colour_diffuse`, :func:`constant_albedo`, the colour tables;
  :func:`diffuse_factors`, :func:`r_dh_with_derivatives`, :func:`colour_gradients`: the
  plugin's factors, its ``R_dh`` with derivatives, whether its films carry gradients.
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import GRID
from thinfilm_mi.optics.core import film_attenuation
from thinfilm_mi.render.diffuse import DiffuseFactors, grid_spectrum, with_derivatives
from thinfilm_mi.render.loop import LoopFilms
from thinfilm_mi.render.textures import mitsuba_module, scalar, texture_range
from thinfilm_mi.render.variant import spectral_mean
from thinfilm_mi.tabulate.diffuse import ColourDiffuse
from thinfilm_mi.tabulate.diffuse_scale import ScaleTable, exact_hemispherical
from thinfilm_mi.tabulate.diffuse_texture import ScaledColourDiffuse

__all__ = ["ExactFactors", "SpectralTerms", "scale_bounds", "coating_transmission",
           "texture_gradients_refused", "colour_diffuse", "constant_albedo", "colour_scale", "prob_specular",
           "diffuse_factors",
           "r_dh_with_derivatives", "colour_gradients"]

class ExactFactors(DiffuseFactors):
    """The factors of model ``"exact"`` for the stack ``coating`` (a
    :class:`~thinfilm_mi.render.kernel.KernelStack` of every film over the base
    medium, its substrate), every thickness times ``scale``."""

    def __init__(self, coating, scale: float = 1.0):
        super().__init__(coating, None, None, scale)

    def at_scale(self, scale: float) -> "ExactFactors":
        return ExactFactors(self.coating, scale)

    def _ratio(self, wl):
        """``n_0 / n_b`` at ``wl``."""
        c = self.coating
        return (c.ambient.spectral_values(wl, real=True)
                / c.substrate.spectral_values(wl, real=True))

    def t(self, cos, wl):
        return super().t(cos, wl) * self._ratio(wl)[None, :]

    def hemispherical(self, wl):
        r, t = self.hemispherical_scales(wl, [self.scale])
        return r[0], t[0]

    def hemispherical_scales(self, wl, scales):
        c = self.coating
        films = [(ix.spectral_values(wl), scalar(d)) for ix, d in zip(c.indices, c.thickness)]
        R_dh, T_hemi = exact_hemispherical(c.ambient.spectral_values(wl, real=True), films,
                                           c.substrate.spectral_values(wl, real=True), wl,
                                           scales)
        return R_dh, T_hemi / self._ratio(wl)[None, :]

    def r_dh_partials(self, wl):
        if not np.allclose(self._ratio(wl), 1.0, rtol=0, atol=1e-12):
            raise ThinFilmError(
                f"{self.coating.plugin}: gradients of the films' parameters with model 'exact' "
                "need 'base_ior' equal to 'ext_ior' (R_dh's derivatives are computed for a base "
                "medium matched to the ambient)")
        return super().r_dh_partials(wl)


def scale_bounds(tex, plugin: str) -> float:
    """The largest value (>= 0) of the ``thickness`` texture ``tex``, read at load."""
    rng = texture_range(tex, mono=True)
    if rng is None:
        raise ThinFilmError(f"{plugin}: 'thickness': its range cannot be evaluated at load "
                            "time, which the hemispherical terms need (a table over the "
                            "thickness scale)")
    return max(float(rng[1]), 0.0)


class SpectralTerms:
    """``R_dh`` and ``T_hemi`` of a ``thinfilm_diffuse`` in spectral variants, from
    ``factors`` (``None``: no films, ``R_dh = 0``, ``T_hemi = 1``). ``texture``: the
    ``thickness`` texture or ``None``; with one, a table over the scale in ``[0,
    max]`` (:class:`ScaleTable`), whose lookup carries ``∂R_dh/∂s`` in AD variants."""

    def __init__(self, factors, texture=None, plugin: str = "thinfilm_diffuse", old=None):
        self.table = None
        self.r_dh = self.t_hemi = None
        #: film N's index as a film-loop buffer (its textures' binary searches cost
        #: the "single" model more than its coating's table: issue 44)
        film_n = getattr(factors, "film_n", None)
        self.film_n = None
        if film_n is not None and film_n.knots is not None and dr.is_jit_v(mitsuba_module().Float):
            self.film_n = LoopFilms([(film_n, 0.0, False)], factors.coating.ambient)
        if factors is not None and texture is not None:
            s_max = scale_bounds(texture, plugin)
            self.table = ScaleTable(lambda s: factors.hemispherical_scales(GRID, s), s_max)
            return
        if factors is None:
            t_hemi, r_dh = np.ones(len(GRID)), np.zeros(len(GRID))
        else:
            r_dh, t_hemi = factors.hemispherical(GRID)
        self.t_hemi = grid_spectrum(None if old is None else old.t_hemi, t_hemi)
        self.r_dh = grid_spectrum(None if old is None else old.r_dh, r_dh)

    def lookup(self, si, stack, active=True):
        """``(R_dh, T_hemi)`` at the hit's wavelengths and the thickness scale of the
        :class:`~thinfilm_mi.render.kernel.KernelStack` ``stack`` there (its texture's
        gradient reaches ``R_dh`` through ``∂R_dh/∂s``)."""
        if self.table is None:
            return self.r_dh.eval(si, active), self.t_hemi.eval(si, active)
        scale = stack.thickness_scale_at(si, active)
        out = self.table.lookup(si.wavelengths, scale, active)
        r_dh = out[0]
        if dr.grad_enabled(scale):
            r_dh = r_dh + out[2] * (scale - dr.detach(scale))
        return r_dh, out[1]


def texture_gradients_refused(plugin: str, model: str) -> str:
    """Why film-parameter gradients are refused together with a ``thickness`` texture
    (models with ``R_dh``: its derivative table holds scale 1 only)."""
    return (f"{plugin}: gradients of the films' parameters together with a 'thickness' "
            f"texture are not supported with model {model!r} (R_dh's derivatives are "
            "tabulated at scale 1); differentiate the texture, or use model 'single'")


def coating_transmission(bsdf, si, cos_theta, k_t, active):
    """``t`` of the ``thinfilm_diffuse`` ``bsdf`` at the hit from its coating's ``k_t``
    (``mi.UnpolarizedSpectrum``): times ``k_a`` of film ``N`` (its thickness times the
    texture's scale) for the paper's models, times ``n_0/n_b`` for model "exact" over
    a base medium unlike the ambient."""
    mi = mitsuba_module()
    n0 = bsdf.coating.ambient.eval_real(si, active)
    if bsdf.film_n is not None:
        scale = bsdf.coating.thickness_scale_at(si, active)
        d = bsdf.film_n_thickness if scale is None else bsdf.film_n_thickness * scale
        grid = bsdf.terms.film_n if bsdf.terms is not None else None
        if grid is None or bsdf.film_n.carries_gradients(si, active):
            n_film = bsdf.film_n.eval(si, active)
        else:
            n_film = grid.index(si.wavelengths)
        k_t = k_t * film_attenuation(n0, cos_theta, n_film, d, si.wavelengths)
    if bsdf.base_ratio:
        k_t = k_t * n0 / bsdf.coating.substrate.eval_real(si, active)
    # (the polarized amplitudes of a scaled stack come back as plain Array4f)
    return mi.UnpolarizedSpectrum(k_t)


def prob_specular(bsdf, si, k_r, t_i, kd, series, active, cos_i):
    """The probability of choosing the delta component of ``bsdf``: the spectral mean
    of ``k_r`` against that of the diffuse albedo estimate ``t_i k_d T_hemi S`` (its
    colour table's in RGB/mono variants)."""
    spec = spectral_mean(k_r)
    if bsdf.colour is not None:
        diff = spectral_mean(bsdf.colour.albedo(cos_i, kd, active, colour_scale(bsdf, si, active)))
    else:
        diff = spectral_mean(t_i * kd * bsdf.terms.lookup(si, bsdf.coating, active)[1] * series)
    total = spec + diff
    return dr.select(total > 0, spec / dr.select(total > 0, total, 1.0), 0.0)


def colour_diffuse(factors, texture, model: str, channels: str, kd, plugin: str):
    """The RGB/mono diffuse table of ``factors`` (:class:`~thinfilm_mi.tabulate.diffuse.ColourDiffuse`;
    ``kd``: :func:`constant_albedo`) under a ``thickness`` texture: at its scale where
    it is constant, else over the scale in its range ``[min, max]``
    (:class:`~thinfilm_mi.tabulate.diffuse_texture.ScaledColourDiffuse`)."""
    if texture is None:
        return ColourDiffuse(factors, model, channels, kd)
    s_max = scale_bounds(texture, plugin)
    if not texture.is_spatially_varying():
        return ColourDiffuse(factors.at_scale(s_max), model, channels, kd)
    s_min = float(texture_range(texture, mono=True)[0])
    return ScaledColourDiffuse(factors, model, channels, kd, s_max, plugin, s_min)


def colour_scale(bsdf, si, active):
    """The thickness scale at the hit for ``bsdf``'s colour table if it is one over the
    scale, else ``None``."""
    return bsdf.coating.thickness_scale_at(si, active) if bsdf.colour.scaled else None


def constant_albedo(reflectance, rough: bool) -> np.ndarray | None:
    """The base albedo per colour channel where it does not vary over the surface and
    the base is Lambertian (the colour tables then integrate the series with it), else
    ``None``."""
    if reflectance.is_spatially_varying() or rough:
        return None
    mi = mitsuba_module()
    si = dr.zeros(mi.SurfaceInteraction3f)
    return np.array(dr.ravel(reflectance.eval(si)), np.float64).reshape(-1)


def diffuse_factors(bsdf):
    """The coating's spectral factors of ``bsdf`` at the current parameters (``None``
    without films): :class:`ExactFactors` for model "exact", else
    :class:`~thinfilm_mi.render.diffuse.DiffuseFactors`."""
    if bsdf.no_films:
        return None
    if bsdf.model == "exact":
        return ExactFactors(bsdf.coating)
    thickness = None if bsdf.film_n is None else scalar(bsdf.film_n_thickness)
    return DiffuseFactors(bsdf.coating, bsdf.film_n, thickness)


def r_dh_with_derivatives(bsdf, r_dh, si, wavelengths, index_at, active):
    """``R_dh`` of ``bsdf`` carrying its derivatives
    (:func:`thinfilm_mi.render.diffuse.with_derivatives`; as is for model "single")."""
    if bsdf.model == "single" or bsdf.no_films:
        return r_dh
    films = list(zip(bsdf.coating.indices, bsdf.coating.thickness))
    if bsdf.film_n is not None:
        films.append((bsdf.film_n, bsdf.film_n_thickness))
    return with_derivatives(bsdf.r_dh_grad, r_dh, films, si, wavelengths, index_at, active,
                            bsdf.coating.plugin)


def colour_gradients(bsdf, si, active) -> bool:
    """RGB/mono AD variants: whether a film thickness or index of ``bsdf`` carries gradients."""
    n = bsdf.film_n
    return bsdf.coating.colour_gradients(si, active) or (n is not None and (
        dr.grad_enabled(bsdf.film_n_thickness) or n.carries_gradients(si, active)))
