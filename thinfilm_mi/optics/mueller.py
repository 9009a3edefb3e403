"""The Mueller components of a stack: what a polarized table holds, on any Dr.Jit type.

A planar stack does not mix s and p: its reflection is the Jones matrix
``diag(r_s, r_p)``, and in Mitsuba's convention (amplitudes ``conj(r)``, see
:mod:`thinfilm_mi.optics.core`) the Mueller matrix in the s/p frame is

    [[R, B, 0,     0    ],
     [B, R, 0,     0    ],
     [0, 0, C_re, -C_im ],
     [0, 0, C_im,  C_re ]]

with ``R = (|r_s|² + |r_p|²)/2``, ``B = (|r_s|² - |r_p|²)/2`` and ``C = r_s
conj(r_p)`` in *our* (tmm's) amplitudes (Mitsuba's ``A_p conj(A_s)``: the sign
of ``C_im`` is that of :func:`thinfilm_mi.render.amplitudes.jones_shape`).
Transmission is the same with ``|t_s|² w_s``, ``|t_p|² w_p`` (the power
factors of :func:`~thinfilm_mi.optics.core.transmittance_factor_s` and ``_p``)
and ``C = t_s conj(t_p) sqrt(w_s w_p)``.

All four are linear in the products ``a_s conj(a_s)``, ``a_p conj(a_p)`` and
``a_s conj(a_p)``, so any average over wavelengths (a band-limited table) or
over the phase of a thick film (an incoherent one) is a matrix of the same form
whose components are the averaged components. In the basis ``(s, p, c)`` =
``(R + B, R - B, C)`` such matrices multiply component by component (the
Mueller matrix of ``diag(a_s, a_p) diag(b_s, b_p)`` has ``(a_s b_s conj(..),
..., a_s b_s conj(a_p b_p))``) and add component by component: an incoherent
thick film combines its two sides' matrices by the same geometric series as the
powers, for ``s`` and ``p`` as :mod:`thinfilm_mi.optics.incoherent` does and for
``c`` in complex arithmetic (:mod:`thinfilm_mi.optics.incoherent_mueller`).

Channels (:func:`channel_count`), the unpolarised powers first so that a
Mueller table's first channels are what a table of powers holds:

* reflection only: ``R, B_R, C_R.re, C_R.im``;
* with transmission: ``R, T, B_R, C_R.re, C_R.im, B_T, C_T.re, C_T.im``.

``R`` and ``T`` are formed as :func:`thinfilm_mi.optics.unpolarized.unpolarized_powers`
forms them (``R <= 1``, ``0 <= T <= 1 - R``, ``R = 1`` and ``T = 0`` at grazing
incidence, where ``r_s = r_p = -1``: ``C_R = 1``).

* :func:`mueller_rt`: the components with the films unrolled
  (:func:`~thinfilm_mi.optics.core.stack_amplitudes`);
* :func:`mueller_rt_loop` / :func:`amplitude_loop`: the same with the films
  visited by a Dr.Jit loop (float64 table builds of deep stacks), which also
  gives the smooth projective amplitudes a band-limited build samples.
"""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.optics.core import (
    COMPONENTS,
    Cx,
    LoopIncidence,
    StackAmplitudes,
    cinv,
    cmul,
    films_left,
    loop_body,
    phase_factor,
    rouard_step,
    stack_amplitudes,
    transmittance_factor_p,
    transmittance_factor_s,
)

__all__ = ["channel_count", "components", "mueller_rt", "amplitude_loop", "loop_components",
           "loop_amplitudes", "mueller_rt_loop"]


def channel_count(transmission: bool) -> int:
    """Channels of the Mueller components: 4 (reflection) or 8 (with transmission)."""
    return 8 if transmission else 4


def components(Rs, Rp, c_r: Cx, Ts=None, Tp=None, c_t: Cx | None = None, grazing=None):
    """The channels (see the module) from the s and p powers and the cross terms
    ``c = a_s conj(a_p)`` (normalised as the powers are); ``grazing`` (a mask, or
    ``None``) sets ``R = 1``, ``T = 0`` and the matrices of ``r = -1``, ``t = 0``."""
    R = dr.minimum(0.5 * (Rs + Rp), 1.0)
    B = 0.5 * (Rs - Rp)
    cre, cim = c_r.re, c_r.im
    if grazing is not None:
        R, B = dr.select(grazing, 1.0, R), dr.select(grazing, 0.0, B)
        cre, cim = dr.select(grazing, 1.0, cre), dr.select(grazing, 0.0, cim)
    if Ts is None:
        return R, B, cre, cim
    T = dr.clip(0.5 * (Ts + Tp), 0.0, 1.0 - R)
    BT, tre, tim = 0.5 * (Ts - Tp), c_t.re, c_t.im
    if grazing is not None:
        T, BT = dr.select(grazing, 0.0, T), dr.select(grazing, 0.0, BT)
        tre, tim = dr.select(grazing, 0.0, tre), dr.select(grazing, 0.0, tim)
    return R, T, B, cre, cim, BT, tre, tim


