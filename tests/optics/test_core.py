"""The optics core (thinfilm_mi/optics/core.py) against closed forms, physics and tmm:
the recursion unrolled and as a symbolic loop over the films (``optics.stack_rt_loop``
and its real-amplitude form, with the rescaling bound), 1000 films in float64 against
tmm, float32 error bounds, and ``sqrt_decaying``'s derivative at zero loss."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tmm
from drjit.llvm import Float, Float64

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi as tf  # noqa: E402
from tests.support.kernels import loop_rt
from thinfilm_mi.materials.stack import MAX_FILMS  # noqa: E402
from thinfilm_mi.optics import core as optics
from thinfilm_mi.optics.core import Cx

EPS32 = 2.0 ** -24  # float32 unit roundoff


# --------------------------------------------------------------------------
# Independent references (numpy complex128)
# --------------------------------------------------------------------------
def q_ref(n, n0, theta):
    """n cos(theta_j) = sqrt(n^2 - n0^2 sin^2 theta), the decaying root."""
    q = np.sqrt(np.complex128(n) ** 2 - (n0 * np.sin(theta)) ** 2 + 0j)
    if q.imag < 0 or (q.imag == 0 and q.real < 0):
        q = -q
    return q


def fresnel_ref(pol, na, nb, qa, qb):
    """Interface amplitudes in tmm's sign convention (r_p = -r_s at normal incidence)."""
    if pol == "s":
        return (qa - qb) / (qa + qb), 2 * qa / (qa + qb)
    # n cos = q  =>  (nb cos_a - na cos_b) = (nb^2 qa - na^2 qb) / (na nb)
    den = nb ** 2 * qa + na ** 2 * qb
    return (nb ** 2 * qa - na ** 2 * qb) / den, 2 * na * nb * qa / den


def power_factor(pol, n_exit, q_exit, q0):
    if pol == "s":
        return q_exit.real / q0
    return (n_exit ** 2 * np.conj(q_exit)).real / abs(n_exit) ** 2 / q0


def airy_ref(pol, n0, n1, d, n2, theta, wl):
    """Closed-form single film: r = (r01 + r12 e^{2i delta}) / (1 + r01 r12 e^{2i delta})."""
    q0, q1, q2 = n0 * np.cos(theta), q_ref(n1, n0, theta), q_ref(n2, n0, theta)
    r01, t01 = fresnel_ref(pol, n0, n1, q0, q1)
    r12, t12 = fresnel_ref(pol, n1, n2, q1, q2)
    delta = 2 * np.pi * q1 * d / wl
    den = 1 + r01 * r12 * np.exp(2j * delta)
    r = (r01 + r12 * np.exp(2j * delta)) / den
    t = t01 * t12 * np.exp(1j * delta) / den
    return r, t, abs(r) ** 2, abs(t) ** 2 * power_factor(pol, n2, q2, q0)


def bare_ref(pol, n0, n2, theta):
    q0, q2 = n0 * np.cos(theta), q_ref(n2, n0, theta)
    r, t = fresnel_ref(pol, n0, n2, q0, q2)
    return r, t, abs(r) ** 2, abs(t) ** 2 * power_factor(pol, n2, q2, q0)


# --------------------------------------------------------------------------
# Calling the core
# --------------------------------------------------------------------------
def _arr(v, Arr, size):
    a = Arr(np.broadcast_to(np.asarray(v, dtype=np.float64), (size,)).copy())
    dr.make_opaque(a)  # opaque inputs: one kernel per stack *shape*, not per value
    return a


def _idx(v, Arr, size, literal):
    """A complex index: a literal (the trace-time specialised path) or a Cx of
    opaque arrays (the general path, as in the render kernels)."""
    if literal:
        return complex(v)
    v = np.asarray(v, dtype=np.complex128)
    return optics.Cx(_arr(v.real, Arr, size), _arr(v.imag, Arr, size))


def core(n0, cos0, films, n_exit, wl, Arr=Float64, literal=True):
    """Run stack_amplitudes and stack_rt; return numpy arrays (complex amplitudes,
    powers from stack_rt, and powers formed from the amplitudes).

    Any parameter may be a numpy array (one value per point) when ``literal`` is
    false; with ``literal`` the indices, thicknesses and n0 must be scalars and
    are traced as constants."""
    size = np.broadcast(np.asarray(cos0), np.asarray(wl)).size
    for n, d in films:
        size = max(size, np.size(n), np.size(d))
    size = max(size, np.size(n_exit), np.size(n0))
    cos0_a, wl_a = _arr(cos0, Arr, size), _arr(wl, Arr, size)
    if literal:
        n0_a = float(n0)
        f = [(complex(n), float(d)) for n, d in films]
    else:
        n0_a = _arr(n0, Arr, size)
        f = [(_idx(n, Arr, size, False), _arr(d, Arr, size)) for n, d in films]
    ne = _idx(n_exit, Arr, size, literal)
    a = optics.stack_amplitudes(n0_a, cos0_a, f, ne, wl_a)
    Rs, Rp, Ts, Tp = optics.stack_rt(n0_a, cos0_a, f, ne, wl_a)
    zero = dr.zeros(Arr, size)
    out = {}
    for k in ("rs", "rp", "ts", "tp", "q_exit"):
        z = getattr(a, k)
        out[k] = np.array(z.re + zero, np.float64) + 1j * np.array(z.im + zero, np.float64)
    for k, v in zip(("Rs", "Rp", "Ts", "Tp"), (Rs, Rp, Ts, Tp)):
        out[k] = np.array(v + zero, np.float64)
    # powers from the amplitudes as well (the route a plugin using
    # stack_amplitudes takes)
    q0 = np.broadcast_to(np.asarray(n0, np.float64) * np.array(cos0_a, np.float64), (size,))
    qe = out["q_exit"]
    ne_c = np.broadcast_to(np.asarray(n_exit, np.complex128), (size,))
    with np.errstate(divide="ignore", invalid="ignore"):
        out["Ts_amp"] = np.where(q0 > 0, abs(out["ts"]) ** 2 * qe.real / q0, 0.0)
        out["Tp_amp"] = np.where(q0 > 0, abs(out["tp"]) ** 2 * (ne_c ** 2 * np.conj(qe)).real
                                 / abs(ne_c) ** 2 / q0, 0.0)
    return out


