"""What ``thinfilm_diffuse`` needs beyond its kernel stack.

* :class:`DiffuseFactors`: its spectral factors as its colour tables
  (:mod:`thinfilm_mi.tabulate.diffuse`) integrate them: the coating's transmittance at
  any (angle, wavelength) and its hemispherical terms, read from the plugin's
  :class:`~thinfilm_mi.render.kernel.KernelStack` and media.
* :func:`update_derivative_table`, :func:`with_derivatives`: ``R_dh`` carrying its
  derivatives with respect to the films' thicknesses and indices (model "multiple"
  in AD variants), from a table built when a film parameter carries gradients.
* :func:`colour_estimate`: the estimate whose gradients an RGB/mono diffuse term takes.
* :func:`absorbs`, :func:`reflectance_from_props`, :func:`grid_spectrum`: the plugin's
  reading of its films and albedo, and its spectra on the 1 nm grid.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import GRID
from thinfilm_mi.optics.core import Cx, film_attenuation
from thinfilm_mi.render.colour import GradientSampler, index_on_wavelengths, with_absorbing
from thinfilm_mi.render.kernel import KernelStack, side_data
from thinfilm_mi.render.params import ALBEDO_SLACK
from thinfilm_mi.render.textures import checked_texture, mitsuba_module, regular, scalar, uniform
from thinfilm_mi.tabulate import base as tabulate_base
from thinfilm_mi.tabulate.diffuse_scale import exact_hemispherical, paper_hemispherical
from thinfilm_mi.tabulate.hemispherical import PER_FILM, DerivativeTable, hemispherical_factors, r_dh_partials

__all__ = ["DiffuseFactors", "film_gradients", "update_derivative_table", "with_derivatives", "absorbs",
           "colour_estimate",
           "reflectance_from_props", "grid_spectrum"]


class DiffuseFactors:
    """The spectral factors of a ``thinfilm_diffuse`` for :class:`ColourDiffuse`:
    ``t(cos, wl)`` (shape ``(len cos, len wl)``) and ``hemispherical(wl) ->
    (R_dh, T_hemi)`` (over ``wl``), for the coating ``coating`` (a
    :class:`~thinfilm_mi.render.kernel.KernelStack`) over the absorbing film ``film_n``
    (a ``SpectralIndex``) of ``film_n_thickness`` nm, or over the base medium
    (``film_n`` ``None``); every thickness times ``scale`` (a ``thickness`` texture's
    value). :meth:`hemispherical_scales` gives the terms at several scales."""

    def __init__(self, coating, film_n, film_n_thickness: float | None, scale: float = 1.0):
        self.coating, self.film_n, self.film_n_thickness = coating, film_n, film_n_thickness
        self.scale = float(scale)

    def at_scale(self, scale: float) -> "DiffuseFactors":
        """The same factors with every thickness times ``scale`` (instead of :attr:`scale`)."""
        return DiffuseFactors(self.coating, self.film_n, self.film_n_thickness, scale)

    def hemispherical_scales(self, wl, scales):
        """``(R_dh, T_hemi)`` at every thickness scale of ``scales``, each of shape
        ``(len scales, len wl)``."""
        n0, coat, n_exit, fn = self.at_scale(1.0)._arguments(wl)
        if fn is None:   # the coating over the (matched) base medium: the exact terms
            return exact_hemispherical(n0, coat, n_exit.real, wl, scales)
        return paper_hemispherical(n0, coat, fn, wl, scales)

    def t(self, cos, wl):

        _, T = side_rt(self.coating, False, cos, wl, self.scale)
        if self.film_n is None:
            return T
        n0 = self.coating.ambient.spectral_values(wl, real=True)
        n_f = self.film_n.spectral_values(wl)
        beta2 = (n0 ** 2)[None, :] * (1.0 - cos ** 2)[:, None]
        q = np.sqrt((n_f ** 2)[None, :] - beta2 + 0j)
        q = np.where(q.imag < 0, -q, q)           # the decaying root
        return T * np.exp(-(4.0 * math.pi / wl)[None, :] * q.imag * self.film_n_thickness
                          * self.scale)

    def _arguments(self, wl):
        """:func:`~thinfilm_mi.tabulate.hemispherical.hemispherical_factors`'s arguments at ``wl``."""

        c = self.coating
        n0 = c.ambient.spectral_values(wl, real=True)
        coat = [(ix.spectral_values(wl), scalar(d) * self.scale)
                for ix, d in zip(c.indices, c.thickness)]
        fn = None if self.film_n is None else (self.film_n.spectral_values(wl),
                                               self.film_n_thickness * self.scale)
        return n0, coat, c.substrate.spectral_values(wl), fn

    def hemispherical(self, wl):

        t_hemi, r_dh = hemispherical_factors(*self._arguments(wl), wavelengths=wl)
        return r_dh, t_hemi

    def r_dh_partials(self, wl):
        """``∂R_dh/∂x`` at ``wl`` (:func:`~thinfilm_mi.tabulate.hemispherical.r_dh_partials`):
        per film of the coating, then film ``N``, its thickness, ``Re n``, ``Im n``."""

        return r_dh_partials(*self._arguments(wl), wavelengths=wl)


