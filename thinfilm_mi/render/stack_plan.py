"""How a stack is planned (no plugin classes here): the options of a
:class:`~thinfilm_mi.render.kernel.KernelStack` (:class:`StackOptions`), and per lit
side what its evaluation skips and reads (:class:`SidePlan`, :func:`plan_sides`).

What a scene does not need is skipped (re-decided after every edit): films of zero
thickness are dropped; below an optically opaque film (:data:`OPAQUE_AMPLITUDE`)
nothing is evaluated and ``T = 0``; films thicker than ``coherence_thickness`` are
averaged incoherently; lossless films need no ``T`` (``1 - R``), and both sides of a
lossless stack may read the ambient side's table (mirrored,
:mod:`thinfilm_mi.render.mirror`). Which sides a table pays for
(:func:`wants_tables`, :func:`few_films`) and which sides read their films from
buffers (:func:`reads_buffers`) are decided here too; the tables and buffers are
built by :mod:`thinfilm_mi.render.stack_build`, into a :class:`StackPlan`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import drjit as dr
import numpy as np

from thinfilm_mi.render import mirror
from thinfilm_mi.render.colour_variants import colour_channels
from thinfilm_mi.render.film_stack import FilmStack
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.tabulation import Route, tabulate_option
from thinfilm_mi.render.textures import GRID, mitsuba_module, texture_on_grid
from thinfilm_mi.tabulate.policy import MIRROR_AUTO_MIN_FILMS

__all__ = ["BUFFERED_MIN_FILMS", "DEFAULT_COHERENCE_THICKNESS", "DEFAULT_SPECTRAL_RESOLUTION",
           "DEFAULT_TABLE_ERROR", "OPAQUE_AMPLITUDE", "SidePlan", "StackOptions", "StackPlan",
           "few_films", "full_plan", "optically_opaque", "plan_sides", "reads_buffers",
           "wants_tables"]

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


class StackOptions:
    """The options of a stack's plan, as a plugin's properties give them.

    ``tabulate`` (``"auto"``, ``True``, ``False``: :mod:`thinfilm_mi.render.tabulation`)
    with ``table_error`` and ``spectral_resolution``: which sides read a verified
    table, and within what; ``coherence_thickness`` (nm): thicker films are averaged
    incoherently; ``sides`` maps ``inside`` (False: lit from the ambient, True: from
    the substrate) to whether ``T`` is needed there; ``rt_min_films``: ``"auto"``
    tabulates a side of ``R`` and ``T`` from this many films (``None``: the
    quantity's own count, ``auto_min_films``)."""

    def __init__(self, tabulate: bool | str = "auto", table_error: float = DEFAULT_TABLE_ERROR,
                 spectral_resolution: float = DEFAULT_SPECTRAL_RESOLUTION,
                 coherence_thickness: float = DEFAULT_COHERENCE_THICKNESS,
                 sides: dict | None = None, rt_min_films: int | None = None):
        #: the ``tabulate`` option (:data:`~thinfilm_mi.render.tabulation.TABULATE_OPTIONS`)
        self.tabulate = tabulate_option(tabulate)
        self.table_error = table_error
        self.spectral_resolution = spectral_resolution
        self.coherence_thickness = coherence_thickness
        self.sides = dict(sides) if sides is not None else {False: False}
        self.rt_min_films = rt_min_films


@dataclass(frozen=True, eq=False)
class SidePlan:
    """How one lighting side of a stack is evaluated, after the skips.

    ``films`` are ``(SpectralIndex, thickness, incoherent)`` from the side the
    light comes from; ``exit`` is the exit medium (the substrate, the ambient,
    or the first optically opaque film, in which case ``opaque`` is true and
    ``T = 0``); ``lossless``: non-absorbing films under a real incidence medium
    (``T = 1 - R``, tables hold ``R``). What :mod:`~thinfilm_mi.render.stack_build`
    builds for the side comes with it: ``table`` (a
    :class:`~thinfilm_mi.tabulate.base.Table`) and ``build_report`` (what its build
    did, a :class:`~thinfilm_mi.tabulate.base.BuildReport`), ``loop`` (a
    :class:`~thinfilm_mi.render.loop.LoopFilms` where the films are read from
    buffers), ``colour`` (RGB/mono variants: a
    :class:`~thinfilm_mi.tabulate.integrated.ColourTable`, or ``None`` where the plugin
    evaluates per channel: no films over an index given per channel)."""

    n0: SpectralIndex
    films: list
    exit: SpectralIndex
    exit_real: bool
    opaque: bool
    transmission: bool
    lossless: bool = False
    table: Any = None
    build_report: Any = None
    loop: Any = None
    colour: Any = None

    @property
    def incoherent(self) -> list[bool]:
        return [f[2] for f in self.films]

    def with_(self, **changes) -> "SidePlan":
        """This plan with ``changes`` (a built table, a loop; a new object)."""
        return replace(self, **changes)


class StackPlan:
    """The planned sides of a stack: ``sides`` maps ``inside`` to its :class:`SidePlan`;
    ``mirrored``: the side lit from the substrate reads the ambient side's table
    (:mod:`thinfilm_mi.render.mirror`); ``failed``: the sides whose table could not be
    built."""

    def __init__(self, sides: dict, mirrored: bool, failed: list | None = None):
        self.sides = sides
        self.mirrored = mirrored
        self.failed = list(failed or [])

    def mirror_table(self, side: SidePlan):
        """The table that serves ``side`` lit from the substrate through the ambient
        side's (:mod:`thinfilm_mi.render.mirror`), or ``None``."""
        outside = self.sides.get(False)
        return outside.table if self.mirrored and side is self.sides.get(True) else None

    def route(self) -> Route:
        """The :class:`~thinfilm_mi.render.tabulation.Route` of the planned sides: ``"table"``
        if every one reads a table, ``"exact"`` if none, else ``"mixed"``."""
        return Route.of([s.table is not None or self.mirror_table(s) is not None
                         for s in self.sides.values() if s.films])


def optically_opaque(index: SpectralIndex, d: float, textured: bool) -> bool:
    """Whether a film of ``index``, ``d`` nm thick, hides what lies beneath it
    (:data:`OPAQUE_AMPLITUDE`); never under a thickness texture (``textured``), which
    may thin the film anywhere."""
    if textured or d <= 0:
        return False
    n = index.spectral_values(GRID)
    k = n.imag if n is not None else texture_on_grid(index.k)
    return bool(np.max(np.exp(-2.0 * math.pi * k * d / GRID)) < OPAQUE_AMPLITUDE)


def side_plan(stack: FilmStack, inside: bool, transmission: bool, films: list, opaque: list,
              lossless: bool = False) -> SidePlan:
    """The plan of one side from the non-zero ``films`` ``(index, thickness,
    incoherent)`` and their ``opaque`` flags, both listed from the ambient."""
    if inside:
        films, opaque = films[::-1], opaque[::-1]
        n0, exit_, exit_real = stack.substrate, stack.ambient, True
    else:
        n0, exit_, exit_real = stack.ambient, stack.substrate, False
    if any(opaque):
        j = opaque.index(True)
        return SidePlan(n0, films[:j], films[j][0], False, True, transmission, lossless)
    return SidePlan(n0, films, exit_, exit_real, False, transmission, lossless)


def full_plan(stack: FilmStack, inside: bool, transmission: bool) -> SidePlan:
    """Every film, no skips, no table (for gradients through every film)."""
    films = [(ix, d, False) for ix, d in zip(stack.indices, stack.thickness)]
    return side_plan(stack, inside, transmission, films, [False] * len(films))


def plan_sides(stack: FilmStack, options: StackOptions) -> StackPlan:
    """The sides of ``stack`` that ``options.sides`` asks for, after the skips (see
    the module), with nothing built yet."""
    # Zero-thickness films dropped; opacity decided once per film for all sides.
    kept = [(ix, d, dv) for ix, d, dv in
            zip(stack.indices, stack.thickness, stack.thickness_values()) if dv > 0]
    films = [(ix, d, dv > options.coherence_thickness) for ix, d, dv in kept]
    textured = stack.thickness_texture is not None
    opaque = [optically_opaque(ix, dv, textured) for ix, _, dv in kept]
    # Spectral variants: lossless films need no T (1 - R); both sides of a lossless
    # stack come from the ambient side's table of R or recursion (render.mirror)
    polarized = mitsuba_module().is_polarized
    spectral = colour_channels() is None and not polarized
    real = spectral and bool(films) and all(mirror.real_on_grid(ix) for ix, _, _ in films)
    lossless = {i: real and (not i or mirror.real_on_grid(stack.substrate)) for i in options.sides}
    mirrored = (set(options.sides) == {False, True} and spectral
                and mirror.mirror_applies(stack.ambient, films, stack.substrate))
    sides = {inside: side_plan(stack, inside, t and not lossless[inside], films, opaque,
                               lossless[inside])
             for inside, t in options.sides.items()}
    return StackPlan(sides, mirrored)


def few_films(stack: FilmStack, options: StackOptions, side: SidePlan, mirrored: bool,
              quantity) -> bool:
    """``tabulate="auto"``: whether ``side`` has fewer films than a table of it pays
    for (``quantity``: what the table would hold, a
    :data:`~thinfilm_mi.tabulate.quantities.QUANTITIES` entry)."""
    if mirrored and mirror.exact_mirrors(stack.ambient, stack.substrate):
        return len(side.films) < MIRROR_AUTO_MIN_FILMS
    rt = side.transmission and not side.opaque
    if rt and options.rt_min_films is not None:
        return len(side.films) < options.rt_min_films
    return len(side.films) < quantity.auto_min_films(rt)


def wants_tables(stack: FilmStack, options: StackOptions, plan: StackPlan, quantity) -> bool:
    """Whether tables are built for ``plan`` at all: ``tabulate`` true, or ``"auto"``
    in vectorised variants (in scalar variants every call is Python anyway and the
    load-time build would dominate) without a thickness texture, where some side
    has the films a table pays for (:func:`few_films`)."""
    option = options.tabulate
    return option.builds and (not option.selective or (
        stack.thickness_texture is None and dr.is_jit_v(mitsuba_module().Float)
        and not all(few_films(stack, options, s, plan.mirrored, quantity)
                    for s in plan.sides.values())))


def reads_buffers(plan: StackPlan, side: SidePlan, reflection_channels: int) -> bool:
    """Whether ``side`` (JIT variants) reads its films from buffers
    (:class:`~thinfilm_mi.render.loop.LoopFilms`): a side whose table serves the calls
    its plan is for (``R``, and ``T`` where the plan asks for it) does not evaluate its
    films (other calls fall back to the unrolled films), nor does one with an
    incoherent film or an index without knots; ``reflection_channels``: the channels
    of a table of ``R`` alone."""
    served = (side.table is not None and (side.table.channels > reflection_channels
                                          or side.opaque or not side.transmission
                                          or side.lossless)
              ) or plan.mirror_table(side) is not None
    return (not served and len(side.films) >= BUFFERED_MIN_FILMS
            and not any(side.incoherent)
            and all(ix.knots is not None for ix, _, _ in side.films))
