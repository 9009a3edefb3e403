"""Polarized response of a :class:`~thinfilm_mi.render.kernel.KernelStack` at a hit.

Polarized variants need the stack's Mueller matrices, not only its powers. A side
planned with a table (:mod:`thinfilm_mi.tabulate.mueller`: ``tabulate`` true, or
``"auto"`` from :data:`~thinfilm_mi.tabulate.policy.MUELLER_AUTO_MIN_FILMS` films) reads its
Mueller components from it (:func:`table_response`); otherwise it is evaluated
exactly from the complex amplitudes ``r_s, r_p, t_s, t_p`` at ``si.wavelengths``
(:func:`optics.stack_amplitudes`, films unrolled, their indices gathered from the
films' buffers of :class:`~thinfilm_mi.render.loop.LoopFilms`; from
:data:`~thinfilm_mi.optics.unpolarized.LOOP_MIN_FILMS` films a loop over those buffers,
:func:`optics.mueller.loop_amplitudes`, so that the kernel does not grow
with the depth), after the same skips as the unpolarized path (films of zero
thickness dropped, nothing below an optically opaque film).

The result is what a Mueller matrix needs, in Mitsuba's convention (see the
docstring of :mod:`thinfilm_mi.optics.core`: Mitsuba's amplitudes are the complex
conjugates of ours):

* ``R`` and ``T``: the unpolarized reflectance and transmittance, formed exactly
  as :func:`unpolarized.unpolarized_rt` forms them (the Mueller matrices' ``M00``;
  the plugins use them for weights and lobe probabilities);
* a :class:`Shape` per lobe: the Mueller matrix in the s/p frame divided by its
  ``M00``, so that ``M = R * shape`` (:mod:`thinfilm_mi.render.modes` rotates it).

Films thicker than ``coherence_thickness`` are averaged incoherently by the tables
(:mod:`thinfilm_mi.optics.incoherent_mueller`: the parts' Mueller matrices add as
intensities do). The exact path (no table: ``tabulate`` false, fewer films, a
``thickness`` texture, gradients) evaluates them coherently (an incoherent average
has no amplitude): there polarized renders of such stacks show their fine fringes
where the unpolarized ones average them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import drjit as dr

from thinfilm_mi.optics.core import Cx, stack_amplitudes, transmittance_factor_p, transmittance_factor_s
from thinfilm_mi.optics.mueller import loop_amplitudes
from thinfilm_mi.optics.unpolarized import unpolarized_powers
from thinfilm_mi.render.kernel import KernelStack
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["Polarized", "Shape", "depolarizing_shape", "jones_shape", "physical",
           "polarized_response", "table_response", "table_shape"]


@dataclass
class Shape:
    """A Mueller matrix in the s/p frame over its ``M00``::

        [[1, b, 0,     0    ],
         [b, d, 0,     0    ],
         [0, 0, c_re, -c_im ],
         [0, 0, c_im,  c_re ]]

    For a Jones pair ``(A_s, A_p)`` in Mitsuba's convention ``d = 1``,
    ``b = (|A_s|^2 - |A_p|^2) / (|A_s|^2 + |A_p|^2)`` and ``c = 2 A_p conj(A_s)
    / (|A_s|^2 + |A_p|^2)`` (``mueller.specular_reflection``'s ``c cos δ``,
    ``c sin δ``). The depolarizer is ``b = d = c = 0``.
    """

    b: Any
    d: Any
    c_re: Any
    c_im: Any

    def select(self, mask, other: "Shape") -> "Shape":
        """Per lane ``self`` where ``mask``, else ``other``."""
        return Shape(*(dr.select(mask, x, y) for x, y in
                       zip((self.b, self.d, self.c_re, self.c_im),
                           (other.b, other.d, other.c_re, other.c_im))))


def depolarizing_shape() -> Shape:
    """The shape of Mitsuba's ``depolarizer``: only ``M00``."""
    return Shape(0.0, 0.0, 0.0, 0.0)


def jones_shape(a_s: Cx, a_p: Cx, w_s=1.0, w_p=1.0) -> Shape:
    """The :class:`Shape` of the Jones pair ``(a_s, a_p)`` in *our* (tmm's) convention,
    with power weights ``w_s``, ``w_p`` (the transmittance factors; 1 for reflection).

    In Mitsuba's convention the amplitudes are ``conj(a)``, so
    ``A_p conj(A_s) = conj(a_p) a_s``.
    """
    P_s, P_p = a_s.abs2() * w_s, a_p.abs2() * w_p
    c = a_p.conj() * a_s
    if not (isinstance(w_s, float) and isinstance(w_p, float)):
        c = c * dr.sqrt(dr.maximum(w_s * w_p, 0.0))
    total = P_s + P_p
    inv = dr.select(total > 0, dr.rcp(dr.select(total > 0, total, 1.0)), 0.0)
    two_inv = 2.0 * inv
    return Shape((P_s - P_p) * inv, 1.0, c.re * two_inv, c.im * two_inv)


@dataclass
class Polarized:
    """The polarized response of one stack at a hit (see the module docstring)."""

    R: Any
    T: Any | None
    reflection: Shape
    transmission: Shape | None

    def select(self, mask, other: "Polarized") -> "Polarized":
        T = None if self.T is None else dr.select(mask, self.T, other.T)
        t = None if self.transmission is None else self.transmission.select(mask, other.transmission)
        return Polarized(dr.select(mask, self.R, other.R), T,
                         self.reflection.select(mask, other.reflection), t)