def film_gradients(bsdf) -> bool:
    """Whether a film parameter of ``bsdf`` (a ``layers.*`` value) carries gradients."""
    mi = mitsuba_module()
    if not dr.is_diff_v(mi.Float):
        return False
    params = mi.traverse(bsdf)
    return any(dr.grad_enabled(params[k]) for k in params.keys()
               if k.startswith("layers.") and dr.is_diff_v(params[k]))


def update_derivative_table(bsdf, factors, model: str, table):
    """``R_dh``'s derivative table for ``bsdf`` now: built from ``factors`` (a
    :class:`DiffuseFactors`) if a film parameter carries gradients and ``table`` is
    missing, kept if it is there, ``None`` when nothing carries gradients (or for
    model "single", or no films). Never needed at scene load, where nothing carries
    gradients: the reverse-mode pass then never runs on Mitsuba's loader threads."""
    if factors is None or model == "single" or not film_gradients(bsdf):
        return None
    return table if table is not None else DerivativeTable(factors.r_dh_partials(GRID))


def with_derivatives(table, r_dh, films, si, wavelengths, index_at, active, plugin: str):
    """``R_dh`` (at ``wavelengths``) plus ``Σ_x ∂R_dh/∂x (x - detach(x))`` over the
    ``films`` (``(SpectralIndex, thickness)``, the coating's then film N) whose
    thickness or index carries gradients: the same value, with ``R_dh``'s derivatives
    (``table``, a :class:`~thinfilm_mi.tabulate.hemispherical.DerivativeTable`).
    ``index_at(ix)``: a film's index at ``wavelengths``. Gradients that reach here
    without a table (enabled without ``params.update()``) raise, never bias."""
    mi = mitsuba_module()
    carriers = {}
    for f, (ix, d) in enumerate(films):
        if dr.grad_enabled(d):
            carriers[PER_FILM * f] = mi.UnpolarizedSpectrum(d - dr.detach(d))
        if ix.carries_gradients(si, active):
            n = index_at(ix)
            carriers[PER_FILM * f + 1] = mi.UnpolarizedSpectrum(n.re - dr.detach(n.re))
            carriers[PER_FILM * f + 2] = mi.UnpolarizedSpectrum(n.im - dr.detach(n.im))
    if not carriers:
        return r_dh
    if table is None:
        raise ThinFilmError(
            f"{plugin}: a film parameter carries gradients, but R_dh's derivative table "
            "was not built: call params.update() after enabling gradients "
            "(dr.enable_grad(params[key]); params.update()), as mi.ad optimisers do")
    return r_dh + table.tangent(wavelengths, carriers, active)


def absorbs(index) -> bool:
    """Whether a film's index (a ``SpectralIndex``) has ``k > 0`` somewhere in 360-830 nm
    (an index without a material: assumed to)."""
    mat = index.material
    if mat is None:
        return True
    if mat.constant is not None:
        return mat.constant.imag > 0
    return bool(np.any(mat.index(GRID).imag > 0))


