"""Tables of a stack's Mueller components, for ``*_spectral_polarized`` variants.

A table of powers holds ``R`` (and ``T``); a polarized render needs the whole
Mueller matrix of each lobe, which for a planar stack is four numbers per lobe,
all linear in intensities (:mod:`thinfilm_mi.optics.mueller`): ``R``, ``B = (R_s -
R_p)/2`` and ``C = r_s conj(r_p)`` (two channels). :data:`MUELLER` is the
*quantity* a :class:`~thinfilm_mi.tabulate.base.SideData` carries to have them
tabulated instead of the powers: 4 channels (``R, B, C_re, C_im``), 8 with
transmission (``R, T``, then the reflection's and the transmission's ``B, C``).
Everything else is the builders' own: the probe, the verification of every
channel within ``table_error`` (:mod:`thinfilm_mi.tabulate.exact`), the band
limit (:mod:`thinfilm_mi.tabulate.band`: the Gaussian in wavenumber averages
intensity-like products, which is what partially coherent light does to each
component), the colour check (here on ``R_s``, ``R_p`` and ``T_s``, ``T_p``,
each a power), the cache and the build report.

The quantity provides:

* the evaluators: :func:`~thinfilm_mi.optics.mueller.mueller_rt` (films
  unrolled), :func:`~thinfilm_mi.optics.incoherent_mueller.incoherent_mueller`
  (thick films averaged incoherently, polarized) and
  :func:`~thinfilm_mi.optics.mueller.mueller_rt_loop` (deep stacks, a loop);
* for the band-limited build's first level, the smooth projective amplitudes
  (:meth:`MuellerQuantity.smooth_terms`, ``N, D`` of s and p at the channels where
  the powers' :func:`~thinfilm_mi.tabulate.band.amplitudes` has them, so
  the resonance search is the same) and the channels from them
  (:meth:`MuellerQuantity.values`).
"""
from __future__ import annotations

import dataclasses

import drjit as dr
import numpy as np

from thinfilm_mi.optics.core import COMPONENTS, transmittance_factor_p, transmittance_factor_s
from thinfilm_mi.optics.incoherent_mueller import incoherent_mueller
from thinfilm_mi.optics.mueller import (
    amplitude_loop,
    channel_count,
    mueller_rt,
    mueller_rt_loop,
)
from thinfilm_mi.tabulate.base import SideData, evaluate_side
from thinfilm_mi.tabulate.policy import MUELLER_AUTO_MAX_FLOATS, MUELLER_AUTO_MIN_FILMS

__all__ = ["MUELLER", "MuellerQuantity"]

#: :meth:`MuellerQuantity.smooth_terms` rescales the amplitudes by smooth factors
#: only (``|N|``, ``|D|`` grow by at most ~2.8 per film: within float64 to ~600
#: films); deeper sides are divided by ``|Re D| + |Im D|`` after every film instead.
MAX_SMOOTH_FILMS = 250


def _terms_loop(n0, cos0, count, film, n_exit, wl, transmission, smooth: bool, **hints):
    """The amplitudes of :func:`~thinfilm_mi.optics.mueller.amplitude_loop` as the
    real channels of :meth:`MuellerQuantity.smooth_terms`."""
    amps = amplitude_loop(n0, cos0, count, film, n_exit, wl, transmission=transmission,
                          n0_max=hints.get("n0_max"), film_n_min=hints.get("film_n_min"),
                          smooth=smooth, label="thinfilm_mueller_band")
    zero = 0.0 * cos0 * wl
    out = []
    for pol in COMPONENTS:
        N, D, _ = amps[pol]
        out += [N.re, N.im, D.re, D.im]
    if transmission:
        q0 = dr.select(amps["grazing"], 1.0, amps["q0"])
        for pol in COMPONENTS:
            T = amps[pol][2]
            out += [T.re, T.im]
        out += [transmittance_factor_s(amps["q_exit"], q0),
                transmittance_factor_p(amps["n_exit"], amps["q_exit"], q0)]
    return tuple(zero + v for v in out)


def _smooth_loop(n0, cos0, count, film, n_exit, wl, transmission, **hints):
    return _terms_loop(n0, cos0, count, film, n_exit, wl, transmission, True, **hints)


def _normalised_loop(n0, cos0, count, film, n_exit, wl, transmission, **hints):
    return _terms_loop(n0, cos0, count, film, n_exit, wl, transmission, False, **hints)


def _unrolled(loop):
    """``loop`` traced film by film (a Python loop: few films), with the signature of
    :attr:`SideData.rt`."""
    def rt(n0, cos0, films, n_exit, wl, transmission):
        return loop(n0, cos0, len(films), lambda j: films[j], n_exit, wl, transmission)
    return rt


