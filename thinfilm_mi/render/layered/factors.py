"""The spectral factors and load-time terms of the closed forms over a diffuse bottom
(:mod:`thinfilm_mi.render.layered.models`, :mod:`thinfilm_mi.render.layered.series`,
:mod:`thinfilm_mi.render.layered.forms`; no plugin classes here).

* :class:`DiffuseFactors` — the factors of the paper's models as the colour tables
  (:mod:`thinfilm_mi.tabulate.diffuse`), the factor table and the load-time terms read
  them: the coating's reflectance ``k_r`` and transmittance ``t`` at any (angle,
  wavelength) and its hemispherical terms
  (:mod:`thinfilm_mi.tabulate.hemispherical`), read from the model's
  :class:`~thinfilm_mi.render.kernel.KernelStack` and media.
* :class:`ExactFactors` — the same for model ``"exact"`` (the whole stack, coherent but
  for the films beyond the coherence thickness, over a base medium of index
  ``base_ior``). The radiance factor ``(n_0/n_b)²`` of a base medium that differs from
  the ambient is split evenly between the two crossings:
  ``t = T n_0/n_b`` and ``T_hemi`` (the base's escape fraction) divided by ``n_0/n_b``,
  so that ``k_d t_i t_o S`` is the diffuse term and ``t_i k_d T_hemi S`` its albedo.
* :class:`SpectralTerms` — ``R_dh`` and ``T_hemi`` in the spectral kernels: ``regular``
  spectra (no texture), or a :class:`~thinfilm_mi.tabulate.hemispherical.ScaleTable`
  over the thickness scale with ``∂R_dh/∂s`` for the texture's gradients.
* :func:`with_derivatives` — ``R_dh`` carrying its derivatives with respect to the
  films' thicknesses and indices, from a
  :class:`~thinfilm_mi.tabulate.hemispherical.DerivativeTable`; :class:`IndexGradients`
  — which indices carry gradients, read without evaluating their textures.
* :func:`factor_table` — the spectral kernels' table of the factors
  (:class:`~thinfilm_mi.tabulate.factors.FactorTable`), shared through the stack's table
  cache and store by :func:`factor_table_key`.
* :func:`colour_diffuse`, :func:`constant_albedo` — the RGB/mono tables of the diffuse
  term; :func:`scale_bounds` — the largest value of a ``thickness`` texture, read at load;
  :func:`texture_gradients_refused` — why film gradients and a texture do not go together.
* :func:`absorbs`, :func:`grid_spectrum` — the reading of the films, and spectra on the
  1 nm grid; :func:`side_rt` — a kernel
  stack's exact float64 ``R``, ``T`` as the colour tables see them.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import GRID
from thinfilm_mi.render.colour_variants import with_absorbing
from thinfilm_mi.render.kernel import KernelStack
from thinfilm_mi.render.loop import LoopFilms
from thinfilm_mi.render.stack_build import STORE_MIN_POINTS, TABLE_CACHE, side_data
from thinfilm_mi.render.tabulation import table_key
from thinfilm_mi.render.textures import (
    mitsuba_module,
    regular,
    scalar,
    texture_on_grid,
    texture_range,
    uniform,
)
from thinfilm_mi.tabulate import base as tabulate_base
from thinfilm_mi.tabulate import factors as factor_build
from thinfilm_mi.tabulate.base import GRAZING_COS, BuildReport
from thinfilm_mi.tabulate.diffuse import ColourDiffuse, ScaledColourDiffuse
from thinfilm_mi.tabulate.factors import FactorTable
from thinfilm_mi.tabulate.hemispherical import (
    DEFAULT_NODES,
    PER_FILM,
    ScaleTable,
    exact_hemispherical,
    paper_terms,
    r_dh_partials,
)
from thinfilm_mi.tabulate.store import default_store

__all__ = ["DiffuseFactors", "ExactFactors", "SpectralTerms",
           "IndexGradients", "with_derivatives", "factor_table", "factor_table_key", "colour_diffuse",
           "constant_albedo", "scale_bounds", "texture_gradients_refused", "absorbs",
           "grid_spectrum", "side_rt"]

class DiffuseFactors:
    """The spectral factors of the paper's models for
    :class:`~thinfilm_mi.tabulate.diffuse.ColourDiffuse`, :class:`SpectralTerms` and
    :func:`factor_table`: ``t(cos, wl)`` and ``rt(cos, wl) -> (k_r, t)`` (shape ``(len
    cos, len wl)`` each) and ``hemispherical(wl) ->
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

    def hemispherical_scales(self, wl, scales, nodes: int | None = None):
        """``(R_dh, T_hemi)`` at every thickness scale of ``scales``, each of shape
        ``(len scales, len wl)`` (:func:`~thinfilm_mi.tabulate.hemispherical.paper_terms`;
        ``nodes``: of its rule, by default as many as the films' fringes need)."""
        n0, coat, n_exit, fn = self.at_scale(1.0)._arguments(wl)
        return paper_terms(n0, coat, n_exit, fn, wl, scales, nodes, self.incoherent())

    def incoherent(self) -> list[bool]:
        """Per film of the coating, whether the kernel averages it incoherently (thicker
        than the stack's ``coherence_thickness``, whatever the scale): the hemispherical
        terms average it alike."""
        c = self.coating
        return [scalar(d) > c.coherence_thickness for d in c.thickness]

    def t(self, cos, wl):
        """``t = k_t k_a`` at every angle ``cos`` and wavelength ``wl``: shape ``(len cos, len wl)``."""
        return self.rt(cos, wl)[1]

    def rt(self, cos, wl):
        """``(k_r, t)`` at every angle ``cos`` and wavelength ``wl``, each of shape ``(len cos,
        len wl)``: the coating's reflectance and :meth:`t`, from one evaluation of the coating."""
        R, T = side_rt(self.coating, False, cos, wl, self.scale)
        if self.film_n is None:
            return R, T
        n0 = self.coating.ambient.spectral_values(wl, real=True)
        n_f = self.film_n.spectral_values(wl)
        beta2 = (n0 ** 2)[None, :] * (1.0 - cos ** 2)[:, None]
        q = np.sqrt((n_f ** 2)[None, :] - beta2 + 0j)
        q = np.where(q.imag < 0, -q, q)           # the decaying root
        return R, T * np.exp(-(4.0 * math.pi / wl)[None, :] * q.imag * self.film_n_thickness
                             * self.scale)

    def _arguments(self, wl):
        """The arguments of :func:`~thinfilm_mi.tabulate.hemispherical.paper_terms` and
        :func:`~thinfilm_mi.tabulate.hemispherical.r_dh_partials` at ``wl`` (the films at
        :attr:`scale`)."""
        c = self.coating
        n0 = c.ambient.spectral_values(wl, real=True)
        coat = [(ix.spectral_values(wl), scalar(d) * self.scale)
                for ix, d in zip(c.indices, c.thickness)]
        fn = None if self.film_n is None else (self.film_n.spectral_values(wl),
                                               self.film_n_thickness * self.scale)
        return n0, coat, c.substrate.spectral_values(wl), fn

    def hemispherical(self, wl):
        """``(R_dh, T_hemi)`` at ``wl`` at :attr:`scale`, with the full rule
        (:data:`~thinfilm_mi.tabulate.hemispherical.DEFAULT_NODES`)."""
        R_dh, T_hemi = self.hemispherical_scales(wl, [self.scale], DEFAULT_NODES)
        return R_dh[0], T_hemi[0]

    def r_dh_partials(self, wl):
        """``∂R_dh/∂x`` at ``wl`` (:func:`~thinfilm_mi.tabulate.hemispherical.r_dh_partials`):
        per film of the coating, then film ``N``, its thickness, ``Re n``, ``Im n``."""
        return r_dh_partials(*self._arguments(wl), wavelengths=wl)


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

    def rt(self, cos, wl):
        R, T = super().rt(cos, wl)
        return R, T * self._ratio(wl)[None, :]

    def hemispherical(self, wl):
        r, t = self.hemispherical_scales(wl, [self.scale])
        return r[0], t[0]

    def hemispherical_scales(self, wl, scales):
        c = self.coating
        films = [(ix.spectral_values(wl), scalar(d)) for ix, d in zip(c.indices, c.thickness)]
        R_dh, T_hemi = exact_hemispherical(c.ambient.spectral_values(wl, real=True), films,
                                           c.substrate.spectral_values(wl, real=True), wl,
                                           scales, incoherent=self.incoherent())
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
        #: film N's index as a film-loop buffer (its textures' binary searches would
        #: cost the "single" model more than its coating's table)
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