def physical(P, B, c_re, c_im, limit):
    """Tabulated Mueller components ``(P, B, C)`` (a lobe's power and the ``B``, ``C`` of
    :mod:`thinfilm_mi.optics.mueller`) made physical.

    Every average of Jones-Mueller matrices of this form has ``P >= sqrt(B² +
    |C|²)``: its components lie in a second-order (Lorentz) cone, the condition
    under which no Stokes vector gains polarization. A cubic lookup may overshoot
    between nodes, so the point is projected onto the cone (closed form: unchanged
    inside, 0 in the polar cone, else ``((P + |x|)/2) (1, x/|x|)`` with ``x = (B, C)``).
    The exact components lie in the cone and a projection onto a convex set is
    non-expansive, so the result is at least as close to them as the lookup (in the
    Euclidean norm of the four components: within twice the largest channel's
    error). Then the whole point is scaled so that ``P <= limit`` (``1``, or ``1 - R``
    for transmission), as the powers' tables clamp ``R`` and ``T``."""
    n = dr.sqrt(B * B + c_re * c_re + c_im * c_im)
    outside = n > P
    t = dr.select(outside, dr.maximum(0.5 * (P + n), 0.0), P)
    k = dr.select(outside, t * dr.rcp(dr.select(n > 0, n, 1.0)), 1.0)
    over = dr.select(t > limit, dr.maximum(limit, 0.0) * dr.rcp(dr.select(t > 0, t, 1.0)), 1.0)
    k = k * over
    return t * over, B * k, c_re * k, c_im * k


def table_shape(P, B, c_re, c_im) -> Shape:
    """The :class:`Shape` of physical components (:func:`physical`); ``P = 0`` gives
    the depolarizer's shape."""
    inv = dr.select(P > 0, dr.rcp(dr.select(P > 0, P, 1.0)), 0.0)
    return Shape(B * inv, 1.0, c_re * inv, c_im * inv)


def table_response(side, si, cos_theta, active, transmission: bool) -> Polarized:
    """The :class:`Polarized` response of a planned ``side`` from its Mueller table
    (channels of :mod:`thinfilm_mi.optics.mueller`), each lobe made physical
    (:func:`physical`)."""
    mi = mitsuba_module()
    table = side.table
    n0 = side.n0.eval_real(si, active)
    n_exit = side.exit.eval_real(si, active) if table.axis.needs_n_exit else None
    ch = table.lookup_channels(cos_theta, n0, n_exit, si.wavelengths, active)
    if table.channels == 8:
        R, *refl = physical(ch[0], *ch[2:5], 1.0)
        T, *trans = physical(ch[1], *ch[5:8], 1.0 - R)
    else:
        R, *refl = physical(ch[0], *ch[1:4], 1.0)
    r_shape = table_shape(R, *refl)
    if not transmission:
        return Polarized(R, None, r_shape, None)
    if side.opaque:
        return Polarized(R, mi.UnpolarizedSpectrum(0.0), r_shape, depolarizing_shape())
    return Polarized(R, T, r_shape, table_shape(T, *trans))


def _unrolled_amplitudes(n0, cos_theta, films, exit_, wl, transmission: bool):
    return stack_amplitudes(n0, cos_theta, films, exit_, wl, transmission=transmission)


def _side(stack: KernelStack, inside: bool, si, cos_theta, active, transmission: bool,
          thickness_scale) -> Polarized:
    mi = mitsuba_module()
    side = stack.current_plan(inside, transmission, stack.index_gradients(si, active))
    if side.table is not None and thickness_scale is None and (
            not transmission or side.opaque or side.table.channels == 8):
        return table_response(side, si, cos_theta, active, transmission)
    n0 = side.n0.eval_real(si, active)
    exit_ = Cx(side.exit.eval_real(si, active), 0.0) if side.exit_real \
        else side.exit.eval(si, active)
    want_t = transmission and not side.opaque
    if side.loop is not None:   # the films' buffers: unrolled, or a loop for deep stacks
        a = side.loop.rt(n0, cos_theta, exit_, si.wavelengths, want_t, thickness_scale,
                         evaluator=loop_amplitudes, unrolled=_unrolled_amplitudes)
    else:
        films = [(ix.eval(si, active), d if thickness_scale is None else d * thickness_scale)
                 for ix, d, _ in side.films]
        a = stack_amplitudes(n0, cos_theta, films, exit_, si.wavelengths, transmission=want_t)
    r_shape = jones_shape(a.rs, a.rp)
    if not transmission:
        return Polarized(unpolarized_powers(a, False), None, r_shape, None)
    if side.opaque:
        zero = mi.UnpolarizedSpectrum(0.0)
        return Polarized(unpolarized_powers(a, False), zero, r_shape, depolarizing_shape())
    R, T = unpolarized_powers(a, True)
    q0 = dr.select(a.grazing, 1.0, a.q0)
    t_shape = jones_shape(a.ts, a.tp, transmittance_factor_s(a.q_exit, q0),
                          transmittance_factor_p(a.n_exit, a.q_exit, q0))
    return Polarized(R, T, r_shape, t_shape)


def polarized_response(stack: KernelStack, si, cos_theta, active=True, *,
                       inside: bool | Any = False, transmission: bool = False) -> Polarized:
    """The exact :class:`Polarized` response of ``stack`` for light arriving at
    ``cos_theta`` (positive, measured on its own side) from the ambient
    (``inside`` false), the substrate (true), or per lane (a mask: both sides are
    evaluated and selected), as :meth:`KernelStack.reflectance` takes them."""
    scale = stack.thickness_scale_at(si, active)
    if isinstance(inside, bool):
        return _side(stack, inside, si, cos_theta, active, transmission, scale)
    out = _side(stack, False, si, cos_theta, active, transmission, scale)
    return _side(stack, True, si, cos_theta, active, transmission, scale).select(inside, out)