def batched(cases, **kw):
    """Evaluate many stacks with one kernel per number of films: ``cases`` is a
    list of (n0, films, n_exit, cos0 array, wl array); returns a list of the
    per-case result dicts."""
    groups = {}
    for i, c in enumerate(cases):
        groups.setdefault(len(c[1]), []).append(i)
    results = [None] * len(cases)
    for L, idx in groups.items():
        sizes = [np.size(np.broadcast(np.asarray(cases[i][3]), np.asarray(cases[i][4]))) for i in idx]
        rep = lambda vals: np.concatenate([np.full(s, v) for v, s in zip(vals, sizes)])
        n0 = rep([cases[i][0] for i in idx])
        films = [(rep([complex(cases[i][1][j][0]) for i in idx]),
                  rep([float(cases[i][1][j][1]) for i in idx])) for j in range(L)]
        ne = rep([complex(cases[i][2]) for i in idx])
        cos0 = np.concatenate([np.broadcast_to(cases[i][3], (s,)) for i, s in zip(idx, sizes)])
        wl = np.concatenate([np.broadcast_to(cases[i][4], (s,)) for i, s in zip(idx, sizes)])
        out = core(n0, cos0, films, ne, wl, literal=False, **kw)
        start = 0
        for i, s in zip(idx, sizes):
            results[i] = {k: v[start:start + s] for k, v in out.items()}
            start += s
    return results


# --------------------------------------------------------------------------
# Closed forms
# --------------------------------------------------------------------------
FILMS = [1.38, 2.3 + 0.4j, 0.2 + 3.4j]          # dielectric, absorbing, metal
SUBSTRATES = [1.52, 0.17 + 3.1j, 4.0 + 0.05j]   # glass, metal, absorbing semiconductor


@pytest.mark.parametrize("n1", FILMS)
@pytest.mark.parametrize("n2", SUBSTRATES)
@pytest.mark.parametrize("literal", [True, False])
def test_single_film_matches_airy_formula(n1, n2, literal):
    n0, d = 1.0, 137.0
    thetas = np.radians([0.0, 20.0, 45.0, 70.0, 85.0])
    wls = np.array([400.0, 550.0, 700.0])
    th, wl = (x.ravel() for x in np.meshgrid(thetas, wls))
    got = core(n0, np.cos(th), [(n1, d)], n2, wl, literal=literal)
    for pol in "sp":
        ref = np.array([airy_ref(pol, n0, n1, d, n2, a, w) for a, w in zip(th, wl)])
        # float64 both sides, a handful of operations: agreement to ~100 ulp.
        np.testing.assert_allclose(got["r" + pol], ref[:, 0], rtol=0, atol=1e-13)
        np.testing.assert_allclose(got["t" + pol], ref[:, 1], rtol=0, atol=1e-13)
        np.testing.assert_allclose(got["R" + pol], ref[:, 2].real, rtol=0, atol=1e-13)
        np.testing.assert_allclose(got["T" + pol], ref[:, 3].real, rtol=0, atol=1e-13)
        np.testing.assert_allclose(got["T" + pol + "_amp"], ref[:, 3].real, rtol=0, atol=1e-13)


@pytest.mark.parametrize("wl", [400.0, 550.0, 800.0])
def test_quarter_wave_antireflection(wl):
    ns = 1.52
    n1 = math.sqrt(ns)
    got = core(1.0, 1.0, [(n1, wl / (4 * n1))], ns, wl)
    bare = core(1.0, 1.0, [], ns, wl)
    assert bare["Rs"][0] == pytest.approx(((ns - 1) / (ns + 1)) ** 2, abs=1e-15)
    # exact zero up to rounding of a few float64 operations
    assert got["Rs"][0] < 1e-28 and got["Rp"][0] < 1e-28
    assert got["Ts"][0] == pytest.approx(1.0, abs=1e-14)


@pytest.mark.parametrize("theta_deg", [0.0, 30.0, 60.0])
@pytest.mark.parametrize("n1", [2.1, 1.25, 2.0 + 0.0j])
def test_half_wave_layer_is_absent(theta_deg, n1):
    th = math.radians(theta_deg)
    wl, ns = 550.0, 1.52 + 0.01j
    q1 = q_ref(n1, 1.0, th).real
    got = core(1.0, math.cos(th), [(n1, wl / (2 * q1))], ns, wl)
    bare = core(1.0, math.cos(th), [], ns, wl)
    for k in ("rs", "rp", "Rs", "Rp", "Ts", "Tp"):
        # a half-wave lossless film has E = exp(2i delta) = 1: the film vanishes
        # from r; t picks up e^{i delta} = -1 (phase only).
        np.testing.assert_allclose(abs(got[k]), abs(bare[k]), rtol=0, atol=1e-13)
    np.testing.assert_allclose(got["rs"], bare["rs"], atol=1e-13)


@pytest.mark.parametrize("n1,n2", [(1.0, 1.5), (1.5, 1.0), (1.33, 2.4)])
def test_brewster_angle(n1, n2):
    tb = math.atan(n2 / n1)
    got = core(n1, math.cos(tb), [], n2, 500.0)
    assert got["Rp"][0] < 1e-28
    assert got["Rs"][0] > 0.01
    # and the closed form away from Brewster
    got = core(n1, math.cos(tb - 0.3), [], n2, 500.0)
    np.testing.assert_allclose(got["Rp"][0], bare_ref("p", n1, n2, tb - 0.3)[2], atol=1e-14)