def factor_table(factors, coating: KernelStack, texture, media):
    """The :class:`~thinfilm_mi.tabulate.factors.FactorTable` of ``factors`` (of the
    coating ``coating``, between the ``media``: ``SpectralIndex``) in spectral JIT variants
    where ``tabulate`` builds tables, without a ``thickness`` ``texture`` or a medium that
    varies over the surface; ``None`` otherwise, or where no table within ``table_error``
    fits (the kernel then evaluates the stack). In place of the stack's own tables for
    every model and stack: under "SiO2 500; Au 5" the kernel of ``sample`` and
    ``eval_pdf`` falls from 7027 to 646 operations (model "exact", the 2-film recursion;
    "single": 3941 to 605, the stack's cubic table of ``R`` and ``k_a``), a render against
    Mitsuba's ``diffuse`` from 1.71x to 1.30x (1.91x to 1.21x) in ``llvm_ad_spectral``
    (``benchmarks/sample_profile.py --plugins diffuse``, ``benchmarks/plugin_bench.py``).

    Shared as the stack's tables are (:func:`factor_table_key`): from this process's
    :data:`~thinfilm_mi.render.stack_build.TABLE_CACHE`, else from the table store on disk
    (:func:`~thinfilm_mi.tabulate.store.default_store`; its report then says ``"from the
    table store"``, the build's under ``build``), else built (0.09 s for "SiO2 500; Au 5",
    model "exact"; 0.21 s "single") and kept in both (the store from
    :data:`~thinfilm_mi.render.stack_build.STORE_MIN_POINTS` evaluations)."""
    if factors is None or texture is not None or not coating.tabulate.builds \
            or not dr.is_jit_v(mitsuba_module().Float):
        return None
    if any(tex.is_spatially_varying() for ix in media for tex in (ix.eta, ix.k)):
        return None
    key = factor_table_key(factors, coating, media)
    found, table = TABLE_CACHE.get(key)
    if found:
        return table
    disk = default_store()
    if disk is not None:
        found, table, report = disk.get(key)
        if found:
            if table is not None:
                table.report = BuildReport(result="from the table store", build=report)
            TABLE_CACHE.put(key, table)
            return table
    kinks = np.unique(np.concatenate([ix.kinks for ix in media]))
    built = FactorTable(factors.rt, factors.hemispherical, coating.table_error, kinks)
    table = built if built.built else None
    TABLE_CACHE.put(key, table)
    if disk is not None and built.report["points"] >= STORE_MIN_POINTS:
        disk.put(key, table, built.report)
    return table


