"""Mitsuba-side plumbing shared by the thin-film BSDFs (no plugin classes here):
:class:`KernelStack`, films (index and opaque thickness) between an ambient index
and a substrate index (:class:`~thinfilm_mi.render.media.SpectralIndex`), evaluated
with the optics core on ``mi.Spectrum`` (all wavelengths of a path at once) in
float32 inside the render kernel: from a table, or from buffers of the films
(:class:`LoopFilms`, from :data:`BUFFERED_MIN_FILMS` films: unrolled below
:data:`~thinfilm_mi.optics.unpolarized.LOOP_MIN_FILMS` films, a loop from it), or
unrolled film by film from the films' index textures (gradients, incoherent films);
both sides of a lossless stack through one side (:mod:`thinfilm_mi.render.mirror`).
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.optics.unpolarized import unpolarized_rt
from thinfilm_mi.render import mirror
from thinfilm_mi.render.colour_variants import (
    GradientSampler,
    attach_gradient,
    colour_channels,
    colour_table,
    index_on_wavelengths,
    prepare_gradients,
)
from thinfilm_mi.render.loop import LoopFilms
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.tabulation import Route, table_key, tabulate_option
from thinfilm_mi.render.textures import GRID, mitsuba_module, scalar, texture_on_grid
from thinfilm_mi.tabulate import band
from thinfilm_mi.tabulate.base import BuildReport, SideData, TableCache, opaque_float
from thinfilm_mi.tabulate.mueller import MUELLER
from thinfilm_mi.tabulate.policy import MAX_TEXELS, MIRROR_AUTO_MIN_FILMS
from thinfilm_mi.tabulate.quantities import POWERS
from thinfilm_mi.tabulate.store import default_store

__all__ = ["DEFAULT_COHERENCE_THICKNESS", "DEFAULT_SPECTRAL_RESOLUTION", "DEFAULT_TABLE_ERROR",
           "BUFFERED_MIN_FILMS", "KernelStack", "OPAQUE_AMPLITUDE", "STORE_MIN_POINTS",
           "SidePlan", "TABLE_CACHE", "side_data"]

#: Default coherence thickness (nm): thicker films are averaged incoherently.
DEFAULT_COHERENCE_THICKNESS = 5000.0
#: Default target for the tables: max abs error in R and T.
DEFAULT_TABLE_ERROR = 1e-3
#: Default ``spectral_resolution`` (nm): a stack whose exact ``R`` and ``T`` no table
#: resolves (cavity resonances ~0.1 nm wide) gets a table of them convolved with a Gaussian
#: in wavenumber of this standard deviation at 560 nm (:mod:`thinfilm_mi.tabulate.band`),
#: narrow enough that broadband light shows no difference in colour.
DEFAULT_SPECTRAL_RESOLUTION = 1.0
#: A film is optically opaque when the amplitude of light crossing it once,
#: ``exp(-2 pi Im(q) d / lambda)`` at normal incidence and the worst wavelength,
#: is below this: what lies beneath then changes r by less than ~1e-9.
OPAQUE_AMPLITUDE = 1e-9
#: Exact sides of this many films read their films from buffers (:class:`LoopFilms`: one
#: index search per wavelength for all films, a gather per film; unrolled below
#: :data:`~thinfilm_mi.optics.unpolarized.LOOP_MIN_FILMS` films, a loop from it), in every
#: variant that evaluates films in kernels: cheaper than reading each film's index textures.
BUFFERED_MIN_FILMS = 1


class SidePlan:
    """How one lighting side of a stack is evaluated, after the skips.

    ``films`` are ``(SpectralIndex, thickness, incoherent)`` from the side the
    light comes from; ``exit`` is the exit medium (the substrate, the ambient,
    or the first optically opaque film, in which case ``opaque`` is true and
    ``T = 0``); ``table`` is a :class:`~thinfilm_mi.tabulate.base.Table` or ``None``.
    """

    def __init__(self, n0: SpectralIndex, films, exit_: SpectralIndex, exit_real: bool,
                 opaque: bool, transmission: bool):
        self.n0 = n0
        self.films = films
        #: non-absorbing films under a real incidence medium: T = 1 - R (tables hold R)
        self.lossless = False
        self.exit = exit_
        self.exit_real = exit_real
        self.opaque = opaque
        self.transmission = transmission
        self.table = None
        #: What the build of :attr:`table` did (a ``tabulate.base.BuildReport``), or None
        self.build_report = None
        self.loop = None   # a LoopFilms where the films are evaluated in a loop
        #: RGB/mono variants: the side's tabulate.integrated.ColourTable, or None where the
        #: plugin evaluates per channel (no films over an index given per channel)
        self.colour = None

    @property
    def incoherent(self) -> list[bool]:
        return [f[2] for f in self.films]


class KernelStack:
    """Films between an ambient medium and a substrate, for evaluation in kernels.

    ``films`` is a list of ``(SpectralIndex, thickness_nm)``; thicknesses are
    stored as opaque ``mi.Float`` so a sweep never recompiles. ``ambient`` must
    be non-absorbing. ``sides`` maps ``inside`` (False: lit from the ambient,
    True: from the substrate) to whether ``T`` is needed there; it decides what
    is tabulated. Other combinations are still evaluated, exactly.

    What a scene does not need is skipped (re-decided in
    :meth:`parameters_changed`): films of zero thickness are dropped; below an
    optically opaque film (:data:`OPAQUE_AMPLITUDE`) nothing is evaluated and
    ``T = 0``; films thicker than ``coherence_thickness`` are averaged
    incoherently; with ``tabulate`` (``"auto"``, ``True``, ``False``) the
    needed sides are read from a verified table (:mod:`thinfilm_mi.tabulate.exact`)
    within ``table_error`` (``"auto"``: sides of ``R`` and ``T`` from ``rt_min_films``
    films if given); identical stacks share one table. Sides evaluated
    exactly run the recursion as a loop over the films in JIT variants
    (:class:`LoopFilms`; from how many films: :data:`BUFFERED_MIN_FILMS`)."""

    def __init__(self, films: Sequence[tuple[SpectralIndex, float]], ambient: SpectralIndex,
                 substrate: SpectralIndex, thickness_texture=None, *,
                 tabulate: bool | str = "auto", table_error: float = DEFAULT_TABLE_ERROR,
                 spectral_resolution: float = DEFAULT_SPECTRAL_RESOLUTION,
                 coherence_thickness: float = DEFAULT_COHERENCE_THICKNESS,
                 sides: dict | None = None, plugin: str = "thin-film BSDF",
                 rt_min_films: int | None = None):
        self.indices = [f[0] for f in films]
        self.thickness = [opaque_float(f[1]) for f in films]
        self.ambient = ambient
        self.substrate = substrate
        #: Optional Mitsuba texture; every film's thickness is multiplied by its
        #: value at the hit (clamped to >= 0).
        self.thickness_texture = thickness_texture
        #: the ``tabulate`` option (:data:`~thinfilm_mi.render.tabulation.TABULATE_OPTIONS`)
        self.tabulate = tabulate_option(tabulate)
        self.table_error = table_error
        self.spectral_resolution = spectral_resolution
        self.coherence_thickness = coherence_thickness
        self.sides = dict(sides) if sides is not None else {False: False}
        self.plugin = plugin
        #: ``tabulate="auto"`` tabulates a side of ``R`` and ``T`` from this many films
        #: (``None``: the quantity's own count, ``auto_min_films``)
        self.rt_min_films = rt_min_films
        self._gave_up = set()   # sides whose table could not be built
        if self.tabulate.required and thickness_texture is not None:
            raise ThinFilmError(f"{plugin}: 'tabulate' is true but a 'thickness' texture is "
                                "given: a table over (angle, wavelength) cannot follow a "
                                "thickness that varies over the surface (use 'auto' or false)")
        self._plan()

    def __len__(self) -> int:
        return len(self.indices)

    # -- planning (load time and after parameter changes) ---------------------
    def _thickness_values(self) -> list[float]:
        return [scalar(d) for d in self.thickness]

    def _opaque(self, index: SpectralIndex, d: float) -> bool:
        if self.thickness_texture is not None or d <= 0:
            return False   # a texture may thin the film anywhere
        n = index.spectral_values(GRID)
        k = n.imag if n is not None else texture_on_grid(index.k)
        return bool(np.max(np.exp(-2.0 * math.pi * k * d / GRID)) < OPAQUE_AMPLITUDE)

    def _side_plan(self, inside: bool, transmission: bool, films: list, opaque: list) -> SidePlan:
        """The plan of one side from the non-zero ``films`` ``(index, thickness,
        incoherent)`` and their ``opaque`` flags, both listed from the ambient."""
        if inside:
            films, opaque = films[::-1], opaque[::-1]
            n0, exit_, exit_real = self.substrate, self.ambient, True
        else:
            n0, exit_, exit_real = self.ambient, self.substrate, False
        if any(opaque):
            j = opaque.index(True)
            return SidePlan(n0, films[:j], films[j][0], False, True, transmission)
        return SidePlan(n0, films, exit_, exit_real, False, transmission)

    def _plan(self) -> None:
        # Zero-thickness films dropped; opacity decided once per film for all sides.
        kept = [(ix, d, dv) for ix, d, dv in
                zip(self.indices, self.thickness, self._thickness_values()) if dv > 0]
        films = [(ix, d, dv > self.coherence_thickness) for ix, d, dv in kept]
        opaque = [self._opaque(ix, dv) for ix, _, dv in kept]
        # Spectral variants: lossless films need no T (1 - R); both sides of a lossless
        # stack come from the ambient side's table of R or recursion (render.mirror)
        polarized = mitsuba_module().is_polarized
        spectral = colour_channels() is None and not polarized
        real = spectral and bool(films) and all(mirror.real_on_grid(ix) for ix, _, _ in films)
        lossless = {i: real and (not i or mirror.real_on_grid(self.substrate)) for i in self.sides}
        self.mirrored = (set(self.sides) == {False, True} and spectral
                         and mirror.mirror_applies(self.ambient, films, self.substrate))
        self.plan = {inside: self._side_plan(inside, t and not lossless[inside], films, opaque)
                     for inside, t in self.sides.items()}
        for inside, side in self.plan.items():
            side.lossless = lossless[inside]
        self.table_failed = []
        if colour_channels() is not None:
            # RGB and mono variants read integrated colour tables (thinfilm_mi.tabulate.integrated)
            for side in self.plan.values():
                side.colour = colour_table(self, side, side_data)
            if dr.is_diff_v(mitsuba_module().Float):
                prepare_gradients([self.ambient, self.substrate] + list(self.indices))
            return
        # Polarized variants read tables of the Mueller components
        # (thinfilm_mi.tabulate.mueller) or evaluate the complex amplitudes
        # (thinfilm_mi.render.amplitudes; their film loop has no real-amplitude form)
        quantity = MUELLER if polarized else POWERS
        self._plan_tables(quantity)
        reflection_channels = quantity.channels(False)
        if dr.is_jit_v(mitsuba_module().Float):
            for side in self.plan.values():
                # A side whose table serves the calls its plan is for (R, and T
                # where the plan asks for it) does not evaluate its films: no
                # buffers for it (other calls fall back to the unrolled films).
                served = (side.table is not None and (side.table.channels > reflection_channels
                                                      or side.opaque or not side.transmission
                                                      or side.lossless)
                          ) or self.mirror_table(side) is not None
                if (not served and len(side.films) >= BUFFERED_MIN_FILMS
                        and not any(side.incoherent)
                        and all(ix.knots is not None for ix, _, _ in side.films)):
                    side.loop = LoopFilms(side.films, side.n0, side.exit)

    def _plan_tables(self, quantity=POWERS) -> None:
        # "auto" tabulates in vectorised variants only: in scalar variants every
        # call is Python anyway and the load-time build would dominate.
        # ``quantity``: what the tables hold (tabulate.quantities.QUANTITIES)
        option = self.tabulate

        def few(side):   # "auto": fewer films than a table of this side pays for
            if self.mirrored and mirror.exact_mirrors(self.ambient, self.substrate):
                return len(side.films) < MIRROR_AUTO_MIN_FILMS
            rt = side.transmission and not side.opaque
            if rt and self.rt_min_films is not None:
                return len(side.films) < self.rt_min_films
            return len(side.films) < quantity.auto_min_films(rt)
        want = option.builds and (not option.selective or (
            self.thickness_texture is None and dr.is_jit_v(mitsuba_module().Float)
            and not all(few(s) for s in self.plan.values())))
        self.table_failed = []
        if not want or self._differentiating():
            return   # (thicknesses with gradients read every film: current_plan)
        for inside, side in self.plan.items():
            if inside and self.mirrored and self.plan[False].table is None:
                # no table to mirror: this side is planned (and tabulated) on its own
                self.mirrored = False
                side.transmission = self.sides[True] and not side.lossless
            if side.films and not (option.selective and (inside in self._gave_up or few(side))) \
                    and self.mirror_table(side) is None:
                side.table = _tables_cache(self, side, quantity)
                if side.table is None:
                    self.table_failed.append(inside)
                    # "auto" does not retry after every parameter edit: a failed build
                    # may spend the whole budget where its rejection cannot be predicted.
                    self._gave_up.add(inside)
        if option.required and self.table_failed:
            import warnings
            why = "; ".join(sorted({str((self.plan[i].build_report or {}).get("result"))
                                    for i in self.table_failed}))
            warnings.warn(f"{self.plugin}: the stack {self.describe()} cannot be tabulated "
                          f"within table_error={self.table_error:g} in {MAX_TEXELS} "
                          f"texels and {option.budget_scale:g}x the build budget of 'auto' "
                          f"({why}); it is evaluated exactly", stacklevel=3)

    def mode(self) -> Route:
        """The :class:`~thinfilm_mi.render.tabulation.Route` of the planned sides: ``"table"``
        if every one reads a table, ``"exact"`` if none, else ``"mixed"``."""
        return Route.of([s.table is not None or self.mirror_table(s) is not None
                         for s in self.plan.values() if s.films])

    def mirror_table(self, side: SidePlan):
        """The table that serves ``side`` lit from the substrate through the ambient
        side's (:mod:`thinfilm_mi.render.mirror`), or ``None``."""
        outside = self.plan.get(False)
        return outside.table if self.mirrored and side is self.plan.get(True) else None

    def describe(self) -> str:
        films = "; ".join(f"{ix.label} {scalar(d):g} nm"
                          for ix, d in zip(self.indices, self.thickness))
        return f"[{films}]" if films else "[no films]"

    def traverse(self, callback) -> None:
        mi = mitsuba_module()
        for i, (ix, d) in enumerate(zip(self.indices, self.thickness)):
            callback.put(f"layers.{i}.thickness", d, mi.ParamFlags.Differentiable)
            ix.traverse(callback, f"layers.{i}.")
        if self.thickness_texture is not None:
            callback.put("thickness", self.thickness_texture, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=None) -> None:
        """Refresh after an edit (``keys``, the changed keys, are not needed:
        the plan and its tables are rebuilt from the current values)."""
        for i, ix in enumerate(self.indices):
            ix.parameters_changed(self.plugin, f"layers.{i}.")
        for i, d in enumerate(self.thickness):
            if dr.is_jit_v(d):
                dr.make_opaque(d)
            if not math.isfinite(scalar(d)) or scalar(d) < 0:
                raise ThinFilmError(f"{self.plugin}: layers.{i}.thickness must be a finite "
                                    f"number >= 0 (nm), got {scalar(d)!r}")
        self._plan()

    def thickness_scale_at(self, si, active=True):
        """The thickness texture's value at the hit (>= 0), or ``None`` without one."""
        if self.thickness_texture is None:
            return None
        return dr.maximum(self.thickness_texture.eval_1(si, active), 0.0)

    # -- evaluation -------------------------------------------------------------
    def _differentiating(self) -> bool:
        return any(dr.grad_enabled(d) for d in self.thickness if dr.is_diff_v(d))

    def _full_plan(self, inside: bool, transmission: bool) -> SidePlan:
        """Every film, no skips, no table (for gradients through every film)."""
        films = [(ix, d, False) for ix, d in zip(self.indices, self.thickness)]
        return self._side_plan(inside, transmission, films, [False] * len(films))

    def index_gradients(self, si, active=True) -> bool:
        """Whether an index of this stack (ambient, films, substrate) carries
        gradients at the hit (AD variants; decided when the kernel is traced: one
        texture evaluation per medium, dropped unless used)."""
        if not dr.is_diff_v(mitsuba_module().Float):
            return False
        media = [self.ambient, self.substrate] + list(self.indices)
        return any(ix.carries_gradients(si, active) for ix in media)

    def current_plan(self, inside: bool, transmission: bool,
                     index_gradients: bool = False) -> SidePlan:
        """The plan of the side lit from the ambient (``inside`` false) or the
        substrate, as evaluated now: every film, without skips or table, when a
        thickness (or, with ``index_gradients``, an index) carries gradients or the
        side was not planned (a table and the film loop's buffers hold numbers, not
        derivatives)."""
        side = self.plan.get(inside)
        if side is None or self._differentiating() or index_gradients:
            side = self._full_plan(inside, transmission)
        return side

    def side_response(self, inside: bool, si, cos_theta, active, transmission: bool,
                   thickness_scale):
        """The planned side ``inside`` at the hit: its table, else its films exactly."""
        mi = mitsuba_module()
        # RGB/mono variants come here only for a side without films: any wavelength will do
        wl = si.wavelengths if mi.is_spectral else mi.Spectrum(550.0)
        side = self.current_plan(inside, transmission, self.index_gradients(si, active))
        n0 = side.n0.eval_real(si, active)
        table = side.table
        if table is not None and thickness_scale is None and (
                not transmission or side.opaque or table.channels > 1 or side.lossless):
            n_exit = side.exit.eval_real(si, active) if table.axis.needs_n_exit else None
            res = table.lookup(cos_theta, n0, n_exit, wl, active)
            if not transmission:
                return res[0]
            if side.lossless and table.channels == 1:
                return res[0], 1.0 - res[0]
            return res[0], (mi.UnpolarizedSpectrum(0.0) if side.opaque else res[1])
        exit_ = Cx(side.exit.eval_real(si, active), 0.0) if side.exit_real \
            else side.exit.eval(si, active)
        if side.loop is not None:
            out = side.loop.rt(n0, cos_theta, exit_, wl, transmission, thickness_scale)
        else:
            films = [(ix.eval(si, active), d if thickness_scale is None else d * thickness_scale)
                     for ix, d, _ in side.films]
            out = _rt(n0, cos_theta, films, exit_, wl, side.incoherent, transmission)
        if transmission and side.opaque:
            return out[0], mi.UnpolarizedSpectrum(0.0)
        return out

    def at_wavelengths(self, inside: bool, si, cos_theta, active, transmission: bool,
                       thickness_scale, wl):
        """Exact ``R`` [, ``T``] at the wavelengths ``wl`` (``mi.Spectrum``) in an
        RGB/mono variant, through every film (the colour gradients)."""
        mi = mitsuba_module()
        side = self._full_plan(inside, transmission)

        def index(ix):
            return Cx(*index_on_wavelengths(ix, si, wl, active))
        n0 = index(side.n0).re
        exit_ = index(side.exit)
        if side.exit_real:
            exit_ = Cx(exit_.re, 0.0)
        films = [(index(ix), d if thickness_scale is None else d * thickness_scale)
                 for ix, d, _ in side.films]
        out = _rt(n0, cos_theta, films, exit_, wl, side.incoherent, transmission)
        if transmission and side.opaque:
            return out[0], mi.Spectrum(0.0)
        return out

    def colour(self, si, cos_theta, active=True, *, inside: bool | Any = False,
               transmission: bool = False):
        """RGB/mono variants: ``R`` (and ``T`` if asked) as ``mi.Spectrum`` colours,
        the spectral values integrated against colour matching
        (:mod:`thinfilm_mi.tabulate.integrated`), read from the side's colour table; a side
        with no films over an index given per channel is evaluated per channel
        (Fresnel), as Mitsuba's ``conductor`` does. Where a thickness or an index
        carries gradients, they come from an unbiased estimate of the integral
        (:class:`~thinfilm_mi.render.colour_variants.GradientSampler`); the value stays the
        table's. Arguments as :meth:`reflectance`."""
        scale = self.thickness_scale_at(si, active)

        def side(flag: bool):
            plan = self.plan.get(flag)
            if plan is None:
                raise ThinFilmError(f"{self.plugin}: internal error: the side lit from the "
                                    f"{'substrate' if flag else 'ambient'} was not planned")
            if plan.colour is None:
                return self.side_response(flag, si, cos_theta, active, transmission, None)
            R, T = plan.colour.lookup(cos_theta, scale, active)
            if transmission and T is None:
                T = mitsuba_module().Spectrum(0.0)
            if self.colour_gradients(si, active):
                sampler = GradientSampler.get()
                wl = sampler.wavelengths(si)
                exact = self.at_wavelengths(flag, si, cos_theta, active, transmission, scale,
                                            wl)
                if transmission:
                    R = attach_gradient(R, sampler.estimate(wl, exact[0]))
                    T = attach_gradient(T, sampler.estimate(wl, exact[1]))
                else:
                    R = attach_gradient(R, sampler.estimate(wl, exact))
            return (R, T) if transmission else R

        return mirror.either_side(side, inside, transmission, mirror.branches(self))

    def colour_gradients(self, si, active=True) -> bool:
        """Whether a film thickness or an index of this stack carries gradients
        (RGB/mono AD variants; decided when the kernel is traced)."""
        if not dr.is_diff_v(mitsuba_module().Float):
            return False
        return self._differentiating() or self.index_gradients(si, active)

    def reflectance(self, si, cos_theta, active=True, *, inside: bool | Any = False,
                    transmission: bool = False, thickness_scale=None):
        """Unpolarized ``R`` (and ``T`` if asked) as ``mi.Spectrum`` at ``si.wavelengths``.

        ``cos_theta`` is the (positive) cosine of incidence measured on the side
        the light comes from. ``inside`` (a Python bool or a mask) selects the
        reversed stack lit from the substrate; the substrate must then be a
        non-absorbing medium. Where ``inside`` is a mask both directions are
        evaluated and blended with ``dr.select``.
        """
        if thickness_scale is None:
            thickness_scale = self.thickness_scale_at(si, active)
        if (self.mirrored and thickness_scale is None and self.current_plan(
                False, False, self.index_gradients(si, active)) is self.plan[False]):
            out = mirror.mirrored_rt(self, si, cos_theta, inside, active, transmission)
            if out is not None:
                return out

        def side(flag: bool):
            return self.side_response(flag, si, cos_theta, active, transmission, thickness_scale)

        return mirror.either_side(side, inside, transmission, mirror.branches(self))