def test_total_internal_reflection_and_phase():
    n1, n2 = 1.5, 1.0
    tc = math.asin(n2 / n1)
    th = np.linspace(tc + 1e-3, math.radians(89.0), 25)
    for literal in (True, False):
        got = core(n1, np.cos(th), [], n2, 550.0, literal=literal)
        np.testing.assert_allclose(got["Rs"], 1.0, atol=1e-14)
        np.testing.assert_allclose(got["Rp"], 1.0, atol=1e-14)
        assert np.all(got["Ts"] == 0.0) and np.all(got["Tp"] == 0.0)
        # Phase of r_s: with exp(-i w t) and the decaying root q2 = i kappa,
        # r_s = (q1 - i kappa)/(q1 + i kappa) = exp(-2i arctan(kappa / q1)), i.e.
        # arg r_s = -2 arctan(sqrt(sin^2 - (n2/n1)^2) / cos) (a phase *lag*).
        phi_s = -2 * np.arctan(np.sqrt(np.sin(th) ** 2 - (n2 / n1) ** 2) / np.cos(th))
        np.testing.assert_allclose(np.angle(got["rs"]), phi_s, atol=1e-12)
        # r_p in tmm's convention: (n2^2 q1 - n1^2 i kappa)/(n2^2 q1 + n1^2 i kappa)
        phi_p = -2 * np.arctan((n1 / n2) ** 2 * np.sqrt(np.sin(th) ** 2 - (n2 / n1) ** 2) / np.cos(th))
        np.testing.assert_allclose(np.angle(got["rp"]), phi_p, atol=1e-12)


def test_frustrated_total_internal_reflection():
    n, gap = 1.5, 1.0
    th = math.radians(60.0)  # beyond the critical angle 41.8 deg
    wl = 550.0
    Ts = []
    for d in (20.0, 100.0, 300.0, 1000.0):
        got = core(n, math.cos(th), [(gap, d)], n, wl)
        for pol in "sp":
            R, T = got["R" + pol][0], got["T" + pol][0]
            assert T > 0
            assert R + T == pytest.approx(1.0, abs=1e-13)
            ref = airy_ref(pol, n, gap, d, n, th, wl)
            assert R == pytest.approx(ref[2], abs=1e-13)
            assert T == pytest.approx(ref[3], abs=1e-13)
        Ts.append(got["Ts"][0])
    assert Ts[0] > Ts[1] > Ts[2] > Ts[3] > 0
    # tunnelling: T falls off as exp(-2 kappa k0 d) once the gap is thick; the
    # multiple-reflection denominator |1 - r^2 exp(-2 kappa k0 d)|^2 still changes
    # ln T by ~2 exp(-2 kappa k0 300) ~ 7e-3 between 300 and 1000 nm, i.e. the
    # slope by ~1e-5 (5e-4 relative): hence rel=2e-3.
    kappa = math.sqrt((n * math.sin(th)) ** 2 - gap ** 2)
    slope = math.log(Ts[3] / Ts[2]) / 700.0
    assert slope == pytest.approx(-2 * kappa * 2 * math.pi / wl, rel=2e-3)


@pytest.mark.parametrize("n1", [1.9, 0.2 + 3.4j])
def test_zero_thickness_limit(n1):
    th = np.radians([0.0, 40.0, 80.0])
    bare = core(1.0, np.cos(th), [], 1.5 + 0.2j, 500.0)
    zero = core(1.0, np.cos(th), [(n1, 0.0)], 1.5 + 0.2j, 500.0)
    tiny = core(1.0, np.cos(th), [(n1, 1e-6)], 1.5 + 0.2j, 500.0)
    for k in ("rs", "rp", "ts", "tp", "Rs", "Rp", "Ts", "Tp"):
        np.testing.assert_allclose(zero[k], bare[k], atol=1e-14)
        # first-order in d: |dr/dd| <~ 4 pi |q1| / lambda * O(1) ~ 0.1 per nm
        np.testing.assert_allclose(tiny[k], bare[k], atol=1e-6)


def test_thick_metal_is_bulk_metal():
    metal = 0.17 + 3.1j
    th = np.radians([0.0, 30.0, 60.0, 85.0])
    bulk = core(1.0, np.cos(th), [], metal, 550.0)
    film = core(1.0, np.cos(th), [(metal, 400.0)], 1.52, 550.0)
    # the field decays as exp(-2 pi Im(q) d / lambda) ~ e^-14 each way, so the
    # light back from the far side is ~ e^-28 ~ 7e-13 of r
    for k in ("rs", "rp", "Rs", "Rp"):
        np.testing.assert_allclose(film[k], bulk[k], atol=1e-11)
    # power through the film ~ exp(-4 pi Im(q) d / lambda) ~ e^-28 ~ 7e-13 (times
    # interface factors <~ 2)
    assert np.all(film["Ts"] < 2e-12) and np.all(film["Tp"] < 2e-12)
    # 1 um of metal: below float64 resolution, and no overflow anywhere
    film = core(1.0, np.cos(th), [(metal, 1000.0), (2.0, 100.0)], 1.52, 550.0)
    for k in ("rs", "rp", "Rs", "Rp"):
        np.testing.assert_allclose(film[k], bulk[k], atol=1e-15)


def _random_stack(rng, sizes, lossless=False, kmax=3.0):
    # a few distinct film counts only: each count is one kernel to compile
    L = int(rng.choice(sizes))
    films = []
    for _ in range(L):
        k = 0.0 if lossless or rng.random() < 0.5 else rng.uniform(0, kmax)
        films.append((complex(rng.uniform(1.0, 2.8), k), float(rng.uniform(0, 400))))
    return films


