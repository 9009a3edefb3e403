"""Numerical stability of the optics core under stress: float32 against float64 and tmm.

    /tmp/venv/bin/python benchmarks/stability.py [--points 1000000] [--tmm-points 2000]
                                                 [--markdown]

For each regime below, ``--points`` extreme evaluations (default 10^6) of the
unpolarised ``R`` and ``T`` are made in **one** float32 Dr.Jit call of
``unpolarized.unpolarized_rt`` (the function every BSDF evaluates in its render
kernel: ``optics.stack_amplitudes`` then the power factors) on
``drjit.llvm.Float`` arrays, one lane per point, with per-lane random indices,
thicknesses, angles and wavelengths (opaque inputs). The same function then runs
on ``drjit.llvm.Float64`` with the *same float32-rounded inputs* (so the error
measured is that of the float32 arithmetic, not of rounding the inputs, which a
render kernel cannot avoid anyway), and ``tmm.coh_tmm`` (s and p, float64 numpy)
on a random subsample of ``--tmm-points`` points per regime (tmm takes ~0.1-1
ms per point, so it cannot do 10^6).

Columns: points; non-finite outputs; out of range (``R`` or ``T`` outside
[0, 1] or ``R + T > 1 + 1e-5``); max and 99.9th percentile of
``max(|R32 - R64|, |T32 - T64|)``; on the tmm subsample, the max of the same
error of float32 and of float64 against tmm (``n/a``: tmm is not defined there,
e.g. exactly grazing incidence). The seed is fixed: the table is reproducible.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from dataclasses import dataclass
from typing import Callable

import drjit as dr
import numpy as np
from drjit.llvm import Float, Float64, UInt32

from thinfilm_mi.llvm import require_llvm
from thinfilm_mi.optics.core import Cx, real_loop_applies, stack_rt_loop
from thinfilm_mi.optics.unpolarized import unpolarized_rt

F32 = np.float32


@dataclass
class Case:
    """One regime: per-point arrays (length N) for a stack of ``L`` films.

    ``n0``: ambient index (real); ``films``: list of (complex index array,
    thickness array in nm); ``n_exit``: complex array; ``cos0``, ``wl`` (nm).
    """

    n0: np.ndarray
    films: list
    n_exit: np.ndarray
    cos0: np.ndarray
    wl: np.ndarray


def _f32(a):
    """Round to float32 (real, or real and imaginary parts separately), back as float64."""
    a = np.asarray(a)
    if np.iscomplexobj(a):
        return a.real.astype(F32).astype(np.float64) + 1j * a.imag.astype(F32).astype(np.float64)
    return a.astype(F32).astype(np.float64)


def rounded(c: Case) -> Case:
    return Case(_f32(c.n0), [(_f32(n), _f32(d)) for n, d in c.films], _f32(c.n_exit),
                _f32(np.clip(c.cos0, 0.0, 1.0)), _f32(c.wl))


U32 = 2.0 ** -24


def perturbed(c: Case, rng) -> Case:
    """Every real input (real and imaginary parts separately) times 1 +- u, u = 2^-24."""
    def p(a):
        a = np.asarray(a)
        if np.iscomplexobj(a):
            return p(a.real) + 1j * p(a.imag)
        return a * (1.0 + U32 * rng.choice([-1.0, 1.0], a.shape))
    return Case(p(c.n0), [(p(n), p(d)) for n, d in c.films], p(c.n_exit),
                np.clip(p(c.cos0), 0.0, 1.0), p(c.wl))


def logu(rng, lo, hi, size):
    return np.exp(rng.uniform(math.log(lo), math.log(hi), size))


def cos_from_beta(n0, beta):
    """cos(theta0) for the tangential index beta = n0 sin(theta0)."""
    s = np.clip(beta / n0, 0.0, 1.0)
    return np.sqrt((1 - s) * (1 + s))


# ---------------------------------------------------------------------------
# Regimes
# ---------------------------------------------------------------------------
def random_films(rng, N, L, dmax=100_000.0, kmax=20.0, lossless=False):
    films = []
    for _ in range(L):
        n = rng.uniform(1.0, 6.0, N)
        k = np.zeros(N) if lossless else np.where(rng.random(N) < 0.5, 0.0, logu(rng, 1e-4, kmax, N))
        # thickness: a third exactly 0, a third up to 1 um, a third up to dmax
        u = rng.random(N)
        d = np.where(u < 1 / 3, 0.0, np.where(u < 2 / 3, rng.uniform(0, 1000.0, N),
                                                rng.uniform(0, dmax, N)))
        films.append((n + 1j * k, d))
    return films


def regime_normal(rng, N):
    """cos = 1 exactly; 7 random films n in [1, 6], k in [0, 20], d in [0, 100 um]."""
    films = random_films(rng, N, 7)
    return Case(np.ones(N), films, rng.uniform(1, 6, N) + 1j * rng.uniform(0, 5, N),
                np.ones(N), rng.uniform(360, 830, N))


def regime_grazing(rng, N):
    """cos in {0, 1e-7} and log-uniform in [1e-7, 1e-3]; 7 random films, n0 in [1, 2]."""
    films = random_films(rng, N, 7)
    u = rng.random(N)
    cos0 = np.where(u < 0.25, 0.0, np.where(u < 0.5, 1e-7, logu(rng, 1e-7, 1e-3, N)))
    return Case(rng.uniform(1, 2, N), films, rng.uniform(1, 6, N) + 1j * rng.uniform(0, 5, N),
                cos0, rng.uniform(360, 830, N))


def regime_critical(rng, N):
    """Light from glass (n0 in [1.4, 2.5]) at the critical angle of the exit medium
    (n_exit = 1.0) or of the first film (n = 1.0 .. n0), +- a log-uniform offset
    in [1e-8, 1e-2] (or exactly at it) in cos; 3 films, the others random."""
    n0 = rng.uniform(1.4, 2.5, N)
    n_low = rng.uniform(1.0, 1.0, N) * np.where(rng.random(N) < 0.5, 1.0, rng.uniform(1.0, 1.3, N))
    films = [(n_low + 0j, rng.uniform(0, 2000, N))] + random_films(rng, N, 2, dmax=2000.0, kmax=5.0)
    which = rng.random(N) < 0.5  # critical angle of the exit medium, else of film 1
    n_exit = np.where(which, 1.0 + 0j, rng.uniform(1.0, 3.0, N) + 0j)
    nc = np.where(which, 1.0, n_low)
    c = cos_from_beta(n0, nc)
    off = np.where(rng.random(N) < 0.1, 0.0, logu(rng, 1e-8, 1e-2, N) * rng.choice([-1, 1], N))
    return Case(n0, films, n_exit, np.clip(c + off, 0, 1), rng.uniform(360, 830, N))


def regime_tir(rng, N):
    """TIR and FTIR from inside glass: n0 = 1.5 | air gap 0-2000 nm | 1.5 (FTIR) or
    | air (TIR) with an optional absorbing or dielectric film, angles beyond
    the critical angle (beta in [1, 1.5])."""
    n0 = np.full(N, 1.5)
    gap = rng.uniform(0, 2000, N)
    ftir = rng.random(N) < 0.5
    films = [(np.full(N, 1.0 + 0j), gap),
             (np.where(rng.random(N) < 0.5, 2.0 + 0j, 0.2 + 3.0j), rng.uniform(0, 50, N))]
    n_exit = np.where(ftir, 1.5 + 0j, 1.0 + 0j)
    beta = rng.uniform(1.0, 1.5, N)
    return Case(n0, films, n_exit, cos_from_beta(n0, beta), rng.uniform(360, 830, N))


def _guided_mode_positions(n0, gap, n_g, d_g, n_ex, wls, k_g):
    """beta (per wavelength) where R dips: a float64 scan of the Otto-coupled slab."""
    betas = np.linspace(1.0005, min(n0, n_g.real) - 1e-4, 4001)
    W, B = np.meshgrid(wls, betas, indexing="ij")
    W, B = W.ravel(), B.ravel()
    n0a = np.full(W.size, n0)
    case = Case(n0a, [(np.full(W.size, 1.0 + 0j), np.full(W.size, gap)),
                      (np.full(W.size, n_g + 1j * k_g), np.full(W.size, d_g))],
                np.full(W.size, n_ex + 0j), cos_from_beta(n0a, B), W)
    R, _ = run_core(case, Float64)
    R = R.reshape(len(wls), len(betas))
    i = np.argmin(R, axis=1)
    return betas[i]


def regime_guided(rng, N):
    """Guided modes: a lossless or nearly lossless high-index film (n = 2.2, 300 nm,
    k = 0 or 1e-4) between air (an Otto coupling gap of 600 nm under a prism
    n0 = 1.9) and air: R = 1 - (absorption at the mode) has dips a few 1e-5 wide
    in beta. Points are placed at the dips (found by a float64 scan at 1000
    wavelengths) +- log-uniform offsets in [1e-8, 1e-2] in beta."""
    n0, gap, n_g, d_g = 1.9, 600.0, 2.2, 300.0
    wls = rng.uniform(360, 830, 1000)
    k_g = 1e-4
    beta_mode = _guided_mode_positions(n0, gap, n_g, d_g, 1.0, wls, k_g)
    pick = rng.integers(0, len(wls), N)
    off = np.where(rng.random(N) < 0.1, 0.0, logu(rng, 1e-8, 1e-2, N) * rng.choice([-1, 1], N))
    beta = np.clip(beta_mode[pick] + off, 1.0, n0)
    kk = np.where(rng.random(N) < 0.5, k_g, 0.0)
    n0a = np.full(N, n0)
    films = [(np.full(N, 1.0 + 0j), np.full(N, gap)), (n_g + 1j * kk, np.full(N, d_g))]
    return Case(n0a, films, np.full(N, 1.0 + 0j), cos_from_beta(n0a, beta), wls[pick])


def regime_thick_absorbing(rng, N):
    """3 films of 100 um with k in {20, log-uniform [1e-4, 20]}, n in [1, 6]; any angle."""
    films = []
    for _ in range(3):
        k = np.where(rng.random(N) < 0.3, 20.0, logu(rng, 1e-4, 20.0, N))
        films.append((rng.uniform(1, 6, N) + 1j * k, np.full(N, 100_000.0)))
    return Case(np.ones(N), films, rng.uniform(1, 6, N) + 1j * rng.uniform(0, 20, N),
                rng.uniform(0, 1, N), rng.uniform(360, 830, N))


def regime_thick_lossless(rng, N):
    """3 lossless films of 20-100 um (n in [1, 6]) on glass: coherent fringes with
    phases up to 2 pi * 6 * 100 um / 360 nm ~ 1e4 rad; float32 cannot hold such a
    phase to better than ~1e4 * 6e-8 rad."""
    films = [(rng.uniform(1, 6, N) + 0j, rng.uniform(20_000, 100_000, N)) for _ in range(3)]
    return Case(np.ones(N), films, np.full(N, 1.52 + 0j), rng.uniform(0, 1, N),
                rng.uniform(360, 830, N))


def regime_bragg(rng, N):
    """30-layer Bragg mirror: 15 pairs TiO2-like 2.35 / SiO2-like 1.46, quarter wave
    at 550 nm, on glass 1.52, any angle and wavelength (band edges included)."""
    films = []
    for i in range(30):
        n = 2.35 if i % 2 == 0 else 1.46
        films.append((np.full(N, n + 0j), np.full(N, 550.0 / (4 * n))))
    return Case(np.ones(N), films, np.full(N, 1.52 + 0j), rng.uniform(0, 1, N),
                rng.uniform(360, 830, N))


def regime_metals(rng, N):
    """k = 20 metals: 3 metal films (n in [0.05, 2], k = 20 or in [1, 20]) 0-100 nm
    thick on a k = 20 substrate, any angle including grazing."""
    films = []
    for _ in range(3):
        k = np.where(rng.random(N) < 0.5, 20.0, rng.uniform(1, 20, N))
        films.append((rng.uniform(0.05, 2, N) + 1j * k, rng.uniform(0, 100, N)))
    cos0 = np.where(rng.random(N) < 0.1, logu(rng, 1e-7, 1e-2, N), rng.uniform(0, 1, N))
    return Case(np.ones(N), films, rng.uniform(0.05, 2, N) + 20j, cos0, rng.uniform(360, 830, N))


def regime_random30(rng, N):
    """30 random films, n in [1, 6], k in [0, 20], d in [0, 100 um] (a third exactly
    0), n0 in [1, 6] (TIR from inside dense media), any angle."""
    films = random_films(rng, N, 30)
    return Case(rng.uniform(1, 6, N), films, rng.uniform(1, 6, N) + 1j * rng.uniform(0, 20, N),
                rng.uniform(0, 1, N), rng.uniform(360, 830, N))


def regime_random30_lossless(rng, N):
    """As random-30 but lossless with 0-1 um films (R + T = 1 exactly)."""
    films = random_films(rng, N, 30, dmax=1000.0, lossless=True)
    return Case(rng.uniform(1, 6, N), films, rng.uniform(1, 6, N) + 0j,
                rng.uniform(0, 1, N), rng.uniform(360, 830, N))


def regime_real_on_metal(rng, N):
    """30 lossless films above the ambient (n in [1.3, 4], d in [0, 2 um]) on a metal
    (n in [0.05, 3], k in [1, 20]), any angle including grazing: the render
    kernels run such stacks through the real-amplitude loop."""
    films = [(rng.uniform(1.3, 4.0, N) + 0j, rng.uniform(0.0, 2000.0, N)) for _ in range(30)]
    cos0 = np.where(rng.random(N) < 0.1, logu(rng, 1e-7, 1e-2, N), rng.uniform(0, 1, N))
    return Case(np.ones(N), films, rng.uniform(0.05, 3.0, N) + 1j * rng.uniform(1, 20, N),
                cos0, rng.uniform(360, 830, N))


def regime_real_from_glass(rng, N):
    """Light from glass (n0 = 1.5) through 7 lossless films of n in [1.52, 4] onto
    air: total internal reflection at the exit beyond 41.8 degrees, with cos
    within 1e-8..1e-2 of that critical angle for a third of the points."""
    films = [(rng.uniform(1.52, 4.0, N) + 0j, rng.uniform(0.0, 1000.0, N)) for _ in range(7)]
    c_crit = cos_from_beta(1.5, 1.0)
    near = c_crit + rng.choice([-1.0, 1.0], N) * logu(rng, 1e-8, 1e-2, N)
    cos0 = np.where(rng.random(N) < 1 / 3, near, rng.uniform(0, 1, N))
    return Case(np.full(N, 1.5), films, np.full(N, 1.0 + 0j), np.clip(cos0, 0.0, 1.0),
                rng.uniform(360, 830, N))


REGIMES: dict[str, Callable] = {
    "normal (cos = 1), 7 films": regime_normal,
    "grazing (cos 0, 1e-7..1e-3)": regime_grazing,
    "critical angle +- 1e-8..1e-2": regime_critical,
    "TIR / FTIR from glass": regime_tir,
    "guided modes (Otto, at the dips)": regime_guided,
    "thick absorbing (100 um, k <= 20)": regime_thick_absorbing,
    "thick lossless (20-100 um)": regime_thick_lossless,
    "Bragg mirror, 30 layers": regime_bragg,
    "metals, k = 20": regime_metals,
    "random 30 films (n, k, d extreme)": regime_random30,
    "random 30 films, lossless, <= 1 um": regime_random30_lossless,
    "real films above n0, 30, on metals": regime_real_on_metal,
    "real films above n0, 7, from glass (exit TIR)": regime_real_from_glass,
}


# ---------------------------------------------------------------------------
# Evaluation
# ---------------------------------------------------------------------------
def real_hints(c: Case):
    """The trace-time hints with which the render kernels run a stack whose films
    are all real and above the ambient (``optics.stack_rt_loop_real``), or None."""
    if not c.films or any(np.any(np.imag(n) != 0) for n, _ in c.films):
        return None
    lo = min(float(np.min(np.real(n))) for n, _ in c.films)
    hi = max(float(np.max(np.real(n))) for n, _ in c.films)
    n0_max = float(np.max(c.n0))
    if not real_loop_applies(n0_max, lo):
        return None
    return dict(n0_max=n0_max, film_n_min=lo, film_n_max=hi, films_max=len(c.films))


def run_core(c: Case, Arr, loop: bool | str = False):
    """unpolarized_rt on Dr.Jit arrays of type Arr (Float or Float64): (R, T) as numpy.

    ``loop``: the form render kernels use for stacks of ``unpolarized.LOOP_MIN_FILMS``
    films or more, ``optics.stack_rt_loop``, with each lane's films gathered
    from film-major buffers (as ``render.loop.LoopFilms`` gathers a film's index),
    ``R = (Rs + Rp) / 2`` and ``T`` clipped to ``[0, 1 - R]`` as in the kernel;
    ``loop="real"``: the same with the hints of :func:`real_hints` (the
    real-amplitude loop the kernels use for real films above the ambient).
    """
    def real(a):
        x = Arr(np.ascontiguousarray(a, dtype=np.float64))
        dr.make_opaque(x)
        return x

    def cx(a):
        a = np.asarray(a, dtype=np.complex128)
        return Cx(real(a.real), real(a.imag))

    if loop:
        N = c.cos0.size
        pad = [np.zeros(N)]   # a gather needs a non-empty source, also for 0 films
        eta = real(np.concatenate([np.real(n) for n, _ in c.films] + pad))
        k = real(np.concatenate([np.imag(n) for n, _ in c.films] + pad))
        thk = real(np.concatenate([np.asarray(d, np.float64) for _, d in c.films] + pad))
        lane = dr.arange(UInt32, N)

        def film(j):
            i = j * N + lane
            return Cx(dr.gather(Arr, eta, i), dr.gather(Arr, k, i)), dr.gather(Arr, thk, i)

        count = UInt32(len(c.films))
        dr.make_opaque(count)
        hints = real_hints(c) if loop == "real" else {}
        Rs, Rp, Ts, Tp = stack_rt_loop(real(c.n0), real(c.cos0), count, film, cx(c.n_exit),
                                       real(c.wl), **hints)
        R = 0.5 * (Rs + Rp)
        T = dr.clip(0.5 * (Ts + Tp), 0.0, 1.0 - R)
    else:
        films = [(cx(n), real(d)) for n, d in c.films]
        R, T = unpolarized_rt(real(c.n0), real(c.cos0), films, cx(c.n_exit), real(c.wl), True)
    dr.eval(R, T)
    return np.array(R, dtype=np.float64), np.array(T, dtype=np.float64)


def run_tmm(c: Case, idx):
    """tmm's unpolarised R, T at the points idx (NaN where tmm is not defined)."""
    import tmm

    R = np.full(len(idx), np.nan)
    T = np.full(len(idx), np.nan)
    for j, i in enumerate(idx):
        cos0 = c.cos0[i]
        if cos0 <= 0.0:
            continue  # tmm divides by cos(theta0)
        n_list = [c.n0[i]] + [n[i] for n, _ in c.films] + [c.n_exit[i]]
        d_list = [np.inf] + [d[i] for _, d in c.films] + [np.inf]
        th = math.acos(cos0)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = tmm.coh_tmm("s", n_list, d_list, th, c.wl[i])
                p = tmm.coh_tmm("p", n_list, d_list, th, c.wl[i])
        except (ValueError, ZeroDivisionError, FloatingPointError, AssertionError):
            continue
        R[j] = 0.5 * (s["R"] + p["R"])
        T[j] = 0.5 * (s["T"] + p["T"])
    return R, T


def measure(name, make, rng, N, n_tmm):
    case = rounded(make(rng, N))
    t0 = time.perf_counter()
    R32, T32 = run_core(case, Float)
    R64, T64 = run_core(case, Float64)
    nonfinite = int(np.sum(~np.isfinite(R32)) + np.sum(~np.isfinite(T32)))
    out = int(np.sum((R32 < 0) | (R32 > 1) | (T32 < 0) | (T32 > 1) | (R32 + T32 > 1 + 1e-5)))
    err = np.maximum(np.abs(R32 - R64), np.abs(T32 - T64))
    worst = int(np.nanargmax(err))
    # Conditioning: the float64 change of R, T when every input moves by at most
    # its own float32 rounding (relative u = 2^-24, random signs, two draws).
    sens = np.zeros(N)
    for _ in range(2):
        Rp, Tp = run_core(perturbed(case, rng), Float64)
        sens = np.maximum(sens, np.maximum(np.abs(Rp - R64), np.abs(Tp - T64)))
    unexplained = int(np.sum(err > 4.0 * sens + 1e-5))
    lossless = (np.asarray(case.n_exit).imag == 0) & np.all(
        [np.asarray(n).imag == 0 for n, _ in case.films], axis=0)
    dev32 = np.abs(R32 + T32 - 1)[lossless]
    dev64 = np.abs(R64 + T64 - 1)[lossless]
    # The loop form (float32) against the same float64 reference.
    def loop_stats(form):
        RL, TL = run_core(case, Float, loop=form)
        errL = np.maximum(np.abs(RL - R64), np.abs(TL - T64))
        return {"nonfinite": int(np.sum(~np.isfinite(RL)) + np.sum(~np.isfinite(TL))),
                "out": int(np.sum((RL < 0) | (RL > 1) | (TL < 0) | (TL > 1)
                                  | (RL + TL > 1 + 1e-5))),
                "max": float(np.max(errL)), "p999": float(np.quantile(errL, 0.999)),
                "unexplained": int(np.sum(errL > 4.0 * sens + 1e-5)),
                "lossless": float(np.abs(RL + TL - 1)[lossless].max()) if lossless.any()
                else None}
    loop = loop_stats(True)
    # ... and the real-amplitude loop, where the kernels would use it
    loop_real = loop_stats("real") if real_hints(case) else None
    idx = rng.choice(N, size=min(n_tmm, N), replace=False)
    Rt, Tt = run_tmm(case, idx)
    ok = np.isfinite(Rt)
    e32 = np.maximum(np.abs(R32[idx] - Rt), np.abs(T32[idx] - Tt))[ok]
    e64 = np.maximum(np.abs(R64[idx] - Rt), np.abs(T64[idx] - Tt))[ok]
    return {
        "regime": name, "N": N, "nonfinite": nonfinite, "out": out,
        "max": float(np.max(err)), "p999": float(np.quantile(err, 0.999)),
        "sens_max": float(np.max(sens)), "sens_worst": float(sens[worst]),
        "unexplained": unexplained,
        "lossless": (int(lossless.sum()), float(dev32.max()) if dev32.size else None,
                     float(dev64.max()) if dev64.size else None),
        "tmm_n": int(ok.sum()), "tmm32": float(e32.max()) if ok.any() else None,
        "tmm64": float(e64.max()) if ok.any() else None,
        "worst": {"cos0": case.cos0[worst], "wl": case.wl[worst], "n0": case.n0[worst],
                  "R32": R32[worst], "R64": R64[worst], "T32": T32[worst], "T64": T64[worst]},
        "loop": loop,
        "loop_real": loop_real,
        "seconds": time.perf_counter() - t0,
        "lossless_dev": None,
    }


def lossless_cell(v):
    n, a, b = v
    return "none" if n == 0 else f"{n}: {a:.1e} / {b:.1e}"


def fmt(x):
    return "n/a" if x is None else f"{x:.1e}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--tmm-points", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--only", default=None, help="run only regimes whose name contains this")
    ap.add_argument("--worst", action="store_true", help="also print the worst point per regime")
    args = ap.parse_args(argv)
    require_llvm()
    rng = np.random.default_rng(args.seed)
    print(f"drjit {dr.__version__}, LLVM {'.'.join(map(str, dr.detail.llvm_version()))}, "
          f"{dr.thread_count()} threads; float32 unpolarized.unpolarized_rt vs the float64 run of the "
          f"same code on the same float32-rounded inputs; tmm on {args.tmm_points} random points "
          "per regime")
    print()
    head = ("| regime | points | non-finite | out of range | max err vs f64 | 99.9% err vs f64 "
            "| max input-rounding sensitivity | err > 4 sens + 1e-5 "
            "| lossless points: max abs(1 - R - T) f32 / f64 "
            "| tmm points | max err f32 vs tmm | max err f64 vs tmm |")
    print(head)
    print("|" + "---|" * 12)
    t0 = time.perf_counter()
    rows = []
    for name, make in REGIMES.items():
        if args.only and args.only not in name:
            continue
        r = measure(name, make, rng, args.points, args.tmm_points)
        rows.append(r)
        print(f"| {name} | {r['N']} | {r['nonfinite']} | {r['out']} | {r['max']:.1e} | "
              f"{r['p999']:.1e} | {r['sens_max']:.1e} | {r['unexplained']} | "
              f"{lossless_cell(r['lossless'])} | "
              f"{r['tmm_n']} | {fmt(r['tmm32'])} | {fmt(r['tmm64'])} |",
              flush=True)
    print()
    for key, title in (
            ("loop", "The loop over films (optics.stack_rt_loop: render kernels for stacks of "
                     "unpolarized.LOOP_MIN_FILMS films or more), float32, against the same float64 "
                     "reference:"),
            ("loop_real", "The real-amplitude loop (optics.stack_rt_loop_real: render kernels "
                          "whose films are all real and above the ambient, at any depth), on "
                          "the regimes that qualify:")):
        print(title)
        print()
        print("| regime | non-finite | out of range | max err vs f64 | 99.9% err vs f64 "
              "| err > 4 sens + 1e-5 | lossless: max abs(1 - R - T) f32 |")
        print("|" + "---|" * 7)
        for r in rows:
            L = r[key]
            if L is not None:
                print(f"| {r['regime']} | {L['nonfinite']} | {L['out']} | {L['max']:.1e} | "
                      f"{L['p999']:.1e} | {L['unexplained']} | {fmt(L['lossless'])} |")
        print()
    print(f"total {time.perf_counter() - t0:.0f} s")
    if args.worst:
        for r in rows:
            w = r["worst"]
            print(f"worst {r['regime']}: " + ", ".join(f"{k}={v:.9g}" for k, v in w.items())
                  + f", sensitivity there {r['sens_worst']:.2g}")
    return rows


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("stability"):   # --write-docs: docs/_generated/stability.md
        ok = main()
    sys.exit(0 if ok else 1)