def _rt(n0, cos0, films, n_exit, wl, incoherent, transmission):
    """Coherent :func:`unpolarized_rt`, or the incoherent-aware evaluator when
    some film is beyond the coherence thickness."""
    if any(incoherent):
        from thinfilm_mi.optics.incoherent import incoherent_rt
        return incoherent_rt(n0, cos0, films, n_exit, wl, incoherent, transmission=transmission)
    return unpolarized_rt(n0, cos0, films, n_exit, wl, transmission)


#: Tables shared between stacks with identical optics (bounded: 64 MiB of texture data).
TABLE_CACHE = TableCache()
#: Builds of at least this many exact evaluations (~30 ms and more: the probes of
#: 10 films and more, every band-limited build) are kept in the table store
#: (:mod:`thinfilm_mi.tabulate.store`) for later processes; cheaper ones are rebuilt.
STORE_MIN_POINTS = 50_000


def _tables_cache(stack: KernelStack, side: SidePlan, quantity=POWERS):
    """The table of ``side``, shared between stacks with identical optics.

    The key is the stack's numbers (every index on the 1 nm grid, thicknesses,
    incoherent flags, what is tabulated, the target, the texel cap), so two
    BSDFs with the same films share one texture. Tables are never modified in
    place. ``quantity``: what the table holds
    (:data:`~thinfilm_mi.tabulate.quantities.QUANTITIES`).

    Not in this process's cache, the table is looked up in the table store on
    disk (:func:`~thinfilm_mi.tabulate.store.default_store`, the report then says
    ``"from the table store"`` with the original build's report under ``build``);
    a build of :data:`STORE_MIN_POINTS` evaluations or more is kept there for
    later processes.
    """
    mi = mitsuba_module()
    media = [side.n0] + [f[0] for f in side.films] + [side.exit]
    values, arrays = {}, []
    for ix in media:
        if id(ix) not in values:
            if ix.eta.is_spatially_varying() or ix.k.is_spatially_varying():
                return None   # an index that varies over the surface: not tabulable
            values[id(ix)] = (texture_on_grid(ix.eta), texture_on_grid(ix.k))
        arrays += values[id(ix)]
    transmission = side.transmission and not side.opaque
    channels = quantity.channels(transmission)
    option = stack.tabulate
    max_texels = quantity.auto_max_floats // channels if option.selective else MAX_TEXELS
    budget_scale = option.budget_scale
    key = table_key(arrays, side.films, (mi.variant(), side.transmission, side.exit_real, side.opaque,
                                         stack.table_error, stack.spectral_resolution, max_texels,
                                         budget_scale, quantity.name,
                                         quantity.linear_max_floats))
    found, table = TABLE_CACHE.get(key)
    if found:
        side.build_report = BuildReport(result="from the cache")
        return table
    disk = default_store()
    if disk is not None:
        found, table, report = disk.get(key)
        if found:
            side.build_report = BuildReport(result="from the table store",
                                                          build=report)
            TABLE_CACHE.put(key, table)
            return table

    data = side_data(side, transmission, quantity=quantity)
    side.build_report = report = BuildReport()
    table = band.build_table(data, stack.table_error, GRID, max_texels,
                             stack.spectral_resolution, report=report,
                             budget_scale=budget_scale, linear_floats=quantity.linear_max_floats)
    TABLE_CACHE.put(key, table)
    work = report.get("points", 0) + (report.get("exact_attempt") or {}).get("points", 0)
    if disk is not None and work >= STORE_MIN_POINTS:
        disk.put(key, table, report)
    return table