def test_energy_conservation_lossless():
    rng = np.random.default_rng(7)
    cases = []
    for _ in range(60):
        films = _random_stack(rng, (1, 3, 12), lossless=True)
        th = np.radians(np.linspace(0, 89.9, 31))
        cases.append((float(rng.uniform(1.0, 1.8)), films, float(rng.uniform(1.0, 2.5)),
                      np.cos(th), float(rng.uniform(360, 830))))
    for got in batched(cases):
        for pol in "sp":
            # float64 recursion over <= 13 interfaces: ~1e-15 per step
            np.testing.assert_allclose(got["R" + pol] + got["T" + pol], 1.0, atol=1e-12)


def test_transmittance_is_reciprocal_with_absorbing_films():
    import thinfilm_mi as tf

    rng = np.random.default_rng(3)
    for _ in range(10):
        films = _random_stack(rng, (1, 2, 6), kmax=2.0)
        st = tf.Stack(films, substrate=1.52, ambient=1.0)
        rev = st.reversed()
        th = np.radians(np.linspace(0, 85, 18))
        th_rev = np.arcsin(np.sin(th) / 1.52)  # Snell: same tangential wave vector
        wl = float(rng.uniform(360, 830))
        a, b = st.rt(wl, th), rev.rt(wl, th_rev)
        # Reciprocity (Lorentz) holds per polarisation; R differs when films absorb.
        np.testing.assert_allclose(a.Ts, b.Ts, atol=1e-12)
        np.testing.assert_allclose(a.Tp, b.Tp, atol=1e-12)


@pytest.mark.parametrize("Arr", [Float64, Float])
@pytest.mark.parametrize("literal", [True, False])
def test_grazing_incidence_is_exact(Arr, literal):
    films = [(1.0, 100.0), (2.0 + 0.5j, 30.0), (1.0, 10.0)]
    got = core(1.0, [0.0, 0.0], films, 1.0, [500.0, 700.0], Arr=Arr, literal=literal)
    for pol in "sp":
        assert np.all(got["R" + pol] == 1.0)
        assert np.all(got["T" + pol] == 0.0)
        assert np.all(got["r" + pol] == -1.0)
        assert np.all(got["t" + pol] == 0.0)
    # direct call, no films, exit medium equal to the ambient (0/0 without the guards)
    Rs, Rp, Ts, Tp = optics.stack_rt(1.0, Arr([0.0]), [], 1.0, Arr([500.0]))
    assert (Rs[0], Rp[0], Ts[0], Tp[0]) == (1.0, 1.0, 0.0, 0.0)


# --------------------------------------------------------------------------
# tmm on random multilayers
# --------------------------------------------------------------------------
def _tmm_case(rng):
    L = int(rng.integers(1, 11))
    films = []
    for _ in range(L):
        k = 0.0 if rng.random() < 0.6 else rng.uniform(0.0, 4.0)
        films.append((complex(rng.uniform(1.0, 3.0), k), float(rng.uniform(0.0, 500.0))))
    n0 = float(rng.uniform(1.0, 1.8))
    ke = 0.0 if rng.random() < 0.5 else rng.uniform(0.0, 4.0)
    n_exit = complex(rng.uniform(1.0, 4.0), ke)
    theta = math.radians(rng.uniform(0.0, 89.0))
    wl = float(rng.uniform(360.0, 830.0))
    return n0, films, n_exit, theta, wl


def _near_critical(n0, films, n_exit, theta, tol):
    """tmm takes cos(arcsin(x)) of the refraction angle: near x = 1 (a lossless
    layer at its critical angle) that loses digits as eps / sqrt(1 - x)."""
    for n, _ in list(films) + [(n_exit, 0)]:
        if complex(n).imag == 0 and abs(n0 * math.sin(theta) / complex(n).real - 1) < tol:
            return True
    return False


def test_random_multilayers_match_tmm_float64():
    rng = np.random.default_rng(20240521)
    cases = []
    while len(cases) < 300:
        n0, films, n_exit, theta, wl = _tmm_case(rng)
        if not _near_critical(n0, films, n_exit, theta, 1e-6):
            cases.append((n0, films, n_exit, math.cos(theta), wl))
    for (n0, films, n_exit, cos0, wl), got in zip(cases, batched(cases)):
        theta = math.acos(cos0)
        nl = [n0] + [n for n, _ in films] + [n_exit]
        dl = [np.inf] + [d for _, d in films] + [np.inf]
        for pol in "sp":
            ref = tmm.coh_tmm(pol, nl, dl, theta, wl)
            # Both float64; tmm's 2x2 products grow like exp(|Im delta|) (it
            # caps Im delta at 35, i.e. changes amplitudes below e^-35 ~ 6e-16)
            # and its arcsin/cos angles lose a few digits: 1e-9 is ample.
            for mine, theirs in ((got["r" + pol][0], ref["r"]), (got["t" + pol][0], ref["t"]),
                                 (got["R" + pol][0], ref["R"]), (got["T" + pol][0], ref["T"])):
                assert abs(mine - theirs) <= 1e-9, (pol, nl, dl, theta, wl, mine, theirs)


# --------------------------------------------------------------------------
# float32 path
# --------------------------------------------------------------------------
def _f32(x):
    return float(np.float32(x))


def _c32(z):
    z = complex(z)
    return complex(_f32(z.real), _f32(z.imag))