def factor_table_key(factors, coating: KernelStack, media) -> str:
    """The key (:func:`~thinfilm_mi.render.tabulation.table_key`) of the factor table of
    ``factors`` of ``coating`` between ``media`` (:func:`factor_table`): what its values
    depend on, the ``media``'s indices on the 1 nm grid and their kinks, the planned side's
    films (thicknesses, incoherent flags) and its exit and opacity, every film's thickness
    and the coherence thickness (the hemispherical terms read them all), film ``N``'s thickness, the thickness scale,
    the factors' kind (:class:`ExactFactors`, or the paper's :class:`DiffuseFactors` of
    models "single" and "multiple", which share them), ``table_error``, the build's
    steps and caps (:mod:`thinfilm_mi.tabulate.factors`), and the variant."""
    arrays = []
    for ix in media:
        arrays += [texture_on_grid(ix.eta), texture_on_grid(ix.k), np.asarray(ix.kinks, np.float64)]
    side = coating.plan[False]
    return table_key(arrays, side.films, (
        mitsuba_module().variant(), "factors", type(factors).__name__, side.exit_real, side.opaque,
        [scalar(d) for d in coating.thickness], coating.coherence_thickness,
        factors.film_n_thickness, factors.scale,
        coating.table_error, factor_build.FACTOR_FIRST_NODES, factor_build.FACTOR_STEPS,
        factor_build.FACTOR_MAX_FLOATS, factor_build.FACTOR_ANGLE_SHARE, GRAZING_COS))


def texture_gradients_refused(plugin: str, model) -> str:
    """Why film-parameter gradients are refused together with a ``thickness`` texture
    (``model``: one with interreflection, whose ``R_dh``'s derivative table holds scale 1
    only)."""
    return (f"{plugin}: gradients of the films' parameters together with a 'thickness' "
            f"texture are not supported with model {model.name!r} (R_dh's derivatives are "
            "tabulated at scale 1); differentiate the texture, or use model 'single'")


