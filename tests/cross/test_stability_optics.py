"""Property tests of the optics core on extreme inputs (hypothesis).

Stacks of 1-30 films with n in [1, 6], k in [0, 20], d in [0, 100 um] (exactly
0 included), angles including normal, grazing (cos = 1e-7 and exactly 0), the
critical angles of the stack +- a tiny offset, light coming from inside a dense
dielectric (TIR), wavelengths 360-830 nm; float32 (drjit.llvm.Float) and
float64 (drjit.llvm.Float64). Properties: every output finite, 0 <= R, T <= 1,
R + T <= 1 + 1e-5, and R + T = 1 for lossless stacks. Both forms of the
recursion are checked: unrolled (``optics.stack_rt``) and the loop over films of
the render kernels (``optics.stack_rt_loop``).

To keep the number of compiled kernels small (hypothesis draws many stacks),
every example is evaluated with opaque array inputs and the film count is drawn
from a few values; one example evaluates a whole batch of angles.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest
from drjit.llvm import Float, Float64
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from tests.support.kernels import loop_rt
from thinfilm_mi.optics import core as optics
from thinfilm_mi.optics.unpolarized import unpolarized_rt, unpolarized_rt_loop

FILM_COUNTS = (1, 2, 7, 30)

index = st.tuples(st.floats(1.0, 6.0), st.one_of(st.just(0.0), st.floats(0.0, 20.0)))
thickness = st.one_of(st.just(0.0), st.floats(0.0, 100.0), st.floats(0.0, 100_000.0))


@st.composite
def stacks(draw, lossless=False):
    L = draw(st.sampled_from(FILM_COUNTS))
    films = []
    for _ in range(L):
        n, k = draw(index)
        films.append((complex(n, 0.0 if lossless else k), draw(thickness)))
    n0 = draw(st.one_of(st.just(1.0), st.floats(1.0, 6.0)))  # > 1: TIR from inside
    ne, ke = draw(index)
    n_exit = complex(ne, 0.0 if lossless else ke)
    wl = draw(st.floats(360.0, 830.0))
    return n0, films, n_exit, wl


def angles(n0, films, n_exit):
    """Normal, grazing, random, and every critical angle of the stack +- tiny;
    returns (cos, mask of the near-critical ones)."""
    cos = [1.0, 0.0, 1e-7, 1e-4, 0.5, 0.9]
    near = [False] * len(cos)
    for n, _ in list(films) + [(n_exit, 0.0)]:
        n = complex(n)
        if n.imag == 0 and n.real < n0:
            s = n.real / n0
            c = math.sqrt((1 - s) * (1 + s))
            for dc in (0.0, 1e-7, -1e-7, 1e-6, -1e-6, 1e-3):
                cos.append(min(max(c + dc, 0.0), 1.0))
                near.append(True)
    return np.array(cos), np.array(near)


def evaluate(Arr, n0, films, n_exit, wl, cos0):
    size = cos0.size

    def arr(v):
        a = Arr(np.full(size, v, dtype=np.float64))
        dr.make_opaque(a)
        return a

    f = [(optics.Cx(arr(complex(n).real), arr(complex(n).imag)), arr(d)) for n, d in films]
    ne = optics.Cx(arr(n_exit.real), arr(n_exit.imag))
    c = Arr(cos0)
    dr.make_opaque(c)
    out = optics.stack_rt(arr(n0), c, f, ne, arr(wl))
    amp = optics.stack_amplitudes(arr(n0), c, f, ne, arr(wl))
    # The loop over films of the render kernels (unpolarized.LOOP_MIN_FILMS), its
    # films gathered from buffers.
    n, k, d = (np.array([v(film) for film in films], np.float64)
               for v in (lambda x: complex(x[0]).real, lambda x: complex(x[0]).imag,
                         lambda x: x[1]))
    looped = [loop_rt(arr(n0), c, n, k, d, ne, arr(wl), Arr)]
    hints = real_hints(n0, films)
    if hints:   # the kernels' loop for real films above the ambient (real amplitudes)
        looped.append(loop_rt(arr(n0), c, n, k, d, ne, arr(wl), Arr, **hints))
    leaves = [np.array(x, np.float64) for x in out]
    for z in (amp.rs, amp.rp, amp.ts, amp.tp):
        leaves += [np.array(z.re, np.float64), np.array(z.im, np.float64)]
    return [leaves[:4]] + [[np.array(x, np.float64) for x in lp] for lp in looped], leaves[4:]


def real_hints(n0, films):
    """The trace-time hints with which the kernels run their loop over real films
    (``optics.stack_rt_loop_real``), or ``None`` where the films do not qualify."""
    n = [complex(f[0]) for f in films]
    if not n or any(x.imag != 0 for x in n):
        return None
    lo, hi = min(x.real for x in n), max(x.real for x in n)
    if not optics.real_loop_applies(n0, lo):
        return None
    return dict(n0_max=n0, film_n_min=lo, film_n_max=hi, films_max=len(n))


# Tolerances. Away from critical angles every Rouard step conserves flux to a
# few ulp, so |R + T - 1| <~ 31 interfaces * few eps: 1e-9 (float64) and 1e-5
# (float32) are loose. At (or within 1e-3 in cos of) the critical angle of a
# film, q is known only to ~sqrt(eps) |n| (q^2 = n^2 - beta^2 is rounded to eps
# n^2) and the core floors it at eps_q = 2 sqrt(eps)(|n| + beta); the step
# (r + gamma E)/(1 + r gamma E) then cancels to a relative precision of
# ~eps / eps_q ~ sqrt(eps) / 2: 1.2e-4 in float32 per such film (1e-8 in
# float64). We allow 5e-4 (float32) and 1e-7 (float64) there.
TOL = {Float64: 1e-9, Float: 1e-5}
TOL_CRITICAL = {Float64: 1e-7, Float: 5e-4}

SETTINGS = settings(max_examples=8, deadline=None, derandomize=True,
                    phases=(Phase.explicit, Phase.reuse, Phase.generate),  # no slow shrinking
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def check(Arr, stack, lossless):
    n0, films, n_exit, wl = stack
    cos0, near = angles(n0, films, n_exit)
    powers, amps = evaluate(Arr, n0, films, n_exit, wl, cos0)
    for v in amps:
        assert np.all(np.isfinite(v))
    for Rs, Rp, Ts, Tp in powers:   # unrolled, the loop over films (and its real form)
        check_powers(Arr, Rs, Rp, Ts, Tp, cos0, near, lossless)


def check_powers(Arr, Rs, Rp, Ts, Tp, cos0, near, lossless):
    for name, v in zip(("Rs", "Rp", "Ts", "Tp"), (Rs, Rp, Ts, Tp)):
        assert np.all(np.isfinite(v)), (name, v)
        assert np.all((v >= 0) & (v <= 1)), (name, v)
    # R + T <= 1 + tol: the clamps keep each of R, T in [0, 1], the sum is only
    # as exact as the arithmetic (see TOL above).
    tol = np.where(near, TOL_CRITICAL[Arr], TOL[Arr])
    assert np.all(Rs + Ts <= 1 + tol) and np.all(Rp + Tp <= 1 + tol)
    graze = cos0 == 0
    assert np.all(Rs[graze] == 1) and np.all(Ts[graze] == 0)
    if lossless:
        assert np.all(np.abs(Rs + Ts - 1) <= tol), np.max(np.abs(Rs + Ts - 1))
        assert np.all(np.abs(Rp + Tp - 1) <= tol), np.max(np.abs(Rp + Tp - 1))


#: Examples per property and precision. float64 runs the same (array-generic)
#: code as the float32 kernels and is what the table builds run, on physical
#: inputs; its examples compile the slowest kernels (the films unrolled in
#: float64: the lossless property took 60 s at 8 examples, a tenth of the
#: suite), so it draws 4 of the same derandomised sequence of stacks.
EXAMPLES = {Float: 8, Float64: 4}


def _check_examples(Arr, strategy, lossless):
    @settings(SETTINGS, max_examples=EXAMPLES[Arr])
    @given(stack=strategy)
    def run(stack):
        check(Arr, stack, lossless=lossless)
    run()


@pytest.mark.parametrize("Arr", [Float, Float64], ids=["float32", "float64"])
def test_absorbing_stacks_stay_physical(Arr):
    _check_examples(Arr, stacks(), lossless=False)


@pytest.mark.parametrize("Arr", [Float, Float64], ids=["float32", "float64"])
def test_lossless_stacks_conserve_energy(Arr):
    _check_examples(Arr, stacks(lossless=True), lossless=True)


@pytest.mark.parametrize("Arr", [Float, Float64], ids=["float32", "float64"])
def test_adjacent_layers_both_at_q_zero(Arr):
    """Two neighbouring films of the same index n = n0 sin(theta) both have q = 0
    exactly: the interface between them must be transparent, not 0/0."""
    n0 = 2.0
    cos0 = np.array([math.sqrt(0.75), 0.1, 1.0])  # sin = 1/2: beta = 1 = n of both films
    films = [(1.0, 50.0), (1.0, 80.0), (1.5, 100.0)]
    powers, amps = evaluate(Arr, n0, films, 1.5 + 0j, 500.0, cos0)
    # the same stack with the two films merged into one 130 nm film
    merged, _ = evaluate(Arr, n0, [(1.0, 130.0), (1.5, 100.0)], 1.5 + 0j, 500.0, cos0)
    for v in amps:
        assert np.all(np.isfinite(v))
    # at q = 0 the core floors q at eps_q (see TOL_CRITICAL above): float32
    # agrees to ~sqrt(eps) there.
    tol = 1e-12 if Arr is Float64 else TOL_CRITICAL[Float]
    for (Rs, Rp, Ts, Tp), (Rs2, _, _, Tp2) in zip(powers[:2], merged):  # unrolled, loop
        for v in (Rs, Rp, Ts, Tp):
            assert np.all(np.isfinite(v))
        np.testing.assert_allclose(Rs, Rs2, atol=tol)
        np.testing.assert_allclose(Tp, Tp2, atol=tol)


# ---------------------------------------------------------------------------
# float32 against float64, per point, within a documented conditioning bound
# (benchmarks/stability.py and benchmarks/STABILITY.md measure the same bound on
# 10^6 points per regime)
# ---------------------------------------------------------------------------
U32 = 2.0 ** -24


def _unpolarised(Arr, n0, films, n_exit, wl, cos0, loop=False):
    """Unpolarised R, T as the kernels form them: ``unpolarized_rt`` (films unrolled)
    or, with ``loop``, ``unpolarized_rt_loop`` (``optics.stack_rt_loop`` with R =
    (Rs + Rp) / 2 and T clipped to [0, 1 - R]) over buffers of the (per-point
    constant) films;
    ``loop="real"`` passes the hints of real films (:func:`real_hints`)."""
    size = cos0.size

    def arr(v):
        a = Arr(np.ascontiguousarray(np.broadcast_to(v, (size,)), dtype=np.float64))
        dr.make_opaque(a)
        return a

    ne = optics.Cx(arr(np.real(n_exit)), arr(np.imag(n_exit)))
    if loop:
        n, k, d = (np.array([g(n, d) for n, d in films], np.float64)
                   for g in (lambda n, d: np.real(n), lambda n, d: np.imag(n), lambda n, d: d))
        hints = real_hints(n0, films) if loop == "real" else {}
        R, T = loop_rt(arr(n0), arr(cos0), n, k, d, ne, arr(wl), Arr, rt=unpolarized_rt_loop,
                       **hints)
    else:
        f = [(optics.Cx(arr(np.real(n)), arr(np.imag(n))), arr(d)) for n, d in films]
        R, T = unpolarized_rt(arr(n0), arr(cos0), f, ne, arr(wl), True)
    dr.eval(R, T)
    return np.array(R, np.float64), np.array(T, np.float64)


def _r32(x):
    """Round to float32 (complex: both parts), back as float64 / complex128."""
    x = np.asarray(x)
    if np.iscomplexobj(x):
        return x.real.astype(np.float32).astype(np.float64) + 1j * x.imag.astype(np.float32)
    return x.astype(np.float32).astype(np.float64)


def float32_bound(n0, films, n_exit, wl, cos0, R64, T64):
    """Documented bound on max(|R32 - R64|, |T32 - T64|) per point.

    * 2e-5: ~31 interface steps of a few ulp each;
    * 16 u sum_j 2 pi |Re q_j| d_j / lambda: the phase of film j is formed with a
      relative error of a few u, i.e. an absolute error ~ u * phase, and
      |dR/d delta| <~ 4 (test_float32_thick_films_bound in tests/optics/test_core.py);
    * 4x the float64 change of R, T when every medium gets an absorption k = 4u|n|
      (rounding in the recursion acts like a loss of relative size u, amplified
      by resonances: guided modes, Fabry-Perot), when cos0 moves by 4u
      relative, and when every n^2 moves by 8u (|n|^2 + beta^2) (the rounding of
      q^2 = n^2 - beta^2 and the core's floor of q at 2 sqrt(u)(|n| + beta));
    * within 1e-2 in cos of a critical angle (and below cos0 = 1e-3), where q of
      a medium is known only to ~sqrt(u)|n| and none of the above is a small
      perturbation: at least 0.2. Measured on 10^6 points per regime
      (benchmarks/STABILITY.md): 9.2e-2 at a critical angle and 1.8e-1 at
      cos0 = 3.9e-5, where the float64 result itself moves by 0.13 and 0.16
      when the inputs move by their own float32 rounding (ill-conditioned, not
      unstable).
    """
    beta2 = n0 * n0 * (1 - cos0) * (1 + cos0)
    phase = np.zeros(cos0.size)
    for n, d in films:
        q = np.sqrt(complex(n) ** 2 - beta2 + 0j)
        phase += 2 * np.pi * np.abs(q.real) * d / wl
    # All perturbed stacks in one float64 call (one kernel): per-lane indices.
    N = cos0.size

    def shift(n, sg):
        n = complex(n)
        return np.sqrt(n * n + sg * 8 * U32 * (np.abs(n) ** 2 + beta2) + 0j)

    variants = [  # (film indices, exit index, cos0), each per lane
        ([np.full(N, complex(n) + 4j * U32 * abs(complex(n))) for n, _ in films],
         np.full(N, complex(n_exit) + 4j * U32 * abs(complex(n_exit))), cos0)]
    for sg in (-1.0, 1.0):
        variants.append(([np.full(N, complex(n)) for n, _ in films], np.full(N, complex(n_exit)),
                         np.clip(cos0 * (1 + sg * 4 * U32), 0, 1)))
        variants.append(([shift(n, sg) for n, _ in films], shift(n_exit, sg), cos0))
    V = len(variants)
    fl = [(np.concatenate([v[0][j] for v in variants]), d) for j, (_, d) in enumerate(films)]
    R, T = _unpolarised(Float64, n0, fl, np.concatenate([v[1] for v in variants]),
                        np.tile(wl, V), np.concatenate([v[2] for v in variants]))
    sens = np.max(np.maximum(np.abs(R.reshape(V, N) - R64), np.abs(T.reshape(V, N) - T64)),
                  axis=0)
    bound = 2e-5 + 16 * U32 * phase + 4 * sens
    near = cos0 < 1e-3
    for n in [complex(n) for n, _ in films] + [complex(n_exit)]:
        if n.imag == 0 and n.real < n0:
            s = n.real / n0
            near |= np.abs(cos0 - math.sqrt((1 - s) * (1 + s))) < 1e-2
    return np.where(near, np.maximum(bound, 0.2), bound)


@st.composite
def real_stacks(draw):
    """Stacks the kernels run through the real-amplitude loop: every film real and
    above the ambient (REAL_LOOP_MARGIN), over any exit medium."""
    L = draw(st.sampled_from(FILM_COUNTS))
    n0 = draw(st.one_of(st.just(1.0), st.floats(1.0, 3.0)))
    lo = optics.REAL_LOOP_MARGIN * n0 * (1.0 + 1e-6)
    films = [(complex(draw(st.floats(lo, 6.0)), 0.0), draw(thickness)) for _ in range(L)]
    ne, ke = draw(index)
    return n0, films, complex(ne, ke), draw(st.floats(360.0, 830.0))


@SETTINGS
@given(stack=real_stacks())
def test_real_films_stay_physical(stack):
    """Every form, the real-amplitude loop included (lossless films over any exit)."""
    check(Float, stack, lossless=stack[2].imag == 0)


@SETTINGS
@given(stack=real_stacks())
def test_float32_error_within_documented_bound_real_films(stack):
    test_float32_error_within_documented_bound.hypothesis.inner_test(stack)


@SETTINGS
@given(stack=stacks())
def test_float32_error_within_documented_bound(stack):
    n0, films, n_exit, wl = stack
    cos0, _ = angles(n0, films, n_exit)
    rng = np.random.default_rng(len(films))
    cos0 = np.concatenate([cos0, rng.uniform(0, 1, 32)])
    # float32-rounded inputs for both, so that the error is that of the arithmetic
    n0, wl, n_exit = float(_r32(n0)), np.full(cos0.size, float(_r32(wl))), complex(_r32(n_exit))
    films = [(complex(_r32(complex(n))), float(_r32(d))) for n, d in films]
    cos0 = _r32(cos0)
    R64, T64 = _unpolarised(Float64, n0, films, n_exit, wl, cos0)
    bound = float32_bound(n0, films, n_exit, wl, cos0, R64, T64)
    forms = (False, True, "real") if real_hints(n0, films) else (False, True)
    for loop in forms:   # every form the kernels use
        R32, T32 = _unpolarised(Float, n0, films, n_exit, wl, cos0, loop=loop)
        err = np.maximum(np.abs(R32 - R64), np.abs(T32 - T64))
        assert np.all(err <= bound), (loop, err.max(), cos0[np.argmax(err - bound)])