def reflectance_from_props(props, plugin: str):
    """The base albedo ``reflectance``: finite and in [0, 1] (up to :data:`ALBEDO_SLACK`:
    sRGB white upsampled to a spectrum peaks a hair above 1; anything larger would let
    ``1 - k_d R_dh`` approach 0)."""
    if "reflectance" not in props:
        return uniform(0.5)
    value = props.get("reflectance")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if not (0.0 <= value <= 1.0):
            raise ThinFilmError(f"{plugin}: 'reflectance' must be in [0, 1] (an albedo), "
                                f"got {value!r}")
    return checked_texture(props, "reflectance", plugin, "a number, a spectrum or a texture",
                           f"{plugin}: 'reflectance' (an albedo, energy conservation)", 0.0,
                           1.0 + ALBEDO_SLACK)


def grid_spectrum(tex, values):
    """``values`` on the 1 nm grid as a ``regular`` spectrum, updating ``tex`` in place
    when it already is one (a ``uniform`` 0 when all values vanish: Mitsuba's
    ``regular`` spectrum refuses a zero integral). In scalar variants a new one is
    made (their ``mi.Float`` holds one number, not the values)."""
    mi = mitsuba_module()
    values = np.asarray(values, dtype=np.float64)
    if not np.any(values.astype(np.float32) > 0):  # Mitsuba stores float32
        return uniform(0.0)
    params = mi.traverse(tex) if tex is not None and dr.is_jit_v(mi.Float) else None
    if params is not None and "values" in params:
        params["values"] = mi.Float(values.astype(np.float32))
        params.update()
        return tex
    return regular(values, GRID[0], GRID[-1])


def colour_estimate(coating, film_n, film_n_thickness, r_dh_at, with_derivatives, si, cos_i, cos_o,
                    active, g, base_ratio: bool = False):
    """An unbiased estimate of the integrated diffuse term of a ``thinfilm_diffuse`` (its
    ``coating``, absorbing film ``film_n`` or ``None``, the colour table's ``r_dh_at``) at
    stratified wavelengths (:class:`~thinfilm_mi.render.colour.GradientSampler`), whose
    gradients the table's value takes; ``R_dh`` with its derivatives (``with_derivatives``,
    the plugin's :func:`with_derivatives`); ``g(c, R_dh)``: the base's term of channel ``c``
    (``G(k_d,c, R_dh)`` for Lambert's). ``base_ratio``: ``t`` carries ``n_0/n_b`` (model
    "exact" over a base medium unlike the ambient); the thickness texture scales every film."""
    mi = mitsuba_module()
    sampler = GradientSampler.get()
    wl = sampler.wavelengths(si)
    scale = coating.thickness_scale_at(si, active)
    n0, _ = index_on_wavelengths(coating.ambient, si, wl, active)

    def t(cos):
        _, k_t = coating.at_wavelengths(False, si, cos, active, True, scale, wl)
        if base_ratio:
            k_t = k_t * n0 / index_on_wavelengths(coating.substrate, si, wl, active)[0]
        if film_n is None:
            return k_t
        d = film_n_thickness if scale is None else film_n_thickness * scale
        return k_t * film_attenuation(n0, cos, Cx(*index_on_wavelengths(film_n, si, wl, active)),
                                      d, wl)
    product = t(cos_i) * t(cos_o)
    r_dh = with_derivatives(r_dh_at(wl, active), si, wl,
                            lambda ix: Cx(*index_on_wavelengths(ix, si, wl, active)), active)
    channels = [sampler.estimate(wl, product * g(c, r_dh))[c] for c in range(dr.size_v(mi.Spectrum))]
    return mi.Spectrum(*channels)


def side_rt(stack: KernelStack, inside: bool, cos: np.ndarray, wavelengths: np.ndarray,
            scale: float = 1.0):
    """Exact float64 ``(R, T)`` of the planned side ``inside`` of ``stack`` at every
    angle ``cos`` and wavelength (shape ``(len cos, len wavelengths)`` each), as
    the colour tables see it (spectral values of every medium), every film's
    thickness times ``scale``."""
    side = stack.plan[inside]
    data = with_absorbing(side_data(side, True))
    wl = np.asarray(wavelengths, np.float64)
    rows = np.tile(np.arange(wl.size), cos.size)
    points = np.repeat(cos, wl.size)
    out = tabulate_base.evaluate_side(data, points, rows, wl, tabulate_base.side_indices(data, wl),
                                      None if scale == 1.0 else np.full(points.size, float(scale)))
    out = out.reshape(cos.size, wl.size, 2)
    T = np.zeros_like(out[..., 0]) if side.opaque else out[..., 1]
    return out[..., 0], T