def _compare32(cases, literal):
    """Max |R32 - R64|, |T32 - T64| over the cases; inputs are rounded to float32
    first so that only the arithmetic of the core is measured."""
    rounded = []
    for n0, films, n_exit, cos0, wl in cases:
        rounded.append((_f32(n0), [(_c32(n), _f32(d)) for n, d in films], _c32(n_exit),
                        np.asarray(cos0, np.float32).astype(np.float64),
                        np.asarray(wl, np.float32).astype(np.float64)))
    if literal:
        a = [core(c[0], c[3], c[1], c[2], c[4], Arr=Float, literal=True) for c in rounded]
        b = [core(c[0], c[3], c[1], c[2], c[4], Arr=Float64, literal=True) for c in rounded]
    else:
        a, b = batched(rounded, Arr=Float), batched(rounded, Arr=Float64)
    errs = []
    for x, y in zip(a, b):
        for k in ("Rs", "Rp", "Ts", "Tp"):
            assert np.all(np.isfinite(x[k]))
            errs.append(np.max(np.abs(x[k] - y[k])))
    return max(errs)


def _moderate_cases(rng, count):
    """<= 10 films of <= 300 nm (optical path <= ~10 wavelengths in all), angles
    kept 2 degrees away from every critical angle."""
    out = []
    while len(out) < count:
        L = int(rng.choice((1, 2, 3, 6, 10)))  # few film counts: few kernels
        films = [(complex(rng.uniform(1.0, 2.5), 0.0 if rng.random() < 0.6 else rng.uniform(0, 3.0)),
                  float(rng.uniform(0.0, 300.0))) for _ in range(L)]
        n0 = float(rng.choice([1.0, 1.0, 1.5]))
        n_exit = complex(rng.uniform(1.0, 4.0), 0.0 if rng.random() < 0.5 else rng.uniform(0, 4.0))
        th = np.radians(np.linspace(0.0, 85.0, 64))
        crit = [math.asin(complex(n).real / n0) for n, _ in films + [(n_exit, 0)]
                if complex(n).imag == 0 and complex(n).real < n0]
        keep = np.all([np.abs(th - c) > math.radians(2.0) for c in crit], axis=0) if crit else \
            np.ones_like(th, bool)
        wl = rng.uniform(360, 830, th.size)
        out.append((n0, films, n_exit, np.cos(th[keep]), wl[keep]))
    return out


@pytest.mark.parametrize("literal", [True, False])
def test_float32_matches_float64_moderate_stacks(literal):
    rng = np.random.default_rng(11)
    err = _compare32(_moderate_cases(rng, 6 if literal else 120), literal)
    # The phase 2 pi q d / lambda (<= ~20 rad here) is formed with a relative
    # error of a few 2^-24, i.e. absolute <~ 20 * 3 * 6e-8 = 4e-6 rad, and each
    # of <= 11 interface steps adds a few ulp: measured <= ~2e-6, bound 1e-5.
    assert err <= 1e-5, err


def test_float32_thick_films_bound():
    """Thick films: the phase itself carries an error of ~ delta * 2^-24 (its
    float32 rounding alone is ulp(delta)/2), so R and T errors grow with
    thickness / lambda. For a single film R(delta) has |dR/d delta| <= 4 |r01
    r12| / (1 - |r01 r12|)^2 * ... <= ~2 here, so the bound is
    err <= C * sum_j (2 pi n_j d_j / lambda) * 2^-24 with a small C; we check C = 8."""
    rng = np.random.default_rng(5)
    for d in (2_000.0, 20_000.0, 100_000.0):
        cases = []
        for _ in range(8):
            films = [(complex(rng.uniform(1.3, 2.4), 0.0), d * rng.uniform(0.5, 1.0)) for _ in range(3)]
            th = np.radians(np.linspace(0.0, 80.0, 41))
            cases.append((1.0, films, 1.52, np.cos(th), rng.uniform(360, 830, th.size)))
        err = _compare32(cases, False)
        phase = 3 * 2 * math.pi * 2.4 * d / 360.0
        assert err <= 8 * phase * EPS32 + 1e-5, (d, err, phase * EPS32)


def test_float32_near_critical_angle_bound():
    """Near a critical angle q = sqrt(n^2 - beta^2) -> 0: beta^2 = n0^2 sin^2 theta
    and n^2 - beta^2 are rounded to ~2^-24 n^2, so q has an absolute error up to
    ~ sqrt(3 * 2^-24) n ~ 4e-4 n, and R depends on q like |dR/dq| <~ 4 / q0.
    We check err <= 4 * sqrt(4 * 2^-24) * n / q0 (a few 1e-3 at most)."""
    rng = np.random.default_rng(9)
    n0, n1 = 1.5, 1.0
    tc = math.asin(n1 / n0)
    th = tc + np.concatenate([np.linspace(-1e-3, 1e-3, 81), [0.0]])
    worst_ratio = 0.0
    for films in ([], [(1.0, 200.0)], [(2.0, 100.0), (1.0, 50.0), (1.8, 80.0)]):
        cases = [(n0, films, n1 if not films else 1.0, np.cos(th), rng.uniform(360, 830, th.size))]
        err = _compare32(cases, True)
        bound = 4 * math.sqrt(4 * EPS32) * n0 / (n0 * math.cos(tc))
        assert err <= bound, (films, err, bound)
        worst_ratio = max(worst_ratio, err / bound)
    assert worst_ratio > 0  # the regime is really exercised (float32 differs)


def test_real_cx_keeps_a_literal_zero_imaginary_part():
    """A real medium (Cx with a literal 0 imaginary part, e.g. the glass substrate):
    its square and inverse stay real at trace time (no traced zeros, one real division),
    with the values of the general complex formulas."""
    x = Float([1.6, 0.5, 2.4])
    z = Cx(x, 0.0)
    sq, inv = z.square(), optics.cinv(z)
    assert isinstance(sq.im, float) and sq.im == 0.0
    assert isinstance(inv.im, float) and inv.im == 0.0
    general = Cx(x, Float([0.0, 0.0, 0.0]))
    np.testing.assert_allclose(np.array(sq.re), np.array(general.square().re), rtol=0)
    # the general re * (1 / re^2) rounds three times, 1 / re once: a few ulp apart
    np.testing.assert_allclose(np.array(inv.re), np.array(optics.cinv(general).re),
                               rtol=4 * EPS32)
    np.testing.assert_allclose(np.array(z.abs2()), np.array(general.abs2()), rtol=0)


