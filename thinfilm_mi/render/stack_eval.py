"""How a planned stack is evaluated at a hit (no plugin classes here): which side
of a :class:`~thinfilm_mi.render.film_stack.FilmStack` the light meets, planned as a
:class:`~thinfilm_mi.render.stack_plan.StackPlan`, and what it returns there, in the
spectral variants (:func:`reflectance`: unpolarized ``R`` [and ``T``] at the path's
wavelengths) and the RGB/mono ones (:func:`colour`: colours from the colour tables,
with gradients from an unbiased estimate where a parameter carries them). One side
is evaluated by :mod:`thinfilm_mi.render.side_eval`; both sides of a lossless stack
from one (mirrored), or each under a branch, by :mod:`thinfilm_mi.render.mirror`; the
polarized variants' response is :mod:`thinfilm_mi.render.amplitudes`'.
"""
from __future__ import annotations

from typing import Any

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render import mirror
from thinfilm_mi.render.colour_variants import GradientSampler, attach_gradient
from thinfilm_mi.render.film_stack import FilmStack
from thinfilm_mi.render.side_eval import side_at_wavelengths, side_response
from thinfilm_mi.render.stack_plan import SidePlan, StackPlan, full_plan
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["at_wavelengths", "colour", "current_side", "reflectance", "response_now"]


def current_side(stack: FilmStack, plan: StackPlan, inside: bool, transmission: bool,
                 index_gradients: bool = False) -> SidePlan:
    """The plan of the side lit from the ambient (``inside`` false) or the
    substrate, as evaluated now: every film, without skips or table, when a
    thickness (or, with ``index_gradients``, an index) carries gradients or the
    side was not planned (a table and the film loop's buffers hold numbers, not
    derivatives)."""
    side = plan.sides.get(inside)
    if side is None or stack.differentiating() or index_gradients:
        side = full_plan(stack, inside, transmission)
    return side


def response_now(stack: FilmStack, plan: StackPlan, inside: bool, si, cos_theta, active,
                 transmission: bool, thickness_scale):
    """The side ``inside`` as evaluated now (:func:`current_side`) at the hit."""
    side = current_side(stack, plan, inside, transmission, stack.index_gradients(si, active))
    return side_response(side, si, cos_theta, active, transmission, thickness_scale)


def at_wavelengths(stack: FilmStack, inside: bool, si, cos_theta, active, transmission: bool,
                   thickness_scale, wl):
    """Exact ``R`` [, ``T``] at the wavelengths ``wl`` (``mi.Spectrum``) in an
    RGB/mono variant, through every film (the colour gradients)."""
    return side_at_wavelengths(full_plan(stack, inside, transmission), si, cos_theta, active,
                               transmission, thickness_scale, wl)


def reflectance(stack: FilmStack, plan: StackPlan, si, cos_theta, active=True, *,
                inside: bool | Any = False, transmission: bool = False, thickness_scale=None):
    """Unpolarized ``R`` (and ``T`` if asked) as ``mi.Spectrum`` at ``si.wavelengths``.

    ``cos_theta`` is the (positive) cosine of incidence measured on the side the
    light comes from. ``inside`` (a Python bool or a mask) selects the reversed
    stack lit from the substrate; the substrate must then be a non-absorbing
    medium. Where ``inside`` is a mask both directions are evaluated, each under a
    branch or selected (:func:`~thinfilm_mi.render.mirror.either_side`), unless the
    plan is mirrored (:func:`~thinfilm_mi.render.mirror.mirrored_rt`).
    """
    if thickness_scale is None:
        thickness_scale = stack.thickness_scale_at(si, active)
    if (plan.mirrored and thickness_scale is None and current_side(
            stack, plan, False, False, stack.index_gradients(si, active)) is plan.sides[False]):
        out = mirror.mirrored_rt(plan.sides[False], si, cos_theta, inside, active, transmission)
        if out is not None:
            return out

    def side(flag: bool):
        return response_now(stack, plan, flag, si, cos_theta, active, transmission,
                            thickness_scale)

    return mirror.either_side(side, inside, transmission, _branches(stack, plan))


def colour(stack: FilmStack, plan: StackPlan, si, cos_theta, active=True, *,
           inside: bool | Any = False, transmission: bool = False):
    """RGB/mono variants: ``R`` (and ``T`` if asked) as ``mi.Spectrum`` colours,
    the spectral values integrated against colour matching
    (:mod:`thinfilm_mi.tabulate.integrated`), read from the side's colour table; a side
    with no films over an index given per channel is evaluated per channel
    (Fresnel), as Mitsuba's ``conductor`` does. Where a thickness or an index
    carries gradients, they come from an unbiased estimate of the integral
    (:class:`~thinfilm_mi.render.colour_variants.GradientSampler`); the value stays the
    table's. Arguments as :func:`reflectance`."""
    scale = stack.thickness_scale_at(si, active)

    def side(flag: bool):
        planned = plan.sides.get(flag)
        if planned is None:
            raise ThinFilmError(f"{stack.plugin}: internal error: the side lit from the "
                                f"{'substrate' if flag else 'ambient'} was not planned")
        if planned.colour is None:
            return response_now(stack, plan, flag, si, cos_theta, active, transmission, None)
        R, T = planned.colour.lookup(cos_theta, scale, active)
        if transmission and T is None:
            T = mitsuba_module().Spectrum(0.0)
        if stack.colour_gradients(si, active):
            sampler = GradientSampler.get()
            wl = sampler.wavelengths(si)
            exact = at_wavelengths(stack, flag, si, cos_theta, active, transmission, scale, wl)
            if transmission:
                R = attach_gradient(R, sampler.estimate(wl, exact[0]))
                T = attach_gradient(T, sampler.estimate(wl, exact[1]))
            else:
                R = attach_gradient(R, sampler.estimate(wl, exact))
        return (R, T) if transmission else R

    return mirror.either_side(side, inside, transmission, _branches(stack, plan))


def _branches(stack: FilmStack, plan: StackPlan) -> bool:
    return mirror.branches(len(stack) > 0, plan.sides.values())