def _transmitted(ts: Cx, tp: Cx, w_s, w_p):
    """``(Ts, Tp, c_T)`` of the transmission amplitudes and their power factors."""
    c = cmul(ts, tp.conj()) * dr.sqrt(dr.maximum(w_s * w_p, 0.0))
    return ts.abs2() * w_s, tp.abs2() * w_p, c


def mueller_rt(n0, cos0, films, n_exit, wl, transmission: bool = True) -> tuple:
    """The channels of a coherent stack, films unrolled; arguments as
    :func:`~thinfilm_mi.optics.unpolarized.unpolarized_rt`."""
    a = stack_amplitudes(n0, cos0, films, n_exit, wl, transmission=transmission)
    c_r = cmul(a.rs, a.rp.conj())
    if not transmission:
        return components(a.rs.abs2(), a.rp.abs2(), c_r, grazing=a.grazing)
    q0 = dr.select(a.grazing, 1.0, a.q0)
    Ts, Tp, c_t = _transmitted(a.ts, a.tp, transmittance_factor_s(a.q_exit, q0),
                               transmittance_factor_p(a.n_exit, a.q_exit, q0))
    return components(a.rs.abs2(), a.rp.abs2(), c_r, Ts, Tp, c_t, grazing=a.grazing)


def amplitude_loop(n0, cos0, count, film, n_exit, wavelength, *, transmission: bool,
                   n0_max: float | None = None, film_n_min: float | None = None,
                   smooth: bool = False, label: str = "thinfilm_mueller") -> dict:
    """The projective amplitudes of a stack with the films visited by a Dr.Jit loop.

    Arguments as :func:`~thinfilm_mi.optics.core.stack_rt_loop` (``count`` films,
    ``film(j)`` their index and thickness; ``n0_max`` an upper bound of the
    ambient's index; ``film_n_min`` a lower bound of the films' index when they are
    real). Returns ``{"s": (N, D, T), "p": (N, D, T), "q0", "q_exit", "n_exit",
    "grazing"}`` with ``r = N / D`` and ``t = T / D`` (``T`` ``None`` without
    ``transmission``; for p the telescoped ``n0 / n_exit`` included): the step of
    :func:`~thinfilm_mi.optics.core.rouard_step`, and ``T <- 2 a_j e_j T`` with the
    film's ``exp(i delta)`` (:func:`~thinfilm_mi.optics.core.rouard_recursion`'s
    amplitude form). After every film ``(N, D, T)`` are divided by ``|Re D| +
    |Im D|`` or, with ``smooth``, multiplied by ``1 / sqrt(|a_j|² + |a_j+1|²)``, a
    smooth function of the wavelength (then every amplitude is analytic in λ
    without the resonant ``1 / D``: what a band-limited build samples; within
    float64 to a few hundred films)."""
    inc = LoopIncidence(n0, cos0, n_exit, wavelength, n0_max, film_n_min)

    def film_terms(j):
        m, d = film(j)
        q, a = inc.film_admittances(Cx.of(m))
        return a, phase_factor(q, d * inc.inv_wl, False)

    t0 = inc.full(Cx(1.0)) if transmission else ()
    state = (count, *inc.full(Cx(0.0)), *inc.full(Cx(1.0)), *t0,
             *inc.full(Cx(0.0)), *inc.full(Cx(1.0)), *t0,
             *inc.full(inc.a_ex["s"]), *inc.full(inc.a_ex["p"]), *inc.full(Cx(0.0)))
    k = 6 if transmission else 4

    def unpack(st):
        """``({pol: (N, D, T)}, {pol: admittance below}, phase factor below)`` of the state."""
        cur = {}
        for i, pol in enumerate(COMPONENTS):
            v = st[i * k:(i + 1) * k]
            cur[pol] = (Cx(v[0], v[1]), Cx(v[2], v[3]), Cx(v[4], v[5]) if transmission else None)
        below = {"s": Cx(st[2 * k], st[2 * k + 1]), "p": Cx(st[2 * k + 2], st[2 * k + 3])}
        return cur, below, Cx(st[2 * k + 4], st[2 * k + 5])

    def body(j, *st):
        j = j - 1
        a, e1 = film_terms(j)
        E = cmul(e1, e1)
        cur, below, E_b = unpack(st)
        out = []
        for pol in COMPONENTS:
            N, D, T = _amplitude_step(a[pol], below[pol], E_b, e1, *cur[pol], smooth=smooth)
            out += [N.re, N.im, D.re, D.im] + ([T.re, T.im] if transmission else [])
        return (j, *out, a["s"].re, a["s"].im, a["p"].re, a["p"].im, E.re, E.im)

    cur, below, E_b = unpack(dr.while_loop(state, films_left, loop_body(body), label=label)[1:])
    a0 = inc.ambient_admittances(n0)
    out = {"q0": inc.q0, "q_exit": inc.q_ex, "n_exit": inc.n_ex, "grazing": inc.grazing}
    # t_p carries the telescoped product n0 / n_exit of the p admittances q / n^2
    t_scale = {"s": lambda T: T, "p": lambda T: cmul(T, cinv(inc.n_ex) * n0)}
    for pol in COMPONENTS:
        N, D, T = _amplitude_step(a0[pol], below[pol], E_b, None, *cur[pol], smooth=smooth,
                                  last=True)
        out[pol] = (N, D, T if T is None else t_scale[pol](T))
    return out


