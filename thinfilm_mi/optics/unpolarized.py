"""Unpolarized powers of a stack, on any Dr.Jit array type: what every render kernel,
table build and hemispherical integral evaluates.

* :func:`unpolarized_rt`: ``R = (Rs + Rp)/2`` and ``T`` (the power entering the exit
  medium) from :func:`thinfilm_mi.optics.core.stack_amplitudes`, the films unrolled;
* :func:`unpolarized_rt_loop`: the same with the films visited by a loop
  (:func:`thinfilm_mi.optics.core.stack_rt_loop`), for stacks of
  :data:`LOOP_MIN_FILMS` films or more;
* :func:`unpolarized_powers`: ``R`` and ``T`` from amplitudes already computed.
"""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.optics.core import (
    clip_transmittance,
    stack_amplitudes,
    stack_rt_loop,
    transmittance_factor_p,
    transmittance_factor_s,
)

__all__ = ["LOOP_MIN_FILMS", "unpolarized_rt", "unpolarized_powers", "unpolarized_rt_loop"]

#: Exact evaluation of a side with at least this many films runs the recursion as a
#: symbolic Dr.Jit loop over buffers of the films (the render kernel's film loop,
#: :func:`unpolarized_rt_loop` in table builds): one loop body whatever the depth, so the
#: kernel compiles as fast for deep stacks as for thin ones and each hit is cheaper; below
#: it the films are unrolled, which lets literal indices specialise the code.
LOOP_MIN_FILMS = 4


def unpolarized_rt(n0, cos0, films, n_exit, wl, transmission: bool = True):
    """Unpolarized ``R`` (and ``T``, the power entering ``n_exit``), any array type.

    ``R = (Rs + Rp) / 2`` clamped to 1; ``T`` clipped to ``[0, 1 - R]``; at grazing
    incidence ``T = 0``. Shared by the kernels and the float64 hemispherical terms.
    """
    a = stack_amplitudes(n0, cos0, films, n_exit, wl, transmission=transmission)
    return unpolarized_powers(a, transmission)


def unpolarized_powers(a, transmission: bool = True):
    """:func:`unpolarized_rt` from the amplitudes ``a`` (:class:`optics.StackAmplitudes`)."""
    R = dr.minimum(0.5 * (a.rs.abs2() + a.rp.abs2()), 1.0)
    if not transmission:
        return R
    q0 = dr.select(a.grazing, 1.0, a.q0)
    T = 0.5 * (a.ts.abs2() * transmittance_factor_s(a.q_exit, q0)
               + a.tp.abs2() * transmittance_factor_p(a.n_exit, a.q_exit, q0))
    T = dr.select(a.grazing, 0.0, clip_transmittance(T, R))
    return R, T


def unpolarized_rt_loop(n0, cos0, count, film, n_exit, wl, transmission: bool = True, **hints):
    """:func:`unpolarized_rt` with the films visited by a loop
    (:func:`optics.stack_rt_loop`, whose arguments and trace-time ``hints`` these
    are): the render kernels' deep stacks and the table builds' (float64)."""
    Rs, Rp, Ts, Tp = stack_rt_loop(n0, cos0, count, film, n_exit, wl,
                                   transmission=transmission, **hints)
    R = 0.5 * (Rs + Rp)
    if not transmission:
        return R
    return R, clip_transmittance(0.5 * (Ts + Tp), R)