class IndexGradients:
    """Whether the indices (``SpectralIndex``) carry gradients at a hit, as
    :meth:`~thinfilm_mi.render.media.SpectralIndex.carries_gradients` says, but read from
    the parameters of their textures where those do not vary over the surface (their
    values depend on the wavelength alone), collected here once (:meth:`collect`, after
    every edit: ``mi.traverse`` is slow and allocates), instead of from an evaluation at
    each trace: an evaluation of an ``irregular`` spectrum (a binary search) starts a
    new Dr.Jit scope, and Dr.Jit merges identical computations (the coated-diffuse
    model's table reads at ``θ_i`` in ``eval_pdf`` and ``sample``) only within one; and
    the allocations of a trace may start a pass of the garbage collector, which the GC
    guard (:mod:`thinfilm_mi.render.gc_guard`) then owes as a full collection."""

    def __init__(self, indices=()):
        self.values = {}
        self.collect(indices)

    def collect(self, indices) -> None:
        """Collect the parameters of ``indices``' textures (a texture that varies over the
        surface is evaluated at each call instead)."""
        mi = mitsuba_module()
        self.values = {}
        if not dr.is_diff_v(mi.Float):
            return
        for ix in indices:
            if ix.eta.is_spatially_varying() or ix.k.is_spatially_varying():
                continue
            values = []
            for tex in (ix.eta, ix.k):
                params = mi.traverse(tex)
                values += [params[k] for k in params.keys()]
            self.values[id(ix)] = values

    def __call__(self, index, si, active=True) -> bool:
        if not dr.is_diff_v(mitsuba_module().Float):
            return False
        values = self.values.get(id(index))
        if values is None:
            return index.carries_gradients(si, active)
        return any(dr.grad_enabled(v) for v in values)


def with_derivatives(table, r_dh, films, si, wavelengths, index_at, active, plugin: str,
                     carries=None):
    """``R_dh`` (at ``wavelengths``) plus ``Σ_x ∂R_dh/∂x (x - detach(x))`` over the
    ``films`` (``(SpectralIndex, thickness)``, the coating's then film N) whose
    thickness or index carries gradients: the same value, with ``R_dh``'s derivatives
    (``table``, a :class:`~thinfilm_mi.tabulate.hemispherical.DerivativeTable`).
    ``index_at(ix)``: a film's index at ``wavelengths``; ``carries(ix, si, active)``:
    whether it carries gradients (an :class:`IndexGradients`; default: the index's own
    ``carries_gradients``). Gradients that reach here
    without a table (enabled without ``params.update()``) raise, never bias."""
    mi = mitsuba_module()
    carriers = {}
    for f, (ix, d) in enumerate(films):
        if dr.grad_enabled(d):
            carriers[PER_FILM * f] = mi.UnpolarizedSpectrum(d - dr.detach(d))
        if (ix.carries_gradients if carries is None else lambda *a: carries(ix, *a))(si, active):
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


def colour_diffuse(factors, texture, model, channels: str, kd, plugin: str):
    """The RGB/mono diffuse table of ``factors`` for ``model`` (a coated-diffuse model,
    :class:`~thinfilm_mi.tabulate.diffuse.ColourDiffuse`; ``kd``: :func:`constant_albedo`)
    under a ``thickness`` texture: at its scale where it is constant, else over the scale
    in its range ``[min, max]`` (:class:`~thinfilm_mi.tabulate.diffuse.ScaledColourDiffuse`)."""
    if texture is None:
        return ColourDiffuse(factors, model, channels, kd)
    s_max = scale_bounds(texture, plugin)
    if not texture.is_spatially_varying():
        return ColourDiffuse(factors.at_scale(s_max), model, channels, kd)
    s_min = float(texture_range(texture, mono=True)[0])
    return ScaledColourDiffuse(factors, model, channels, kd, s_max, plugin, s_min)


def constant_albedo(reflectance, rough: bool) -> np.ndarray | None:
    """The base albedo per colour channel where it does not vary over the surface and
    the base is Lambertian (the colour tables then integrate the series with it), else
    ``None``."""
    if reflectance.is_spatially_varying() or rough:
        return None
    mi = mitsuba_module()
    si = dr.zeros(mi.SurfaceInteraction3f)
    return np.array(dr.ravel(reflectance.eval(si)), np.float64).reshape(-1)


def absorbs(index) -> bool:
    """Whether a film's index (a ``SpectralIndex``) has ``k > 0`` somewhere in 360-830 nm
    (an index without a material: assumed to)."""
    mat = index.material
    if mat is None:
        return True
    if mat.constant is not None:
        return mat.constant.imag > 0
    return bool(np.any(mat.index(GRID).imag > 0))


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