def _amplitude_step(a: Cx, b: Cx, E: Cx, e1, N: Cx, D: Cx, T: Cx | None, *, smooth: bool,
                    last: bool = False):
    """One interface of :func:`amplitude_loop`: the Rouard step from the medium below
    (admittance ``b``, phase factor ``E``) to the one above (``a``, its ``exp(i delta)``
    ``e1``; ``None`` for the ambient), ``T <- 2 a e1 T``, then (but for the ``last``) the
    rescaling: by ``1 / (|Re D| + |Im D|)``, or with ``smooth`` by ``1 / sqrt(|a|² +
    |b|²)``."""
    N, D = rouard_step(a, b, E, N, D)
    if T is not None:
        T = cmul(a, T) * 2.0 if e1 is None else cmul(cmul(a, e1), T) * 2.0
    if last:
        return N, D, T
    if smooth:
        scale = dr.rsqrt(a.abs2() + b.abs2())
    else:
        scale = 1.0 / (dr.abs(D.re) + dr.abs(D.im))
    N, D = N * scale, D * scale
    return N, D, (None if T is None else T * scale)


def loop_components(amps: dict, transmission: bool) -> tuple:
    """The channels from :func:`amplitude_loop`'s amplitudes."""
    (Ns, Ds, Ts_), (Np, Dp, Tp_) = amps["s"], amps["p"]
    grazing = amps["grazing"]
    inv_s, inv_p = 1.0 / Ds.abs2(), 1.0 / Dp.abs2()
    # r_s conj(r_p) = N_s conj(N_p) / (D_s conj(D_p))
    den = cmul(Ds, Dp.conj())
    inv_sp = inv_s * inv_p
    c_r = cmul(cmul(Ns, Np.conj()), den.conj()) * inv_sp
    Rs, Rp = dr.minimum(Ns.abs2() * inv_s, 1.0), dr.minimum(Np.abs2() * inv_p, 1.0)
    if not transmission:
        return components(Rs, Rp, c_r, grazing=grazing)
    q0 = dr.select(grazing, 1.0, amps["q0"])
    w_s = transmittance_factor_s(amps["q_exit"], q0)
    w_p = transmittance_factor_p(amps["n_exit"], amps["q_exit"], q0)
    ts = cmul(Ts_, Ds.conj()) * inv_s
    tp = cmul(Tp_, Dp.conj()) * inv_p
    Ts, Tp, c_t = _transmitted(ts, tp, w_s, w_p)
    return components(Rs, Rp, c_r, Ts, Tp, c_t, grazing=grazing)


def loop_amplitudes(n0, cos0, count, film, n_exit, wl, transmission: bool = True, *,
                    n0_max: float | None = None, film_n_min: float | None = None,
                    film_n_max: float | None = None, films_max: int | None = None) -> StackAmplitudes:
    """:func:`~thinfilm_mi.optics.core.stack_amplitudes` with the films visited by a loop
    (:func:`amplitude_loop`; the signature of
    :func:`~thinfilm_mi.optics.unpolarized.unpolarized_rt_loop`, ``film_n_max`` and
    ``films_max`` accepted and not needed): the exact path of polarized variants for
    deep stacks, whose kernel does not grow with the number of films. ``r = -1`` and
    ``t = 0`` at grazing incidence."""
    amps = amplitude_loop(n0, cos0, count, film, n_exit, wl, transmission=transmission,
                          n0_max=n0_max, film_n_min=film_n_min)
    grazing = amps["grazing"]
    out = {}
    for pol in COMPONENTS:
        N, D, T = amps[pol]
        inv = cinv(D)
        out[pol] = (Cx(-1.0, 0.0).select(grazing, cmul(N, inv)),
                    None if T is None else Cx(0.0, 0.0).select(grazing, cmul(T, inv)))
    return StackAmplitudes(out["s"][0], out["p"][0], out["s"][1], out["p"][1], amps["q0"],
                           amps["q_exit"], amps["n_exit"], grazing)


def mueller_rt_loop(n0, cos0, count, film, n_exit, wl, transmission: bool = True, *,
                    n0_max: float | None = None, film_n_min: float | None = None,
                    film_n_max: float | None = None, films_max: int | None = None) -> tuple:
    """:func:`mueller_rt` with the films visited by a loop (:func:`amplitude_loop`);
    the signature of :func:`~thinfilm_mi.optics.unpolarized.unpolarized_rt_loop`
    (``film_n_max`` and ``films_max`` are accepted and not needed)."""
    amps = amplitude_loop(n0, cos0, count, film, n_exit, wl, transmission=transmission,
                          n0_max=n0_max, film_n_min=film_n_min)
    return loop_components(amps, transmission)
