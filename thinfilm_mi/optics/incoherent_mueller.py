"""Thick (incoherent) films in polarized variants: the Mueller components of a stack
whose films marked incoherent add intensities (the channels of
:mod:`thinfilm_mi.optics.mueller`).

The unpolarised average (:mod:`thinfilm_mi.optics.incoherent`) combines, for s and
p separately, the powers of the coherent sub-stacks between incoherent media by a
geometric series over the round trips inside each incoherent film. A Mueller
matrix of a planar stack is, in the components ``(s, p, c)`` = ``(|a_s|²,
|a_p|², a_s conj(a_p))``, a triple that multiplies component by component along a
light path and adds component by component over paths (see
:mod:`thinfilm_mi.optics.mueller`). The round trips of different orders in a thick
film differ in phase by multiples of ``2 delta`` (the same ``delta = 2 pi q d /
lambda`` for s and p), which the incoherent average removes, so the matrix of
the whole stack is the sum over orders of the products of the parts' matrices:
the unpolarised recursion, run for ``s`` and ``p`` as before and for ``c`` in
complex arithmetic::

    c_Re <- c_Rf + c_Tf c_Tb P² c_Re / (1 - c_Rb P² c_Re)
    c_Te <- c_Tf P c_Te / (1 - c_Rb P² c_Re)

(``P``: the film's single-pass power transmission, real: ``exp(i delta)
conj(exp(i delta))``). ``c_R = r_s conj(r_p)`` of a sub-stack and ``c_T =
τ̃_s conj(τ̃_p)`` with ``τ̃ = τ sqrt(Re a_out / Re a_in)`` (the amplitude whose
square is the sub-stack's power transmittance, tmm's normalisation). As
``|c| <= sqrt(s p)`` for every part, ``|c_Rb P² c_Re| < 1`` wherever the s and p
series converge, and the result keeps ``|C|² <= R² - B²`` (a physical matrix).

The sub-stacks' ``τ`` are the ratios of the magnetic field for p (the recursion
leaves out the telescoped ``n_in / n_out`` of the electric field), which telescope
through the stack; the final ``c_T`` is turned to the electric-field amplitudes of
:mod:`thinfilm_mi.optics.mueller` by the phase of ``conj(n0 / n_exit)`` (1 for a
real exit medium). With no film marked incoherent this is
:func:`~thinfilm_mi.optics.mueller.mueller_rt` itself. Conventions (absorbing
incoherent films, evanescent ones, guards) as in
:mod:`thinfilm_mi.optics.incoherent`; ``tests/optics/test_incoherent_mueller.py`` checks
the result against the average of coherent matrices over the thick film's phase.
"""
from __future__ import annotations

from typing import Any, Sequence

import drjit as dr

from thinfilm_mi.optics.core import Cx, cmul, prepare_stack, rouard_recursion
from thinfilm_mi.optics.incoherent import coherent_groups
from thinfilm_mi.optics.mueller import components, mueller_rt

__all__ = ["incoherent_mueller"]


def _substack(a: list, E: list, e1: list, lo: int, hi: int, reverse: bool):
    """``(r, τ̃)`` of the coherent sub-stack between media ``lo`` and ``hi`` for one
    polarisation (admittances ``a``), lit from ``lo`` (or from ``hi`` if
    ``reverse``): complex reflection amplitude and the transmission amplitude
    normalised so that ``|τ̃|²`` is the power transmittance (0 where the incident
    medium carries no flux)."""
    idx = list(range(lo, hi + 1))
    if reverse:
        idx.reverse()
    N, D, T = rouard_recursion([a[j] for j in idx], [E[j] for j in idx], [e1[j] for j in idx],
                               None, [None] * (len(idx) - 1))
    inv = 1.0 / D.abs2()
    Dc = D.conj()
    r = cmul(N, Dc) * inv
    a_in, a_out = a[idx[0]], a[idx[-1]]
    flux_ok = a_in.re > 0
    ratio = dr.maximum(a_out.re, 0.0) / dr.select(flux_ok, a_in.re, 1.0)
    # the factors 2 of the len(idx) - 1 interface t's
    norm = dr.select(flux_ok, dr.sqrt(ratio) * (2.0 ** (len(idx) - 1)), 0.0) * inv
    return r, cmul(T, Dc) * norm


