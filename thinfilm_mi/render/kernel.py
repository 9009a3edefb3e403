"""The stack a thin-film BSDF evaluates in its kernels (no plugin classes here):
:class:`KernelStack`, the composition of what a stack is
(:class:`~thinfilm_mi.render.film_stack.FilmStack`), its options and plan
(:mod:`thinfilm_mi.render.stack_plan`), the tables and buffers built for the plan
(:mod:`thinfilm_mi.render.stack_build`) and their evaluation at a hit
(:mod:`thinfilm_mi.render.stack_eval`), under the names the plugins and models call.
The names of those modules that the layers above read are here too.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render import stack_eval
from thinfilm_mi.render.film_stack import FilmStack, stack_facts
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.stack_build import build_plan
from thinfilm_mi.render.stack_plan import (
    DEFAULT_COHERENCE_THICKNESS,
    DEFAULT_SPECTRAL_RESOLUTION,
    DEFAULT_TABLE_ERROR,
    SidePlan,
    StackOptions,
    plan_sides,
)
from thinfilm_mi.render.tabulation import Route

__all__ = ["KernelStack", "StackSpec", "build_stack"]


class KernelStack:
    """Films between an ambient medium and a substrate, for evaluation in kernels.

    ``films`` is a list of ``(SpectralIndex, thickness_nm)``; thicknesses are
    stored as opaque ``mi.Float`` so a sweep never recompiles. ``ambient`` must
    be non-absorbing. ``sides`` maps ``inside`` (False: lit from the ambient,
    True: from the substrate) to whether ``T`` is needed there; it decides what
    is tabulated. Other combinations are still evaluated, exactly. The options
    (``tabulate``, ``table_error``, ``spectral_resolution``, ``coherence_thickness``,
    ``rt_min_films``) are :class:`~thinfilm_mi.render.stack_plan.StackOptions`'.

    The stack is read (:func:`~thinfilm_mi.render.film_stack.stack_facts`),
    planned from what it is (:func:`~thinfilm_mi.render.stack_plan.plan_sides`: what a
    scene does not need is skipped, the sides that pay for one read a table) and the
    plan built (:func:`~thinfilm_mi.render.stack_build.build_plan`), again after every
    edit (:meth:`parameters_changed`; ``auto`` then builds no table for a deep side);
    identical stacks share one table."""

    def __init__(self, films: Sequence[tuple[SpectralIndex, float]], ambient: SpectralIndex,
                 substrate: SpectralIndex, thickness_texture=None, *,
                 tabulate: bool | str = "auto", table_error: float = DEFAULT_TABLE_ERROR,
                 spectral_resolution: float = DEFAULT_SPECTRAL_RESOLUTION,
                 coherence_thickness: float = DEFAULT_COHERENCE_THICKNESS,
                 sides: dict | None = None, plugin: str = "thin-film BSDF",
                 rt_min_films: int | None = None):
        #: What the stack is: its films, media and thickness texture.
        self.films = FilmStack(films, ambient, substrate, thickness_texture, plugin)
        #: How it is planned.
        self.options = StackOptions(tabulate, table_error, spectral_resolution,
                                    coherence_thickness, sides, rt_min_films)
        if self.options.tabulate.required and thickness_texture is not None:
            raise ThinFilmError(f"{plugin}: 'tabulate' is true but a 'thickness' texture is "
                                "given: a table over (angle, wavelength) cannot follow a "
                                "thickness that varies over the surface (use 'auto' or false)")
        facts = stack_facts(self.films)
        plan = plan_sides(facts, self.options)
        #: The planned sides with their tables and buffers (a built StackPlan).
        self.planned = build_plan(plan)

    def __len__(self) -> int:
        return len(self.films)

    # -- what the stack is, as its users name it -------------------------------
    indices = property(lambda self: self.films.indices, doc="The films' indices, from the ambient.")
    thickness = property(lambda self: self.films.thickness, doc="The films' opaque thicknesses (nm).")
    ambient = property(lambda self: self.films.ambient, doc="The ambient medium.")
    substrate = property(lambda self: self.films.substrate, doc="The substrate medium.")
    thickness_texture = property(lambda self: self.films.thickness_texture,
                                 doc="The texture that scales every thickness, or ``None``.")
    plugin = property(lambda self: self.films.plugin, doc="The BSDF's name, for messages.")

    def describe(self) -> str:
        """The films as ``to_string`` shows them (:meth:`FilmStack.describe`)."""
        return self.films.describe()

    def traverse(self, callback) -> None:
        """The films' parameters, as ``mi.traverse`` shows them."""
        self.films.traverse(callback)

    def parameters_changed(self, keys=None) -> None:
        """Refresh after an edit (``keys``, the changed keys, are not needed:
        the plan is made again from the current values, as an edited stack's:
        :func:`~thinfilm_mi.render.stack_plan.cached_only`)."""
        self.films.parameters_changed()
        facts = stack_facts(self.films)
        plan = plan_sides(facts, self.options, self.planned.gave_up, edited=True)
        self.planned = build_plan(plan)

    def thickness_scale_at(self, si, active=True):
        """The thickness texture's value at the hit (>= 0), or ``None`` without one."""
        return self.films.thickness_scale_at(si, active)

    def index_gradients(self, si, active=True) -> bool:
        """Whether an index carries gradients at the hit (:meth:`FilmStack.index_gradients`)."""
        return self.films.index_gradients(si, active)

    def colour_gradients(self, si, active=True) -> bool:
        """Whether a thickness or an index carries gradients (RGB/mono AD variants)."""
        return self.films.colour_gradients(si, active)

    # -- its options and plan ------------------------------------------------------
    tabulate = property(lambda self: self.options.tabulate, doc="The ``tabulate`` option.")
    table_error = property(lambda self: self.options.table_error, doc="The tables' target.")
    spectral_resolution = property(lambda self: self.options.spectral_resolution,
                                   doc="The band-limited tables' resolution (nm).")
    coherence_thickness = property(lambda self: self.options.coherence_thickness,
                                   doc="Thicker films (nm) are averaged incoherently.")
    sides = property(lambda self: self.options.sides, doc="``{inside: needs T}``.")
    rt_min_films = property(lambda self: self.options.rt_min_films,
                            doc="``auto`` tabulates a side of R and T from this many films.")
    plan = property(lambda self: self.planned.sides, doc="``{inside: SidePlan}``, as built.")
    mirrored = property(lambda self: self.planned.mirrored,
                        doc="Whether both sides read the ambient side's table.")
    table_failed = property(lambda self: self.planned.failed,
                            doc="The sides whose table could not be built.")

    def mode(self) -> Route:
        """The :class:`~thinfilm_mi.render.tabulation.Route` of the planned sides."""
        return self.planned.route()

    def mirror_table(self, side: SidePlan):
        """The ambient side's table where it serves ``side`` (mirrored), or ``None``."""
        return self.planned.mirror_table(side)

    # -- its evaluation at a hit -------------------------------------------------------
    def current_plan(self, inside: bool, transmission: bool,
                     index_gradients: bool = False) -> SidePlan:
        """The side as evaluated now (:func:`~thinfilm_mi.render.stack_eval.current_side`)."""
        return stack_eval.current_side(self.films, self.planned, inside, transmission,
                                       index_gradients)

    def side_response(self, inside: bool, si, cos_theta, active, transmission: bool,
                      thickness_scale):
        """The side ``inside`` at the hit: its table, else its films exactly."""
        return stack_eval.response_now(self.films, self.planned, inside, si, cos_theta, active,
                                       transmission, thickness_scale)

    def at_wavelengths(self, inside: bool, si, cos_theta, active, transmission: bool,
                       thickness_scale, wl):
        """Exact ``R`` [, ``T``] at ``wl`` through every film (RGB/mono colour gradients)."""
        return stack_eval.at_wavelengths(self.films, inside, si, cos_theta, active,
                                         transmission, thickness_scale, wl)

    def colour(self, si, cos_theta, active=True, *, inside: bool | Any = False,
               transmission: bool = False):
        """RGB/mono variants: ``R`` [and ``T``] as colours (:func:`~thinfilm_mi.render.stack_eval.colour`)."""
        return stack_eval.colour(self.films, self.planned, si, cos_theta, active,
                                 inside=inside, transmission=transmission)

    def reflectance(self, si, cos_theta, active=True, *, inside: bool | Any = False,
                    transmission: bool = False, thickness_scale=None):
        """Unpolarized ``R`` [and ``T``] at ``si.wavelengths`` (:func:`~thinfilm_mi.render.stack_eval.reflectance`)."""
        return stack_eval.reflectance(self.films, self.planned, si, cos_theta, active,
                                      inside=inside, transmission=transmission,
                                      thickness_scale=thickness_scale)


@dataclass(frozen=True, eq=False)
class StackSpec:
    """A thin-film BSDF's stack as its properties give it, parsed and checked, nothing
    built (:meth:`~thinfilm_mi.render.reader.PluginProperties.stack_spec`): ``films``
    (``(SpectralIndex, thickness_nm)`` from the ambient), ``ambient``, ``substrate`` and
    ``options`` (:class:`KernelStack`'s keyword options). A plugin reads all its
    properties, refuses the ones no one read, and only then builds the stack
    (:func:`build_stack`), whose tables may take seconds."""

    films: list
    ambient: SpectralIndex
    substrate: SpectralIndex
    options: dict


def build_stack(spec: StackSpec, *, sides: dict | None = None,
                plugin: str = "thin-film BSDF") -> KernelStack:
    """The :class:`KernelStack` of ``spec``: ``sides`` (``{inside: needs_T}``) says what the
    BSDF evaluates, hence what is tabulated; ``plugin`` names the BSDF in what the stack
    reports later (a warning, an edit)."""
    return KernelStack(spec.films, spec.ambient, spec.substrate, sides=sides, plugin=plugin,
                       **spec.options)
