"""Thick films treated incoherently: intensities, not amplitudes, add up in them.

A film much thicker than the coherence length of the light (a few µm for
sunlight or a lamp: ``lambda^2 / delta_lambda``) shows interference fringes
closer than any real spectrum resolves; a spectral renderer that samples a few
monochromatic wavelengths per path turns them into colour noise. Averaged over
a fringe, such a film only attenuates and reflects *power*. This module computes
that average exactly, as tmm's ``inc_tmm`` does for layers marked ``'i'``
(S. J. Byrnes, "Multilayer optical calculations", arXiv:1603.02720, section
"Incoherent and partly-incoherent calculations"; tmm's ``tmm_core.py``).

Conventions (those of :mod:`thinfilm_mi.optics.core` and of ``inc_tmm``):

* The films marked incoherent split the stack into *coherent sub-stacks*: the
  consecutive coherent films between two incoherent media (the ambient, an
  incoherent film, the exit medium). A sub-stack may have no films (a bare
  interface between two incoherent media).
* For each sub-stack and each polarisation, the coherent core gives power
  reflectances and transmittances from both sides: forward ``Rf, Tf`` (lit from
  the medium before it) and backward ``Rb, Tb`` (lit from the medium after it,
  the films in reverse order). An incident medium ``i`` may absorb (an
  incoherent film with ``k > 0``); as in tmm, ``R = |r|^2`` and
  ``T = |t|^2 Re(a_exit) / Re(a_i)`` are relative to the power flux of the
  incident wave alone (the cross term with the reflected wave averages out in
  an incoherent medium), where ``a = q`` for s and ``a = q / n^2`` for p are the
  admittances (``Re(q/n^2) |n|^2 = Re(n^2 conj(q)) / |n|^2`` is the p factor of
  :func:`thinfilm_mi.optics.core.transmittance_factor_p` with ``q0 = 1``).
* ``q = n cos(theta) = sqrt(n^2 - n0^2 sin^2 theta0)`` is the decaying root
  (``Im q >= 0``) chosen by :func:`thinfilm_mi.optics.core.sqrt_decaying`, the very
  ``q`` the coherent core uses (including its floor at critical angles). One
  pass through an incoherent film of thickness ``d`` keeps the fraction
  ``P = exp(-4 pi Im(q) d / lambda)`` of the power (``inc_tmm``'s ``P_list``;
  :func:`thinfilm_mi.optics.core.film_attenuation`). A lossless incoherent film's
  thickness therefore does not matter at all.
* The multiple incoherent reflections are a geometric series. Going from the
  exit medium outwards, the effective reflectance ``Re`` and transmittance
  ``Te`` seen from inside incoherent film ``k + 1`` (at its far face) become,
  seen from the medium before sub-stack ``k``::

      Re <- Rf + Tf Tb P^2 Re / (1 - Rb P^2 Re)
      Te <- Tf P Te / (1 - Rb P^2 Re)

  This is inc_tmm's product of ``L`` matrices written as a continued fraction:
  all terms are non-negative, nothing is divided by a transmittance (tmm
  divides by ``T_list`` and floors ``P`` at 1e-30), so an opaque film (``P``
  underflowing to 0) or an interface with ``T = 0`` gives no 0/0.
* s and p are combined separately (a planar stack does not mix them), then
  ``R = (Rs + Rp) / 2`` and ``T = (Ts + Tp) / 2`` as in
  :func:`thinfilm_mi.optics.unpolarized.unpolarized_rt`: ``R`` clamped to 1, ``T`` clipped
  to ``[0, 1 - R]``, and ``R = 1``, ``T = 0`` exactly at grazing incidence.
  ``T`` is the power entering the exit medium (into a metal substrate: the
  power it absorbs).
* In an absorbing incident medium the cross term between the incident and the
  reflected wave is left out of the flux (tmm's convention, exact once a thick
  film has averaged it out), so a sub-stack's ``R + T`` may differ from its
  true ``1 - A``. For the films this is meant for (thick: ``k`` small, or
  opaque) the difference is of order ``k / n`` times the light that comes back
  through the film; a strongly absorbing film thin enough to be transparent
  (k ~ 1, d ~ 10 nm) is not incoherent, and marking it so can give
  ``R + T > 1`` (as in tmm); the final clip bounds it.
* An incoherent film in which the light is evanescent and lossless (beyond its
  critical angle, ``Re q = 0``) carries no power flux, so nothing crosses it.
  (A thin gap that tunnels light is a coherent effect: keep such films coherent.)
* An incoherent film of thickness 0 is *not* the same as no film: it still
  removes the interference between the sub-stacks on its two sides (the
  intensities of its two faces add). It equals no film only where that
  interference is absent anyway, e.g. when its index matches a neighbour's.

Everything is generic over Python floats, Dr.Jit ``Float64``/``Float`` arrays
and ``mi.Spectrum``: only ``dr.*`` functions and :class:`~thinfilm_mi.optics.core.Cx`
are used, and the list of incoherent films is a Python list known at trace
time. The sub-stack powers come from the core's own setup and recursion
(``optics.prepare_stack`` and ``optics.rouard_recursion``, in the form ``stack_rt`` uses),
so the branch choices, critical-angle floors and float32 rescaling are the
core's.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import drjit as dr

from thinfilm_mi.optics.core import (
    COMPONENTS,
    clip_transmittance,
    is_zero,
    prepare_stack,
    rouard_recursion,
    stack_rt,
)

__all__ = ["incoherent_rt", "incoherent_rt_sp", "reference_incoherent_rt", "coherent_groups"]


def coherent_groups(incoherent: Sequence[bool]) -> list[int]:
    """Media indices of the incoherent media (``0`` the ambient, ``j`` film ``j - 1``,
    ``len(incoherent) + 1`` the exit); consecutive entries bound one coherent sub-stack."""
    inc = [bool(x) for x in incoherent]
    return [0] + [j + 1 for j, x in enumerate(inc) if x] + [len(inc) + 1]


def _substack(a: list, E: list, mag2: list, lo: int, hi: int, reverse: bool, transmission: bool):
    """Power ``(R, T)`` of the coherent sub-stack between media ``lo`` and ``hi`` for
    one polarisation (admittances ``a``), lit from ``lo`` (or from ``hi`` if
    ``reverse``). ``T`` is ``None`` unless ``transmission``."""
    idx = list(range(lo, hi + 1))
    if reverse:
        idx.reverse()
    a_s = [a[j] for j in idx]
    E_s = [E[j] for j in idx]
    t_power = None
    if transmission:
        # |a_j|^2 |exp(i delta_j)|^2 for the incident medium and the films (not
        # the incident medium's own attenuation: that is the incoherent P).
        t_power = []
        for pos, j in enumerate(idx[:-1]):
            f = a[j].abs2()
            if pos > 0 and mag2[j] is not None:
                f = f * mag2[j]
            t_power.append(f)
    N, D, T = rouard_recursion(a_s, E_s, None, t_power, [None] * (len(idx) - 1))
    inv = 1.0 / D.abs2()
    R = N.abs2() * inv
    if not transmission:
        return R, None
    a_in, a_out = a[idx[0]], a[idx[-1]]
    # no flux in the incident medium (grazing, or a lossless evanescent film): T = 0
    flux_ok = a_in.re > 0
    re_in_safe = dr.select(flux_ok, a_in.re, 1.0)
    # the factors 2 of the len(idx) - 1 interface t's, squared
    T = T * inv * ((4.0 ** (len(idx) - 1)) * a_out.re / re_in_safe)
    T = dr.select(flux_ok, T, 0.0)
    return R, T


def incoherent_rt_sp(n0, cos0, films: Sequence[tuple[Any, Any]], n_exit, wl,
                     incoherent: Sequence[bool], transmission: bool = True):
    """``(Rs, Rp, Ts, Tp)`` of a stack whose films marked in ``incoherent`` add
    intensities (see the module docstring); ``Ts = Tp = None`` without
    ``transmission``. Per polarisation ``R <= 1`` and ``0 <= T <= 1 - R``;
    ``R = 1``, ``T = 0`` at grazing incidence.

    Arguments as for :func:`thinfilm_mi.optics.core.stack_amplitudes`; ``incoherent``
    is a Python sequence of bools, one per film (known at trace time).
    """
    incoherent = list(incoherent)
    if len(incoherent) != len(films):
        raise ValueError(f"incoherent: expected {len(films)} flags (one per film), "
                         f"got {len(incoherent)}")
    groups = coherent_groups(incoherent)
    if len(groups) == 2:  # all coherent: the core itself
        Rs, Rp, Ts, Tp = stack_rt(n0, cos0, films, n_exit, wl, transmission=transmission)
        return Rs, Rp, Ts, Tp

    cos0, q0, media, qs, E, _, _, _, adm = prepare_stack(
        n0, cos0, films, n_exit, wl, True, True, True, False)
    grazing = cos0 <= 0.0
    inv_wl = 1.0 / wl
    # |exp(2 i delta)| = exp(-4 pi Im(q) d / lambda) of every film (None where it
    # is 1 at trace time): the t_power factor of coherent films, and the
    # single-pass power transmission P of incoherent ones.
    mag2 = [None] * len(media)
    for j, (_, d) in enumerate(films):
        q = qs[j + 1]
        if not is_zero(q.im):
            mag2[j + 1] = dr.exp((-4.0 * math.pi) * (q.im * (d * inv_wl)))

    out = []
    for pol in COMPONENTS:
        a = adm[pol]
        last = len(groups) - 2
        Re, Te = _substack(a, E, mag2, groups[last], groups[last + 1], False, transmission)
        for k in range(last - 1, -1, -1):
            lo, hi = groups[k], groups[k + 1]
            Rf, Tf = _substack(a, E, mag2, lo, hi, False, True)
            Rb, Tb = _substack(a, E, mag2, lo, hi, True, True)
            P = mag2[hi]
            PR = Re if P is None else P * P * Re
            den = 1.0 - Rb * PR
            # den <= 0 needs Rb P^2 Re >= 1: a lossless evanescent film (then Tf =
            # Tb = 0) or the R > 1 of a thin absorbing "incoherent" film (above)
            den = dr.select(den > 0.0, den, 1.0)
            inv = 1.0 / den
            Re = Rf + Tf * Tb * PR * inv
            if transmission:
                Te = Tf * Te * inv if P is None else Tf * P * Te * inv
        R = dr.select(grazing, 1.0, dr.minimum(Re, 1.0))
        T = None
        if transmission:
            T = dr.select(grazing, 0.0, clip_transmittance(Te, R))
        out.append((R, T))
    (Rs, Ts), (Rp, Tp) = out
    return Rs, Rp, Ts, Tp


def incoherent_rt(n0, cos0, films: Sequence[tuple[Any, Any]], n_exit, wl,
                  incoherent: Sequence[bool], transmission: bool = True):
    """Unpolarised ``R`` (and ``T``, the power entering ``n_exit``) of a stack with
    incoherent thick films; any array type (floats, Dr.Jit arrays, ``mi.Spectrum``).

    Same arguments and conventions as :func:`thinfilm_mi.optics.unpolarized.unpolarized_rt`
    plus ``incoherent`` (a Python list of bools, one per film, from the ambient
    side inwards): ``R = (Rs + Rp) / 2`` clamped to 1, ``T`` clipped to
    ``[0, 1 - R]``, ``R = 1`` and ``T = 0`` at grazing incidence. With no film
    marked it is the coherent core (:func:`thinfilm_mi.optics.core.stack_rt`). For a
    stack lit from the other side reverse ``films`` and ``incoherent`` together.
    """
    Rs, Rp, Ts, Tp = incoherent_rt_sp(n0, cos0, films, n_exit, wl, incoherent, transmission)
    R = dr.minimum(0.5 * (Rs + Rp), 1.0)
    if not transmission:
        return R
    return R, clip_transmittance(0.5 * (Ts + Tp), R)


def reference_incoherent_rt(n0, cos0, films, thicknesses, n_exit, wavelength,
                            incoherent: Sequence[bool], size=None) -> dict:
    """Float64 ``Rs, Rp, Ts, Tp, R, T`` (numpy arrays) of a partly incoherent stack.

    Like :func:`thinfilm_mi.optics.backend.reference_rt`: every argument a numpy array
    of one flat length (or a broadcastable scalar), ``films`` the complex indices
    and ``thicknesses`` (nm, scalars) of the films, ``incoherent`` one bool per
    film. Runs :func:`incoherent_rt_sp` once on Dr.Jit's LLVM backend.
    """
    from drjit.llvm import Float64

    from thinfilm_mi.optics.backend import to_inputs, to_numpy

    n0_d, cos0_d, film_d, nex, wl, size = to_inputs(n0, cos0, films, thicknesses, n_exit,
                                                    wavelength, size)
    Rs, Rp, Ts, Tp = incoherent_rt_sp(n0_d, cos0_d, film_d, nex, wl, incoherent)
    R = dr.minimum(0.5 * (Rs + Rp), 1.0)
    T = clip_transmittance(0.5 * (Ts + Tp), R)
    zero = dr.zeros(Float64, size)
    out = {"Rs": Rs + zero, "Rp": Rp + zero, "Ts": Ts + zero, "Tp": Tp + zero,
           "R": R + zero, "T": T + zero}
    dr.eval(*out.values())
    return {k: to_numpy(v) for k, v in out.items()}