def _triple(x_s: Cx, x_p: Cx):
    """``(s, p, c)`` of a pair of amplitudes."""
    return [x_s.abs2(), x_p.abs2(), cmul(x_s, x_p.conj())]


def incoherent_mueller(n0, cos0, films: Sequence[tuple[Any, Any]], n_exit, wl,
                       incoherent: Sequence[bool], transmission: bool = True) -> tuple:
    """The Mueller channels (:mod:`thinfilm_mi.optics.mueller`) of a stack whose films
    marked in ``incoherent`` add intensities; arguments as
    :func:`thinfilm_mi.optics.incoherent.incoherent_rt_sp`."""
    incoherent = list(incoherent)
    if len(incoherent) != len(films):
        raise ValueError(f"incoherent: expected {len(films)} flags (one per film), "
                         f"got {len(incoherent)}")
    groups = coherent_groups(incoherent)
    if len(groups) == 2:
        return mueller_rt(n0, cos0, films, n_exit, wl, transmission)
    cos0, q0, media, qs, E, e1, _, _, adm = prepare_stack(
        n0, cos0, films, n_exit, wl, True, True, True, True)
    grazing = cos0 <= 0.0
    # |exp(i delta)|^2 of every incoherent film: its single-pass power transmission
    P = [None if e is None else e.abs2() for e in e1]

    def parts(lo, hi, reverse):
        (r_s, t_s), (r_p, t_p) = (_substack(adm[pol], E, e1, lo, hi, reverse) for pol in "sp")
        return _triple(r_s, r_p), _triple(t_s, t_p)

    last = len(groups) - 2
    Re, Te = parts(groups[last], groups[last + 1], False)
    for k in range(last - 1, -1, -1):
        lo, hi = groups[k], groups[k + 1]
        Rf, Tf = parts(lo, hi, False)
        Rb, Tb = parts(lo, hi, True)
        P2 = P[hi] * P[hi]
        dens = [1.0 - Rb[i] * P2 * Re[i] for i in range(2)]
        # as in optics.incoherent: a series that does not converge (a lossless
        # evanescent film, or a thin absorbing "incoherent" one) is cut off
        ok = (dens[0] > 0.0) & (dens[1] > 0.0)
        inv = [1.0 / dr.select(ok, d, 1.0) for d in dens]
        den_c = Cx(1.0, 0.0) - cmul(Rb[2], Re[2]) * P2
        den_c = Cx(dr.select(ok, den_c.re, 1.0), dr.select(ok, den_c.im, 0.0))
        inv.append(Cx(den_c.re, -den_c.im) * (1.0 / den_c.abs2()))
        for i in range(3):
            mul = (lambda x, y: cmul(x, y)) if i == 2 else (lambda x, y: x * y)
            loop = mul(mul(Tf[i], Tb[i]), mul(Re[i], inv[i])) * P2
            if transmission:
                Te[i] = mul(mul(Tf[i], Te[i]), inv[i]) * P[hi]
            Re[i] = Rf[i] + loop
    if not transmission:
        return components(Re[0], Re[1], Re[2], grazing=grazing)
    # p: from the magnetic to the electric field amplitude, conj(n0 / n_exit) / |.|
    n_ex = media[-1]
    if isinstance(n_ex.im, (int, float)) and n_ex.im == 0:
        c_t = Te[2]
    else:
        c_t = cmul(Te[2], n_ex) * dr.rsqrt(n_ex.abs2())
    return components(Re[0], Re[1], Re[2], Te[0], Te[1], c_t, grazing=grazing)
