"""How a stack's plan is built (no plugin classes here): :func:`build_plan` plans the
sides of a :class:`~thinfilm_mi.render.film_stack.FilmStack`
(:func:`~thinfilm_mi.render.stack_plan.plan_sides`) and returns them with what they
read: in RGB/mono variants their colour tables
(:func:`~thinfilm_mi.render.colour_variants.colour_table`); elsewhere the verified
tables the plan wants (:func:`build_tables`: of the powers,
:mod:`thinfilm_mi.tabulate.exact`, or of the Mueller components,
:mod:`thinfilm_mi.tabulate.mueller`), shared between stacks with identical optics
(:data:`TABLE_CACHE`, then the table store on disk), and the films' buffers
(:class:`~thinfilm_mi.render.loop.LoopFilms`) of the sides evaluated exactly.
"""
from __future__ import annotations

import warnings

import drjit as dr
import numpy as np

from thinfilm_mi.render.colour_variants import colour_channels, colour_table, prepare_gradients
from thinfilm_mi.render.film_stack import FilmStack
from thinfilm_mi.render.loop import LoopFilms
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.stack_plan import (
    SidePlan,
    StackOptions,
    StackPlan,
    few_films,
    plan_sides,
    reads_buffers,
    wants_tables,
)
from thinfilm_mi.render.tabulation import table_key
from thinfilm_mi.render.textures import GRID, mitsuba_module, scalar, texture_on_grid
from thinfilm_mi.tabulate import band
from thinfilm_mi.tabulate.base import BuildReport, SideData, TableCache
from thinfilm_mi.tabulate.mueller import MUELLER
from thinfilm_mi.tabulate.policy import MAX_TEXELS
from thinfilm_mi.tabulate.quantities import POWERS
from thinfilm_mi.tabulate.store import default_store

__all__ = ["STORE_MIN_POINTS", "TABLE_CACHE", "build_plan", "build_tables", "side_data",
           "side_table"]

#: Tables shared between stacks with identical optics (bounded: 64 MiB of texture data).
TABLE_CACHE = TableCache()
#: Builds of at least this many exact evaluations (~30 ms and more: the probes of
#: 10 films and more, every band-limited build) are kept in the table store
#: (:mod:`thinfilm_mi.tabulate.store`) for later processes; cheaper ones are rebuilt.
STORE_MIN_POINTS = 50_000


def build_plan(stack: FilmStack, options: StackOptions, gave_up=frozenset()) -> StackPlan:
    """The sides of ``stack`` planned with ``options`` and built (see the module);
    ``gave_up``: the sides whose table ``"auto"`` does not try again (a failed build
    may spend the whole budget where its rejection cannot be predicted)."""
    plan = plan_sides(stack, options)
    if colour_channels() is not None:
        # RGB and mono variants read integrated colour tables (thinfilm_mi.tabulate.integrated)
        sides = {inside: side.with_(colour=colour_table(stack, side, side_data))
                 for inside, side in plan.sides.items()}
        if dr.is_diff_v(mitsuba_module().Float):
            prepare_gradients(stack.media())
        return StackPlan(sides, plan.mirrored)
    # Polarized variants read tables of the Mueller components
    # (thinfilm_mi.tabulate.mueller) or evaluate the complex amplitudes
    # (thinfilm_mi.render.amplitudes; their film loop has no real-amplitude form)
    quantity = MUELLER if mitsuba_module().is_polarized else POWERS
    plan = build_tables(stack, options, plan, quantity, gave_up)
    if not dr.is_jit_v(mitsuba_module().Float):
        return plan
    channels = quantity.channels(False)
    sides = {inside: side.with_(loop=LoopFilms(side.films, side.n0, side.exit))
             if reads_buffers(plan, side, channels) else side
             for inside, side in plan.sides.items()}
    return StackPlan(sides, plan.mirrored, plan.failed)


def build_tables(stack: FilmStack, options: StackOptions, plan: StackPlan, quantity=POWERS,
                 gave_up=frozenset()) -> StackPlan:
    """``plan`` with the tables of ``quantity`` (what they hold:
    :data:`~thinfilm_mi.tabulate.quantities.QUANTITIES`) that it wants
    (:func:`~thinfilm_mi.render.stack_plan.wants_tables`); none where a thickness
    carries gradients (every film is read then:
    :func:`~thinfilm_mi.render.stack_eval.current_side`). Without the ambient side's
    table a mirrored plan is no longer mirrored: the side lit from the substrate is
    then planned, and tabulated, on its own."""
    option = options.tabulate
    if not wants_tables(stack, options, plan, quantity) or stack.differentiating():
        return plan
    sides, mirrored, failed = dict(plan.sides), plan.mirrored, []
    for inside, side in plan.sides.items():
        if inside and mirrored and sides[False].table is None:
            mirrored = False
            side = sides[inside] = side.with_(
                transmission=options.sides[True] and not side.lossless)
        if side.films and not (option.selective and (
                inside in gave_up or few_films(stack, options, side, mirrored, quantity))) \
                and StackPlan(sides, mirrored).mirror_table(side) is None:
            table, report = side_table(options, side, quantity)
            sides[inside] = side.with_(table=table, build_report=report)
            if table is None:
                failed.append(inside)
    if option.required and failed:
        why = "; ".join(sorted({str((sides[i].build_report or {}).get("result"))
                                for i in failed}))
        warnings.warn(f"{stack.plugin}: the stack {stack.describe()} cannot be tabulated "
                      f"within table_error={options.table_error:g} in {MAX_TEXELS} "
                      f"texels and {option.budget_scale:g}x the build budget of 'auto' "
                      f"({why}); it is evaluated exactly", stacklevel=4)
    return StackPlan(sides, mirrored, failed)


def side_table(options: StackOptions, side: SidePlan, quantity=POWERS):
    """``(table, report)``: the table of ``side`` (``None`` where none can be) and what
    its build did (a :class:`~thinfilm_mi.tabulate.base.BuildReport`, ``None`` for an
    index that varies over the surface), shared between stacks with identical optics.

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
                return None, None   # an index that varies over the surface: not tabulable
            values[id(ix)] = (texture_on_grid(ix.eta), texture_on_grid(ix.k))
        arrays += values[id(ix)]
    transmission = side.transmission and not side.opaque
    channels = quantity.channels(transmission)
    option = options.tabulate
    max_texels = quantity.auto_max_floats // channels if option.selective else MAX_TEXELS
    budget_scale = option.budget_scale
    key = table_key(arrays, side.films, (mi.variant(), side.transmission, side.exit_real, side.opaque,
                                         options.table_error, options.spectral_resolution,
                                         max_texels, budget_scale, quantity.name,
                                         quantity.linear_max_floats))
    found, table = TABLE_CACHE.get(key)
    if found:
        return table, BuildReport(result="from the cache")
    disk = default_store()
    if disk is not None:
        found, table, report = disk.get(key)
        if found:
            TABLE_CACHE.put(key, table)
            return table, BuildReport(result="from the table store", build=report)

    data = side_data(side, transmission, quantity=quantity)
    report = BuildReport()
    table = band.build_table(data, options.table_error, GRID, max_texels,
                             options.spectral_resolution, report=report,
                             budget_scale=budget_scale, linear_floats=quantity.linear_max_floats)
    TABLE_CACHE.put(key, table)
    work = report.get("points", 0) + (report.get("exact_attempt") or {}).get("points", 0)
    if disk is not None and work >= STORE_MIN_POINTS:
        disk.put(key, table, report)
    return table, report


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