def test_film_bounds_skip_only_what_cannot_happen():
    """optics.film_bounds: a real root where n_min >= n0_max, the q = 0 guard skipped
    only where |q| stays far above its reach (a real film at the ambient's index, or
    one barely absorbing below it, keeps the guard)."""
    b = optics.film_bounds(1.45, 1.47, 0.0, 0.0, 1.0)
    assert b.n2_min == 1.45 ** 2 and b.q_away
    assert not optics.film_bounds(1.0, 1.2, 0.0, 0.0, 1.0).q_away          # q = 0 at grazing
    assert not optics.film_bounds(1.3, 1.5, 0.0, 0.0, 1.6).q_away          # below the ambient
    assert optics.film_bounds(0.05, 1.6, 1.8, 5.0, 1.6) == optics.FilmBounds(None, True)  # a metal
    assert not optics.film_bounds(1.0, 1.0, 1e-6, 1e-6, 1.0).q_away        # barely absorbing


@pytest.mark.parametrize("n0", [1.0, 1.6])
def test_stack_rt_with_film_bounds_matches_float64(n0):
    """stack_rt given each film's bounds (a real root, no q = 0 guard where they allow;
    the ambient an array, bounded by n0_max) against float64 without them: random
    stacks of real and absorbing films (metals: n in [0.05, 2], k in [1, 6]), every
    angle including grazing, from air and from glass (a real film below the ambient's
    index keeps the general root and the guard)."""
    rng = np.random.default_rng(17)
    worst = worst_plain = 0.0
    for _ in range(40):
        count = int(rng.integers(1, 4))
        metal = rng.random(count) < 0.5
        n = np.where(metal, rng.uniform(0.05, 2.0, count), rng.uniform(1.3, 2.4, count))
        k = np.where(metal, rng.uniform(1.0, 6.0, count), 0.0)
        d = rng.uniform(5.0, 300.0, count)
        bounds = [optics.film_bounds(nj, nj, kj, kj, n0) for nj, kj in zip(n, k)]
        th = np.radians(np.concatenate([rng.uniform(0.0, 90.0, 200), [0.0, 90.0]]))
        # away from critical angles, where float32's q carries ~sqrt(eps) errors
        # (test_float32_near_critical_angle_bound), with or without bounds
        crit = [math.asin(m / n0) for m in [*n[~metal], 1.6 if n0 == 1.0 else 1.0] if m < n0]
        th = th[np.all([np.abs(th - c) > math.radians(2.0) for c in crit], axis=0)] \
            if crit else th
        wl = rng.uniform(360.0, 830.0, th.size)
        n_exit = 1.6 if n0 == 1.0 else 1.0
        f32 = [(Cx(Float(float(nj)), 0.0 if kj == 0 else Float(float(kj))), Float(float(dj)))
               for nj, kj, dj in zip(n, k, d)]
        f64 = [(complex(nj, kj), dj) for nj, kj, dj in zip(n, k, d)]
        ours = optics.stack_rt(Float(np.full(th.size, n0)), Float(np.cos(th)), f32, n_exit,
                               Float(wl), bounds=bounds, n0_max=n0,
                               exit_bounds=optics.film_bounds(n_exit, n_exit, 0.0, 0.0, n0))
        plain = optics.stack_rt(Float(np.full(th.size, n0)), Float(np.cos(th)), f32, n_exit,
                                Float(wl))
        ref = optics.stack_rt(n0, Float64(np.cos(th)), f64, n_exit, Float64(wl))
        for a, b, r in zip(ours, plain, ref):
            worst = max(worst, float(np.max(np.abs(np.array(a) - np.array(r)))))
            worst_plain = max(worst_plain, float(np.max(np.abs(np.array(b) - np.array(r)))))
    # thin films (phases <= ~2 pi 2.4 * 300 / 360 ~ 13 rad) and at most 4 interfaces:
    # float32 rounding as in test_float32_matches_float64_moderate_stacks (bound 1e-5);
    # the bounds change the traced operations, not the values beyond a few ulp
    assert worst <= 1e-5, worst
    assert worst <= worst_plain + 1e-6, (worst, worst_plain)


def random_stack(rng, count):
    """Films with n in [1, 6], k in [0, 20] (half of them absorbing), d in [0, 2000] nm."""
    n = rng.uniform(1.0, 6.0, count)
    k = rng.uniform(0.0, 20.0, count) * (rng.random(count) < 0.5)
    d = rng.uniform(0.0, 2000.0, count)
    return n, k, d


@pytest.mark.parametrize("count", [0, 1, 2, 5, 13, 30])
def test_loop_is_the_unrolled_recursion(count):
    """Same algebra, other rescaling cadence (every film instead of every third)
    and the factor 4 of each |t|^2 applied per film: the results differ by
    float64 rounding, amplified at most by the conditioning of |N|^2 / |D|^2 near
    a resonance (~1e6 for these stacks), hence 1e-9."""
    rng = np.random.default_rng(count)
    n, k, d = random_stack(rng, count)
    m = 20000
    cos = rng.uniform(0.0, 1.0, m)
    cos[:4] = [0.0, 1e-7, 1.0, 0.5]
    wl = rng.uniform(360.0, 830.0, m)
    n0, n_exit = 1.5, Cx(0.2, 3.4)
    films = [(Cx(float(a), float(b)), float(c)) for a, b, c in zip(n, k, d)]
    ref = optics.stack_rt(n0, Float64(cos), films, n_exit, Float64(wl))
    out = loop_rt(n0, cos, n, k, d, n_exit, wl)
    for name, a, b in zip(("Rs", "Rp", "Ts", "Tp"), ref, out):
        a, b = np.array(a), np.array(b)
        assert np.all(np.isfinite(b)), name
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-9, err_msg=name)