class MuellerQuantity:
    """What a Mueller table holds and how its builds evaluate it (see the module)."""

    name = "mueller"
    auto_max_floats = MUELLER_AUTO_MAX_FLOATS
    #: Mueller tables stay splines: resampled for bilinear lookups (16-25x the texels), the
    #: tables ``auto`` builds would exceed :data:`~thinfilm_mi.tabulate.policy.LINEAR_MAX_FLOATS`
    linear_max_floats = 0
    #: channels 8-9 of :meth:`smooth_terms` are amplitudes (``T``), not their squares
    squared_terms = False
    #: First v-node spacing of band-limited tables (in σ_ν), finer than the powers'
    #: (``band.V_SPACING``): the cross term ``C`` interpolates worse along v than ``R``, and
    #: at this spacing it meets the target the first time instead of after a finer round.
    v_spacing = 0.5

    @staticmethod
    def channels(transmission: bool) -> int:
        return channel_count(transmission)

    @staticmethod
    def auto_min_films(transmission: bool) -> int:
        """Films from which ``tabulate="auto"`` tabulates a side (either way)."""
        return MUELLER_AUTO_MIN_FILMS

    @staticmethod
    def rt(incoherent: list):
        """The build's evaluator ``(n0, cos0, films, n_exit, wl, transmission) ->
        channels`` of a side with these incoherent flags."""
        if any(incoherent):
            return lambda n0, cos0, films, n_exit, wl, transmission: incoherent_mueller(
                n0, cos0, films, n_exit, wl, incoherent, transmission)
        return mueller_rt

    rt_loop = staticmethod(mueller_rt_loop)

    @staticmethod
    def grazing(transmission: bool) -> np.ndarray:
        """The channels at grazing incidence (``r_s = r_p = -1``, ``t = 0``)."""
        return np.array([1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0] if transmission
                        else [1.0, 0.0, 1.0, 0.0])

    @staticmethod
    def smooth_terms(side: SideData, cos0: np.ndarray, rows: np.ndarray, wl: np.ndarray,
                     indices) -> tuple[np.ndarray, np.ndarray]:
        """The smooth projective amplitudes at points ``(cos0[i], wl[rows[i]])``, as
        :func:`~thinfilm_mi.tabulate.band.amplitudes` gives them: ``(terms,
        exponents)``, ``terms`` with ``Re, Im`` of ``N_s, D_s, N_p, D_p`` (channels
        0-7) and, with transmission, of ``T_s, T_p`` and the power factors ``w_s,
        w_p`` (``r = N / D``, ``t = T / D``); the exponents are 0 (the smooth
        rescaling alone keeps them in range). Beyond :data:`MAX_SMOOTH_FILMS` films
        the amplitudes are divided by ``|Re D| + |Im D|`` after every film instead: exact
        values, but ``D`` has no zeros left, so such sides are sampled without the
        resonance search."""
        smooth = len(side.films) <= MAX_SMOOTH_FILMS
        loop = _smooth_loop if smooth else _normalised_loop
        terms = dataclasses.replace(side, rt=_unrolled(loop), rt_loop=loop)
        values = evaluate_side(terms, cos0, rows, wl, indices)
        return values, np.zeros(values.shape[:-1] + (2,))

    @staticmethod
    def values(terms: np.ndarray, transmission: bool) -> np.ndarray:
        """The channels (last axis) from :meth:`smooth_terms` (any leading shape),
        formed as :func:`~thinfilm_mi.optics.mueller.components` forms them."""
        def cx(k):
            return terms[..., k] + 1j * terms[..., k + 1]
        Ds, Dp = cx(2), cx(6)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rs, rp = cx(0) / Ds, cx(4) / Dp
            Rs, Rp = np.minimum(np.abs(rs) ** 2, 1.0), np.minimum(np.abs(rp) ** 2, 1.0)
            c = rs * np.conj(rp)
            R = np.minimum(0.5 * (Rs + Rp), 1.0)
            out = [R, 0.5 * (Rs - Rp), c.real, c.imag]
            if transmission:
                ts, tp = cx(8) / Ds, cx(10) / Dp
                w_s, w_p = terms[..., 12], terms[..., 13]
                Ts, Tp = np.abs(ts) ** 2 * w_s, np.abs(tp) ** 2 * w_p
                ct = ts * np.conj(tp) * np.sqrt(np.maximum(w_s * w_p, 0.0))
                T = np.clip(0.5 * (Ts + Tp), 0.0, 1.0 - R)
                out = [R, T] + out[1:] + [0.5 * (Ts - Tp), ct.real, ct.imag]
        out = np.stack(out, axis=-1)
        bad = ~np.all(np.isfinite(out), axis=-1, keepdims=True)
        return np.where(bad, MuellerQuantity.grazing(transmission), out)

    @staticmethod
    def colour_terms(values: np.ndarray, transmission: bool) -> np.ndarray:
        """The powers the colour check compares (last axis): ``R``, ``R_s = R + B``,
        ``R_p = R - B`` [, and the same of ``T``]: what a render through a polarizer
        sees, each non-negative."""
        R, B = values[..., 0], values[..., 2 if transmission else 1]
        out = [R, R + B, R - B]
        if transmission:
            T, BT = values[..., 1], values[..., 5]
            out += [T, T + BT, T - BT]
        return np.stack(out, axis=-1)


#: The Mueller quantity (stateless; one instance shared by every build).
MUELLER = MuellerQuantity()