def _index_function(ix: SpectralIndex, real: bool = False, channel: complex | None = None):
    """``wl -> index`` (float64 numpy) of a medium for the table builds: its spectral
    values (:meth:`SpectralIndex.spectral_values`), or the constant ``channel``."""
    memo = {}

    def f(wl):   # the build asks for the same wavelengths several times
        wl = np.asarray(wl, np.float64)
        if channel is not None:
            return np.full(wl.shape, channel.real if real else channel)
        key = wl.tobytes()
        if key not in memo:
            memo.clear()
            memo[key] = ix.spectral_values(wl, real)
        return memo[key]
    return f


def side_data(side: SidePlan, transmission: bool, channel: dict | None = None,
              quantity=POWERS) -> SideData:
    """The float64 build data (:class:`~thinfilm_mi.tabulate.base.SideData`) of ``side``; ``channel`` maps
    media (by ``id``) given per channel to their index in the channel built;
    ``quantity``: what is tabulated (:data:`~thinfilm_mi.tabulate.quantities.QUANTITIES`)."""
    channel = channel or {}

    def on(ix, real=False):
        return _index_function(ix, real, channel.get(id(ix)))

    incoherent = side.incoherent
    media = [side.n0] + [f[0] for f in side.films] + [side.exit]
    return SideData(
        n0=on(side.n0, real=True), films=[(on(ix), scalar(d)) for ix, d, _ in side.films],
        n_exit=on(side.exit, real=True) if side.exit_real else on(side.exit),
        transmission=transmission, rt=quantity.rt(incoherent), quantity=quantity,
        rt_loop=None if any(incoherent) else quantity.rt_loop,
        kinks=np.unique(np.concatenate([ix.kinks for ix in media])),
        fringe_films=[j for j, f in enumerate(side.films) if not f[2]])