def test_loop_matches_tmm_with_total_internal_reflection():
    """Light from glass (n0 = 1.7) through low-index films beyond their critical
    angle (evanescent q) and an absorbing film, on a dielectric exit: tmm's
    coh_tmm in float64 (1e-9: the rounding of two float64 computations)."""
    n = np.array([1.38, 2.3, 1.2, 0.5, 2.0, 1.46])
    k = np.array([0.0, 0.0, 0.0, 2.9, 0.0, 0.0])
    d = np.array([120.0, 80.0, 300.0, 15.0, 95.0, 60.0])
    n0, n_exit = 1.7, 1.33
    cases = [(c, wl) for c in (1.0, 0.8, 0.6, 0.3, 0.05) for wl in (380.0, 520.0, 700.0)]
    cos = np.array([c for c, _ in cases])
    wl = np.array([w for _, w in cases])
    out = loop_rt(n0, cos, n, k, d, Cx(n_exit, 0.0), wl)
    assert_matches_tmm(out, n0, n + 1j * k, d, n_exit, cases)


def assert_matches_tmm(out, n0, n, d, n_exit, cases):
    """``(Rs, Rp, Ts, Tp)`` at the ``(cos, wavelength)`` ``cases`` against tmm's
    coh_tmm (1e-9: the rounding of two float64 computations)."""
    Rs, Rp, Ts, Tp = (np.array(v) for v in out)
    n_list = [n0] + list(n) + [n_exit]
    d_list = [np.inf] + list(d) + [np.inf]
    for i, (c, w) in enumerate(cases):
        th = float(np.arccos(c))
        s = tmm.coh_tmm("s", n_list, d_list, th, w)
        p = tmm.coh_tmm("p", n_list, d_list, th, w)
        assert abs(Rs[i] - s["R"]) < 1e-9 and abs(Rp[i] - p["R"]) < 1e-9, (c, w)
        assert abs(Ts[i] - s["T"]) < 1e-9 and abs(Tp[i] - p["T"]) < 1e-9, (c, w)


# --- the real-amplitude loop (optics.stack_rt_loop_real) ----------------------
# Films of real index above the ambient's: the kernels' loop then divides each
# Rouard step by a_j + a_j+1 and works with real Fresnel amplitudes.


def real_loop_rt(n0, cos, n, d, n_exit, wl, Arr=Float64, films_max="count"):
    """stack_rt_loop with the hints of a kernel whose films are real: the
    real-amplitude loop (``films_max``: the count, or None to force rescaling)."""
    return loop_rt(n0, cos, n, None, d, n_exit, wl, Arr, n0_max=n0,
                   film_n_min=float(np.min(n, initial=2.0 * n0)),
                   film_n_max=float(np.max(n, initial=2.0 * n0)),
                   films_max=len(n) if films_max == "count" else films_max)


@pytest.mark.parametrize("count", [0, 1, 2, 5, 13, 30])
@pytest.mark.parametrize("n0, n_exit", [(1.0, Cx(0.2, 3.4)), (1.5, Cx(1.0, 0.0)),
                                        (1.33, Cx(1.52, 0.0))],
                         ids=["metal", "exit-tir", "glass"])


def test_real_loop_is_the_unrolled_recursion(count, n0, n_exit, real_path_calls):
    """Same Rouard step divided by a_j + a_j+1 instead of multiplied by it, so the
    results differ by float64 rounding, amplified by the conditioning of
    |N|^2 / |D|^2 near resonances (~1e6 here): 1e-9. Both with the rescaling and
    without it (films_max within the bound of real_loop_rescale). The exit-tir
    case is lit from glass (n0 = 1.5) with air below: q of the exit is
    imaginary beyond 41.8 degrees."""
    rng = np.random.default_rng(100 + count)
    n = rng.uniform(1.01 * n0, 4.0, count)
    d = rng.uniform(0.0, 2000.0, count)
    m = 20000
    cos = rng.uniform(0.0, 1.0, m)
    cos[:4] = [0.0, 1e-7, 1.0, 0.5]
    wl = rng.uniform(360.0, 830.0, m)
    films = [(Cx(float(a), 0.0), float(c)) for a, c in zip(n, d)]
    ref = optics.stack_rt(n0, Float64(cos), films, n_exit, Float64(wl))
    for films_max in ("count", None):
        out = real_loop_rt(n0, cos, n, d, n_exit, wl, films_max=films_max)
        for name, a, b in zip(("Rs", "Rp", "Ts", "Tp"), ref, out):
            a, b = np.array(a), np.array(b)
            assert np.all(np.isfinite(b)), name
            np.testing.assert_allclose(b, a, rtol=0, atol=1e-9, err_msg=name)
    assert len(real_path_calls) == 2


def test_real_loop_matches_tmm():
    """Light from glass (n0 = 1.5) through high-index films onto air (total
    internal reflection at the exit beyond 41.8 degrees): tmm's coh_tmm."""
    n = np.array([1.7, 2.3, 1.9, 2.1, 1.6])
    d = np.array([120.0, 80.0, 300.0, 15.0, 95.0])
    n0, n_exit = 1.5, 1.0
    cases = [(c, wl) for c in (1.0, 0.8, 0.75, 0.7, 0.3, 0.05) for wl in (380.0, 520.0, 700.0)]
    cos = np.array([c for c, _ in cases])
    wl = np.array([w for _, w in cases])
    assert_matches_tmm(real_loop_rt(n0, cos, n, d, Cx(n_exit, 0.0), wl), n0, n, d, n_exit, cases)


