"""How a stack is planned (no plugin classes here): the options of a
:class:`~thinfilm_mi.render.kernel.KernelStack` (:class:`StackOptions`), and from what
the stack is (:class:`~thinfilm_mi.render.film_stack.StackFacts`) per lit side what its
evaluation skips and reads (:class:`SidePlan`) and what is built for it
(:func:`plan_sides`, a :class:`StackPlan`): pure decisions, nothing built.

What a scene does not need is skipped (re-decided after every edit): films of zero
thickness are dropped; below an optically opaque film nothing is evaluated and
``T = 0``; films thicker than ``coherence_thickness`` are averaged incoherently;
lossless films need no ``T`` (``1 - R``), and both sides of a lossless stack may read
the ambient side's table (mirrored, :func:`mirror_applies`, evaluated by
:mod:`thinfilm_mi.render.mirror`). Whether tables are built at all
(:func:`wants_tables`), which sides a table pays for (:func:`few_films`), which sides an
edit leaves to the tables already built (:func:`cached_only`) and which
sides read their films from buffers where no table serves them (:func:`buffered`) are
decided here too; :mod:`thinfilm_mi.render.stack_build` builds what the plan asks for.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import drjit as dr
import numpy as np

from thinfilm_mi.render.colour_variants import colour_channels
from thinfilm_mi.render.film_stack import OPAQUE_AMPLITUDE, FilmStack, StackFacts
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.tabulation import Route, tabulate_option
from thinfilm_mi.render.textures import mitsuba_module
from thinfilm_mi.tabulate.mueller import MUELLER
from thinfilm_mi.tabulate.policy import EDIT_EXACT_MIN_FILMS, MIRROR_AUTO_MIN_FILMS
from thinfilm_mi.tabulate.quantities import POWERS

__all__ = ["BUFFERED_MIN_FILMS", "DEFAULT_COHERENCE_THICKNESS", "DEFAULT_SPECTRAL_RESOLUTION",
           "DEFAULT_TABLE_ERROR", "OPAQUE_AMPLITUDE", "SidePlan", "StackOptions", "StackPlan",
           "buffered", "cached_only", "exact_mirrors", "few_films", "full_plan", "mirror_applies",
           "plan_sides", "wants_tables"]

#: Default coherence thickness (nm): thicker films are averaged incoherently.
DEFAULT_COHERENCE_THICKNESS = 5000.0
#: Default target for the tables: max abs error in R and T.
DEFAULT_TABLE_ERROR = 1e-3
#: Default ``spectral_resolution`` (nm): a stack whose exact ``R`` and ``T`` no table
#: resolves (cavity resonances ~0.1 nm wide) gets a table of them convolved with a Gaussian
#: in wavenumber of this standard deviation at 560 nm (:mod:`thinfilm_mi.tabulate.band`),
#: narrow enough that broadband light shows no difference in colour.
DEFAULT_SPECTRAL_RESOLUTION = 1.0
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
    """How one lighting side of a stack is evaluated, after the skips, and what is
    built for it.

    ``films`` are ``(SpectralIndex, thickness, incoherent)`` from the side the
    light comes from; ``exit`` is the exit medium (the substrate, the ambient,
    or the first optically opaque film, in which case ``opaque`` is true and
    ``T = 0``); ``lossless``: non-absorbing films under a real incidence medium
    (``T = 1 - R``, tables hold ``R``). The plan's answers for the build:
    ``tabulate``, a table of the side is built, or with ``cached_only`` only taken
    from the caches (:func:`cached_only`); ``buffered``, the side reads its films from
    buffers where no table serves it (:func:`buffered`). What
    :mod:`~thinfilm_mi.render.stack_build` builds comes with it: ``table`` (a
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
    tabulate: bool = False
    cached_only: bool = False
    buffered: bool = False
    table: Any = None
    build_report: Any = None
    loop: Any = None
    colour: Any = None

    @property
    def incoherent(self) -> list[bool]:
        return [f[2] for f in self.films]


@dataclass(frozen=True, eq=False)
class StackPlan:
    """The planned sides of a stack: ``sides`` maps ``inside`` to its :class:`SidePlan`;
    ``mirrored``: the side lit from the substrate reads the ambient side's table
    (:mod:`thinfilm_mi.render.mirror`); what the build reads: ``facts`` (the
    :class:`~thinfilm_mi.render.film_stack.StackFacts` planned from), ``options``
    (:class:`StackOptions`), ``tables`` (whether tables are built at all),
    ``quantity`` (what they hold, a :data:`~thinfilm_mi.tabulate.quantities.QUANTITIES`
    entry); after the build, ``failed``: the sides whose table could not be built, and
    ``gave_up``: those whose table ``"auto"`` does not try again (a failed build may
    spend the whole budget where its rejection cannot be predicted)."""

    sides: dict
    mirrored: bool
    facts: StackFacts | None = None
    options: StackOptions | None = None
    tables: bool = False
    quantity: Any = POWERS
    failed: list = field(default_factory=list)
    gave_up: frozenset = frozenset()

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


def mirror_applies(facts: StackFacts, films: list) -> bool:
    """Whether both sides of these films (``(index, thickness, incoherent)``) may be
    read from the ambient side's table of ``R``: every medium lossless and the
    substrate's index nowhere below the ambient's (the ambient side then never
    totally reflects, and its table has one angle segment)."""
    ambient, substrate = facts.stack.ambient, facts.stack.substrate
    if not films or not all(facts.real[id(ix)] for ix in [ambient, substrate]
                            + [ix for ix, _, _ in films]):
        return False
    return bool(np.all(facts.grid[id(substrate)].real >= facts.grid[id(ambient)].real))


def exact_mirrors(ambient: SpectralIndex, substrate: SpectralIndex) -> bool:
    """Whether a mirrored stack between these media is evaluated exactly without a
    table (:func:`~thinfilm_mi.render.mirror.mirrored_rt`): neither is dispersive, so
    one mapped angle serves every wavelength."""
    return all(ix.knots is not None and ix.knots.size == 0 for ix in (ambient, substrate))


def plan_sides(facts: StackFacts, options: StackOptions, gave_up=frozenset(),
               edited: bool = False) -> StackPlan:
    """The sides of the stack ``facts`` describe that ``options.sides`` asks for, after
    the skips (see the module), with what is built for them decided (nothing built
    yet); ``gave_up``: the sides whose table ``"auto"`` does not try again; ``edited``:
    the stack is planned after an edit (:func:`cached_only`)."""
    stack = facts.stack
    # Zero-thickness films dropped; opacity decided once per film for all sides.
    kept = [(ix, d, dv, op) for ix, d, dv, op in
            zip(stack.indices, stack.thickness, facts.thickness, facts.opaque) if dv > 0]
    films = [(ix, d, dv > options.coherence_thickness) for ix, d, dv, _ in kept]
    opaque = [op for _, _, _, op in kept]
    # Spectral variants: lossless films need no T (1 - R); both sides of a lossless
    # stack come from the ambient side's table of R or recursion (render.mirror)
    polarized = mitsuba_module().is_polarized
    colour = colour_channels() is not None
    spectral = not colour and not polarized
    real = spectral and bool(films) and all(facts.real[id(ix)] for ix, _, _ in films)
    lossless = {i: real and (not i or facts.real[id(stack.substrate)]) for i in options.sides}
    mirrored = (set(options.sides) == {False, True} and spectral
                and mirror_applies(facts, films))
    sides = {inside: side_plan(stack, inside, t and not lossless[inside], films, opaque,
                               lossless[inside])
             for inside, t in options.sides.items()}
    # Polarized variants read tables of the Mueller components
    # (thinfilm_mi.tabulate.mueller) or evaluate the complex amplitudes
    # (thinfilm_mi.render.amplitudes; their film loop has no real-amplitude form)
    quantity = MUELLER if polarized else POWERS
    tables = (not colour and not facts.differentiating
              and wants_tables(stack, options, sides, mirrored, quantity))
    selective = options.tabulate.selective
    jit = dr.is_jit_v(mitsuba_module().Float)
    # The side lit from the substrate of a mirrored plan is tabulated only where the
    # ambient side's table is not built (then it is planned on its own)
    sides = {inside: replace(
                 side, tabulate=tables and bool(side.films) and not (selective and (
                     inside in gave_up or few_films(stack, options, side, mirrored and not inside,
                                                    quantity))),
                 cached_only=edited and cached_only(options, side),
                 buffered=not colour and jit and buffered(side))
             for inside, side in sides.items()}
    return StackPlan(sides, mirrored, facts, options, tables, quantity, gave_up=frozenset(gave_up))


def few_films(stack: FilmStack, options: StackOptions, side: SidePlan, mirrored: bool,
              quantity) -> bool:
    """``tabulate="auto"``: whether ``side`` has fewer films than a table of it pays
    for (``quantity``: what the table would hold, a
    :data:`~thinfilm_mi.tabulate.quantities.QUANTITIES` entry; ``mirrored``: the table
    serves both sides)."""
    if mirrored and exact_mirrors(stack.ambient, stack.substrate):
        return len(side.films) < MIRROR_AUTO_MIN_FILMS
    rt = side.transmission and not side.opaque
    if rt and options.rt_min_films is not None:
        return len(side.films) < options.rt_min_films
    return len(side.films) < quantity.auto_min_films(rt)


def cached_only(options: StackOptions, side: SidePlan) -> bool:
    """``tabulate="auto"`` after an edit: whether ``side`` reads a table only where one of
    its new values is cached, and is otherwise evaluated exactly (from
    :data:`~thinfilm_mi.tabulate.policy.EDIT_EXACT_MIN_FILMS` films: a rebuild per edit
    would cost more than the renders between edits)."""
    return options.tabulate.selective and len(side.films) >= EDIT_EXACT_MIN_FILMS


def wants_tables(stack: FilmStack, options: StackOptions, sides: dict, mirrored: bool,
                 quantity) -> bool:
    """Whether tables are built for the planned ``sides`` at all: ``tabulate`` true, or
    ``"auto"`` in vectorised variants (in scalar variants every call is Python anyway
    and the load-time build would dominate) without a thickness texture, where some
    side has the films a table pays for (:func:`few_films`)."""
    option = options.tabulate
    return option.builds and (not option.selective or (
        stack.thickness_texture is None and dr.is_jit_v(mitsuba_module().Float)
        and not all(few_films(stack, options, s, mirrored, quantity) for s in sides.values())))


def buffered(side: SidePlan) -> bool:
    """Whether ``side`` (JIT variants) reads its films from buffers
    (:class:`~thinfilm_mi.render.loop.LoopFilms`) where no table serves the calls its
    plan is for: not a side of fewer than :data:`BUFFERED_MIN_FILMS` films, nor one
    with an incoherent film or an index without knots."""
    return (len(side.films) >= BUFFERED_MIN_FILMS and not any(side.incoherent)
            and all(ix.knots is not None for ix, _, _ in side.films))
