"""How a stack's plan is built (no plugin classes here): :func:`build_plan` builds
what a :class:`~thinfilm_mi.render.stack_plan.StackPlan` asks for
(:func:`~thinfilm_mi.render.stack_plan.plan_sides` decided it) and returns the plan
with it, without planning anything again: in RGB/mono variants the sides' colour
tables (:func:`~thinfilm_mi.render.colour_variants.colour_table`); elsewhere the
verified tables the plan asks for (:func:`build_tables`: of the powers,
:mod:`thinfilm_mi.tabulate.exact`, or of the Mueller components,
:mod:`thinfilm_mi.tabulate.mueller`), shared between stacks with identical optics
(:data:`TABLE_CACHE`, then the table store on disk), and the films' buffers
(:class:`~thinfilm_mi.render.loop.LoopFilms`) of the sides no table serves.
"""
from __future__ import annotations

import warnings
from dataclasses import replace

import drjit as dr
import numpy as np

from thinfilm_mi.render.colour_variants import colour_channels, colour_table, prepare_gradients
from thinfilm_mi.render.film_stack import StackFacts
from thinfilm_mi.render.loop import LoopFilms
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.stack_plan import SidePlan, StackOptions, StackPlan
from thinfilm_mi.render.tabulation import table_key
from thinfilm_mi.render.textures import GRID, mitsuba_module, scalar
from thinfilm_mi.tabulate import band
from thinfilm_mi.tabulate.base import BuildReport, SideData, TableCache
from thinfilm_mi.tabulate.policy import MAX_TEXELS
from thinfilm_mi.tabulate.quantities import POWERS
from thinfilm_mi.tabulate.store import default_store

__all__ = ["NOT_REBUILT", "STORE_MIN_POINTS", "TABLE_CACHE", "build_plan", "build_tables",
           "side_data", "side_table"]

#: Tables shared between stacks with identical optics (bounded: 64 MiB of texture data).
TABLE_CACHE = TableCache()
#: Builds of at least this many exact evaluations (~30 ms and more: the probes of
#: 10 films and more, every band-limited build) are kept in the table store
#: (:mod:`thinfilm_mi.tabulate.store`) for later processes; cheaper ones are rebuilt.
STORE_MIN_POINTS = 50_000
#: The report's ``result`` for a side an edit left without a table
#: (:func:`~thinfilm_mi.render.stack_plan.cached_only`): evaluated exactly.
NOT_REBUILT = "not rebuilt after an edit (exact)"


def build_plan(plan: StackPlan) -> StackPlan:
    """What ``plan`` asks for, built (see the module): a new plan, ``plan`` is left as
    it was given."""
    if colour_channels() is None:
        built = build_tables(plan)
        # A side's table holds T wherever the side asks for it: it serves every call
        # the side is planned for, and so does the ambient side's where it is mirrored
        mirror = built.mirrored and built.sides[False].table is not None
        sides = dict(built.sides)
        for inside, side in built.sides.items():
            if side.buffered and side.table is None and not (inside and mirror):
                sides[inside] = replace(side, loop=LoopFilms(side.films, side.n0, side.exit))
        return replace(built, sides=sides)
    # RGB and mono variants read integrated colour tables (thinfilm_mi.tabulate.integrated)
    facts = plan.facts
    sides = {inside: replace(side, colour=colour_table(facts, side, side_data))
             for inside, side in plan.sides.items()}
    if dr.is_diff_v(mitsuba_module().Float):
        prepare_gradients(facts.stack.media())
    return replace(plan, sides=sides)


def build_tables(plan: StackPlan) -> StackPlan:
    """``plan`` with the tables its sides ask for (``tabulate``; of ``plan.quantity``).
    Without the ambient side's table a mirrored plan is no longer mirrored: the side
    lit from the substrate is then tabulated on its own, as the plan decided for that
    case. A new plan; ``failed`` and ``gave_up`` say which tables could not be built."""
    if not plan.tables:
        return plan
    options, stack = plan.options, plan.facts.stack
    sides, mirrored, failed = dict(plan.sides), plan.mirrored, []
    for inside, side in plan.sides.items():
        if inside and mirrored:
            if sides[False].table is not None:
                continue   # read through the ambient side's table
            mirrored = False
        if side.tabulate:
            table, report = side_table(plan.facts, options, side, plan.quantity)
            sides[inside] = replace(side, table=table, build_report=report)
            if table is None and not side.cached_only:
                failed.append(inside)
    option = options.tabulate
    if option.required and failed:
        why = "; ".join(sorted({str((sides[i].build_report or {}).get("result"))
                                for i in failed}))
        # a side that was tabulated keeps its table (the plan is then mixed)
        what, rest = (f"the stack {stack.describe()}", "it is") if len(failed) == len(sides) else (
            f"the side of the stack {stack.describe()} lit from the "
            f"{'substrate' if failed[0] else 'ambient'}", "that side is")
        warnings.warn(f"{stack.plugin}: {what} cannot be tabulated "
                      f"within table_error={options.table_error:g} in {MAX_TEXELS} "
                      f"texels and {option.budget_scale:g}x the build budget of 'auto' "
                      f"({why}); {rest} evaluated exactly", stacklevel=4)
    return replace(plan, sides=sides, mirrored=mirrored, failed=failed,
                   gave_up=plan.gave_up | set(failed))


def side_table(facts: StackFacts, options: StackOptions, side: SidePlan, quantity=POWERS):
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
    later processes. A ``cached_only`` side found in neither gets no table (report
    :data:`NOT_REBUILT`) and is evaluated exactly.
    """
    mi = mitsuba_module()
    arrays = []
    for ix in [side.n0] + [f[0] for f in side.films] + [side.exit]:
        n = facts.grid[id(ix)]
        if n is None:
            return None, None   # an index that varies over the surface: not tabulable
        arrays += [n.real, n.imag]
    transmission = side.transmission and not side.opaque
    data = side_data(side, transmission, quantity=quantity)
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

    if side.cached_only:
        return None, BuildReport(result=NOT_REBUILT, points=0)
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
