"""Both sides of a lossless stack from one table of ``R``.

A stack between real media whose films do not absorb conserves energy
(``R + T = 1`` from either side) and its ``T`` is reciprocal (the same for light
crossing it either way along one path). So ``R`` seen from the substrate at
``θ_s`` is ``R`` seen from the ambient at ``θ_a`` with ``n_a sin θ_a = n_s sin θ_s``
(Snell's law through the films; beyond the critical angle ``R = 1``), and
``T = 1 - R`` on both sides. :mod:`~thinfilm_mi.render.stack_plan` plans
such a stack (:func:`~thinfilm_mi.render.stack_plan.mirror_applies`: a
``thinfilm_dielectric`` or ``thinfilm_roughdielectric`` lit from both sides,
spectral variants, the substrate's index at least the ambient's) with
one table of ``R`` lit from the ambient (one channel instead of two, one side
instead of two), and :func:`mirrored_rt` reads it for every lane: one cubic lookup
per wavelength where two sides of ``R`` and ``T`` took four, with no per-side
branch. Evaluated exactly, such a stack runs the ambient side's recursion (``R``
only) for every lane at the mapped angle, where both sides' were run. The table's
verified error bound holds over its whole angle axis, so the mapped lookups and
``1 - R`` stay within ``table_error``.

Other stacks lit from either side per lane (:func:`either_side`) evaluate each side
under a symbolic conditional: a SIMD packet whose lanes all arrive on one side runs
that side's lookups or recursion only (Dr.Jit skips a branch no lane of a packet
takes), where both were computed for every lane and selected.
"""
from __future__ import annotations

from typing import Any

import drjit as dr

from thinfilm_mi.render.side_eval import side_response
from thinfilm_mi.render.stack_plan import exact_mirrors
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["branches", "either_side", "literal_outside", "mirrored_rt"]


def mirrored_rt(side, si, cos_theta, inside: bool | Any, active, transmission: bool):
    """``R`` (and ``T = 1 - R``) at ``si.wavelengths`` for light at ``cos_theta`` on the
    side ``inside`` (a bool or a mask) of a stack planned as mirrored (see the module
    docstring), from ``side``, its planned ambient side
    (:class:`~thinfilm_mi.render.stack_plan.SidePlan`): one lookup per wavelength of its
    table, or without a table one exact evaluation of it (when neither medium is
    dispersive: one mapped angle per lane). ``None`` where neither applies."""
    mi = mitsuba_module()
    wl = si.wavelengths
    constant = exact_mirrors(side.n0, side.exit)
    if side.table is None and not constant:
        return None
    if inside is False:
        cos_a = sin_a = tir = None
    else:
        cos = dr.clip(cos_theta, 0.0, 1.0)
        sin = dr.safe_sqrt((1.0 - cos) * (1.0 + cos))
        n_a = side.n0.eval_real(si, active)
        n_s = side.exit.eval_real(si, active)
        cos_a, sin_a, tir = [], [], []
        for i in range(1 if side.table is None else len(wl)):
            beta = n_s[i] * sin                        # n_a sin θ_a
            d2 = (n_a[i] - beta) * (n_a[i] + beta)     # (n_a cos θ_a)^2
            inv = dr.rcp(n_a[i])
            c, s = dr.sqrt(dr.maximum(d2, 0.0)) * inv, dr.minimum(beta * inv, 1.0)
            if inside is True:
                cos_a.append(c), sin_a.append(s), tir.append(d2 <= 0)
            else:
                cos_a.append(dr.select(inside, c, cos))
                sin_a.append(dr.select(inside, s, sin))
                tir.append(inside & (d2 <= 0))
    if side.table is not None:
        R = side.table.lookup(cos_theta if cos_a is None else cos_a, None, None, wl, active,
                              sin_i=sin_a)[0]
        if tir is not None:
            R = dr.select(dr.mask_t(mi.UnpolarizedSpectrum)(*tir), 1.0, R)
    else:
        R = mi.UnpolarizedSpectrum(side_response(side, si, cos_theta if cos_a is None
                                                 else cos_a[0], active, False, None))
        if tir is not None:
            R = dr.select(tir[0], 1.0, R)
    return (R, 1.0 - R) if transmission else R


def branches(has_films: bool, sides) -> bool:
    """Whether :func:`either_side` branches for a stack (``has_films``: whether it has
    films, of any thickness; ``sides``: its planned sides,
    :class:`~thinfilm_mi.render.stack_plan.SidePlan`): not for a bare interface (its
    Fresnel terms cost less than the branch), nor where a side is optically opaque or
    averages a film incoherently. (Two opaque sides both return the literal ``T = 0``,
    which Dr.Jit 1.5.0 hands back as one branch's own variable, a kernel LLVM refuses
    (tests/cross/test_stability_bsdf.py): :func:`literal_outside` mends any such output.)"""
    return has_films and not any(s.opaque or any(s.incoherent) for s in sides)


def either_side(side, inside, transmission: bool, branch: bool = True):
    """``side(inside)`` for a Python bool; for a mask, ``side(True)`` where it is set
    and ``side(False)`` elsewhere: with ``branch`` each under a symbolic conditional
    (see the module docstring), else both computed and selected (:func:`branches`);
    ``transmission``: whether ``side`` returns ``(R, T)``."""
    if isinstance(inside, bool):
        return side(inside)
    if not branch:
        outside = _pair(side(False), transmission)
        out = tuple(dr.select(inside, a, b) for a, b in zip(_pair(side(True), transmission),
                                                            outside))
        return out if transmission else out[0]
    out = dr.if_stmt(args=(), cond=inside, true_fn=lambda: _pair(side(True), transmission),
                     false_fn=lambda: _pair(side(False), transmission))
    out = tuple(literal_outside(x) for x in out)
    return out if transmission else out[0]


def literal_outside(x):
    """``x`` (an output of ``dr.if_stmt``) with each literal component made again
    outside the conditional. Where both branches return the same literal, Dr.Jit 1.5.0
    (drjit-core ``jitc_var_cond_end``) returns the false branch's own variable, which
    the LLVM backend defines inside that branch's block: a use after the conditional
    then fails LLVM's verification ("Instruction does not dominate all uses!") and the
    process aborts. A literal's value is known without evaluating anything."""
    if dr.depth_v(x) > 1:
        return type(x)(*[literal_outside(c) for c in x])
    if x.state == dr.VarState.Literal and not dr.grad_enabled(x):
        return dr.full(type(x), x[0], dr.width(x))
    return x


def _pair(res, transmission: bool):
    """``res`` as a tuple of ``mi.UnpolarizedSpectrum`` (both branches' types must agree)."""
    U = mitsuba_module().UnpolarizedSpectrum
    return tuple(U(x) for x in (res if transmission else (res,)))