def test_real_loop_without_rescaling_stays_in_float32_range():
    """The largest contrast the bound allows (films of n = 1.0011 and 6 over an
    ambient of 1): real_loop_rescale(...) films without rescaling, in float32,
    stay finite and agree with float64 (which has no range problem) to the
    float32 conditioning of such a stack (measured ~1e-4; 1e-3 allowed). One
    film more forces the rescaling back on (checked by the same call with
    films_max = None, which must agree too)."""
    from drjit.llvm import Float
    every = optics.real_loop_rescale(1.0, 1.0011, 6.0)
    assert 2 <= every < 30
    n = np.array([1.0011 if i % 2 == 0 else 6.0 for i in range(every)])
    d = np.full(every, 37.0)
    rng = np.random.default_rng(7)
    cos = np.r_[rng.uniform(0.0, 1.0, 5000), 1e-4, 1e-6]
    wl = rng.uniform(360.0, 830.0, cos.size)
    ref = [np.array(v) for v in real_loop_rt(1.0, cos, n, d, Cx(1.2, 7.0), wl)]
    for films_max in ("count", None):
        out = real_loop_rt(1.0, cos.astype(np.float32), n, d, Cx(1.2, 7.0),
                           wl.astype(np.float32), Arr=Float, films_max=films_max)
        for a, b in zip(ref[:2], out[:2]):
            b = np.array(b, np.float64)
            assert np.all(np.isfinite(b))
            assert np.max(np.abs(a - b)) < 1e-3


@pytest.mark.parametrize("n0, lo, hi", [(1.0, 1.0011, 6.0), (1.000277, 1.38, 2.6),
                                        (1.5, 1.52, 2.5), (1.0, 1.46, 2.3)])


def test_rescale_bound_covers_every_interface(n0, lo, hi):
    """real_loop_rescale's film count keeps |D| and |T|^2 within 2^+-100: every
    interface between two films of index in [lo, hi] at any angle has an
    amplitude |r| (s and p) with 2 max(log2(1 + |r|), -log2(1 - |r|)) * count
    <= 100 (sampled independently of the function's own grid)."""
    every = optics.real_loop_rescale(n0, lo, hi)
    rng = np.random.default_rng(5)
    na, nb = rng.uniform(lo, hi, (2, 200_000))
    na[:4], nb[:4] = [lo, lo, hi, hi], [hi, hi, lo, lo]
    beta = n0 * np.sqrt(rng.uniform(0.0, 1.0, na.size))
    beta[:2] = [0.0, n0]
    qa, qb = np.sqrt(na * na - beta * beta), np.sqrt(nb * nb - beta * beta)
    for a, b in ((qa, qb), (qa / na**2, qb / nb**2)):
        r = np.abs(a - b) / (a + b)
        bits = 2.0 * np.maximum(np.log2(1.0 + r), -np.log2(1.0 - r))
        assert np.max(bits) * every <= 100.0


def test_deep_stack_agrees_with_tmm_at_the_limit():
    """1000 films in float64 (the loop form) against tmm, which does not rescale."""
    import tmm
    d = [60.0 + i % 7 for i in range(MAX_FILMS)]
    n = [2.3 if i % 2 else 1.38 for i in range(MAX_FILMS)]
    st = tf.Stack(list(zip(n, d)), substrate=1.52)
    for wl, th in ((480.0, 0.0), (633.0, 0.6)):
        ref = 0.5 * sum(tmm.coh_tmm(p, [1.0] + n + [1.52], [np.inf] + d + [np.inf], th, wl)["R"]
                        for p in "sp")
        # float64 through 1000 films: ~1e-13 per film
        assert abs(float(st.rt(wl, th).R) - ref) < 1e-9


def test_sqrt_decaying_derivative_at_zero_loss():
    """d Im(q)/d Im(n²) at a lossless index is the one-sided derivative on the side
    of loss, 1 / (2 q), not 0 (dr.abs has derivative 0 at 0)."""
    from drjit.llvm.ad import Float64

    from thinfilm_mi.optics.core import Cx, sqrt_decaying
    y = Float64(0.0, 0.0)
    dr.enable_grad(y)
    q = sqrt_decaying(Cx(Float64(4.0, -4.0), y))
    dr.forward_from(y)
    # x = 4: q = 2, d Im q / dy = 1/(2 * 2); x = -4 (evanescent): q = 2i, d Re q/dy = 1/4
    np.testing.assert_allclose(np.array(dr.grad(q.im)), [0.25, 0.0], atol=1e-15)
    np.testing.assert_allclose(np.array(dr.grad(q.re)), [0.0, 0.25], atol=1e-15)


def test_float64_phase_factor_of_a_phase_of_any_size():
    """The float64 phase factor (table builds, hemispherical terms) of a phase of many
    turns, against numpy's ``exp(2πi frac(u))`` of the same float64 ``u``: exact to rounding
    up to whole-turn phases (1e30: the float64 holds whole turns only, factor 1, as float32
    from 2^24 turns). Dr.Jit's float64 ``sincos`` of such phases returns values in the 1e100s
    (a film of 1e12 nm gave NaN terms and a Mueller table build of 12 GB)."""
    u = np.array([0.3, 2.0 ** 20 + 0.125, 2.0 ** 40 + 0.25, 1e12 + 0.5, 1e30, -(2.0 ** 33) - 0.375])
    e = optics.phase_factor(Cx(Float64(1.0), 0.0), Float64(u), False)
    ref = np.exp(2j * np.pi * (u - np.round(u)))
    np.testing.assert_allclose(np.array(e.re) + 1j * np.array(e.im), ref, rtol=0, atol=1e-15)
