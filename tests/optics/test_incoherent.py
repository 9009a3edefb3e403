"""Incoherent thick films (thinfilm_mi/optics/incoherent.py) against tmm.inc_tmm, closed
forms, the coherent core, physics limits, and the wavelength average that the
incoherent treatment stands for.

References are independent of the code under test: ``tmm.inc_tmm`` (a transfer
matrix of intensities, arXiv:1603.02720) and closed forms written out here with
numpy. Calls run on ``drjit.llvm.Float64`` (the reference path), on
``drjit.llvm.Float`` and ``mi.Spectrum`` (the float32 path of render kernels)
and on Python floats. Cases that share a stack shape (film count and
incoherent flags) are evaluated in one kernel with opaque inputs.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest
from drjit.llvm import Float, Float64

from thinfilm_mi.optics import core as optics
from thinfilm_mi.optics.incoherent import incoherent_rt, incoherent_rt_sp, reference_incoherent_rt
from thinfilm_mi.optics.unpolarized import unpolarized_rt

tmm = pytest.importorskip("tmm")

EPS32 = 2.0 ** -24


# --------------------------------------------------------------------------
# Calling the code under test
# --------------------------------------------------------------------------
def _arr(v, Arr):
    a = Arr(np.ascontiguousarray(v, dtype=np.float64))
    dr.make_opaque(a)
    return a


def _cx(v, Arr):
    v = np.asarray(v, dtype=np.complex128)
    return optics.Cx(_arr(v.real, Arr), _arr(v.imag, Arr))


def run(cases, Arr=Float64):
    """``cases``: list of (n0, films [(n, d)], incoherent flags, n_exit, cos0 array,
    wl array or scalar). Returns one dict (Rs, Rp, Ts, Tp, R, T as numpy) per
    case; one kernel per (film count, flags)."""
    groups = {}
    for i, c in enumerate(cases):
        groups.setdefault((len(c[1]), tuple(c[2])), []).append(i)
    results = [None] * len(cases)
    for (L, flags), idx in groups.items():
        sizes = [np.size(cases[i][4]) for i in idx]
        rep = lambda vals: np.concatenate([np.full(s, v) for v, s in zip(vals, sizes)])
        n0 = _arr(rep([cases[i][0] for i in idx]), Arr)
        films = [(_cx(rep([complex(cases[i][1][j][0]) for i in idx]), Arr),
                  _arr(rep([float(cases[i][1][j][1]) for i in idx]), Arr)) for j in range(L)]
        ne = _cx(rep([complex(cases[i][3]) for i in idx]), Arr)
        cos0 = _arr(np.concatenate([np.broadcast_to(cases[i][4], (s,)) for i, s in zip(idx, sizes)]), Arr)
        wl = _arr(np.concatenate([np.broadcast_to(cases[i][5], (s,)) for i, s in zip(idx, sizes)]), Arr)
        Rs, Rp, Ts, Tp = incoherent_rt_sp(n0, cos0, films, ne, wl, list(flags))
        R, T = incoherent_rt(n0, cos0, films, ne, wl, list(flags))
        zero = dr.zeros(Arr, sum(sizes))
        outs = [x + zero for x in (Rs, Rp, Ts, Tp, R, T)]
        dr.eval(*outs)
        outs = [np.array(x, dtype=np.float64) for x in outs]
        start = 0
        for i, s in zip(idx, sizes):
            results[i] = {k: v[start:start + s] for k, v in zip(("Rs", "Rp", "Ts", "Tp", "R", "T"), outs)}
            start += s
    return results


def tmm_ref(n0, films, flags, n_exit, cos0, wl):
    """tmm.inc_tmm per angle: {'Rs', 'Rp', 'Ts', 'Tp'} as numpy arrays."""
    nl = [n0] + [n for n, _ in films] + [n_exit]
    dl = [np.inf] + [d for _, d in films] + [np.inf]
    cl = ["i"] + ["i" if f else "c" for f in flags] + ["i"]
    out = {}
    wls = np.broadcast_to(wl, np.shape(cos0))
    for pol in "sp":
        vals = [tmm.inc_tmm(pol, nl, dl, cl, math.acos(c), w) for c, w in zip(cos0, wls)]
        out["R" + pol] = np.array([v["R"] for v in vals])
        out["T" + pol] = np.array([v["T"] for v in vals])
    return out


def fresnel_R(pol, na, nb, cos_a):
    """Interface power reflectance between real media (numpy)."""
    qa = na * cos_a
    qb = np.sqrt(nb ** 2 - (na ** 2) * (1 - cos_a ** 2) + 0j)
    if pol == "s":
        r = (qa - qb) / (qa + qb)
    else:
        r = (nb ** 2 * qa - na ** 2 * qb) / (nb ** 2 * qa + na ** 2 * qb)
    return np.abs(r) ** 2


COS = np.cos(np.radians([0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 85.0, 89.0]))


# --------------------------------------------------------------------------
# tmm.inc_tmm and closed forms
# --------------------------------------------------------------------------
# (n0, films, incoherent flags, n_exit): the named cases of the brief
NAMED = {
    "glass slab 1 mm in air": (1.0, [(1.5, 1e6)], [True], 1.0),
    "absorbing slab": (1.0, [(1.7 + 2e-3j, 5e4)], [True], 1.0),
    "absorbing slab on glass, from water": (1.33, [(2.2 + 0.01j, 3e3)], [True], 1.52),
    "AR film on a thick absorbing layer on a metal":
        (1.0, [(1.38, 100.0), (1.6 + 1e-5j, 1e5)], [False, True], 0.17 + 3.1j),
    "several groups":
        (1.0, [(1.38, 95.0), (2.3, 60.0), (1.52, 2e4), (2.1 + 0.3j, 25.0), (1.46, 140.0),
               (1.8 + 1e-4j, 8e3), (2.4, 50.0)],
         [False, False, True, False, False, True, False], 0.2 + 3.4j),
    "adjacent incoherent films": (1.2, [(1.5, 1e4), (1.7 + 1e-3j, 2e4)], [True, True], 1.52 + 0.1j),
    "incoherent film first and last":
        (1.0, [(1.55, 5e4), (1.9, 120.0), (1.4 + 5e-4j, 3e4)], [True, False, True], 4.0 + 0.05j),
}


def test_named_cases_match_tmm_inc_tmm():
    names = list(NAMED)
    cases = [NAMED[k] + (COS, 550.0) for k in names]
    for name, case, got in zip(names, cases, run(cases)):
        ref = tmm_ref(case[0], case[1], case[2], case[3], COS, 550.0)
        for key in ("Rs", "Rp", "Ts", "Tp"):
            # both float64; a handful of interfaces and a geometric series of
            # non-negative terms, tmm's arcsin/cos angles lose a few digits: 1e-10.
            np.testing.assert_allclose(got[key], ref[key], rtol=0, atol=1e-10, err_msg=f"{name} {key}")
        # unpolarised = mean of s and p (no clipping is active in these cases)
        np.testing.assert_allclose(got["R"], 0.5 * (ref["Rs"] + ref["Rp"]), rtol=0, atol=1e-10)
        np.testing.assert_allclose(got["T"], 0.5 * (ref["Ts"] + ref["Tp"]), rtol=0, atol=1e-10)


def test_lossless_slab_closed_form():
    """A lossless slab in air: R = R1 + T1^2 R2 / (1 - R1 R2) with R1 = R2 the
    interface reflectance (the same from both sides) and T1 = 1 - R1, and
    T = T1^2 / (1 - R1^2) = (1 - R1)/(1 + R1); independent of the thickness."""
    cos = np.cos(np.radians(np.linspace(0.0, 89.5, 60)))
    cases = [(1.0, [(1.5, d)], [True], 1.0, cos, wl) for d, wl in ((1e6, 550.0), (3e3, 410.0), (0.0, 700.0))]
    for got in run(cases):
        for pol in "sp":
            R1 = fresnel_R(pol, 1.0, 1.5, cos)
            T1 = 1.0 - R1
            np.testing.assert_allclose(got["R" + pol], R1 + T1 ** 2 * R1 / (1 - R1 * R1), rtol=0, atol=1e-14)
            np.testing.assert_allclose(got["T" + pol], (1 - R1) / (1 + R1), rtol=0, atol=1e-14)


def _random_case(rng, flags):
    """Random n0 in [1, 1.5]; incoherent films n in [1.5, 2.5] (propagating: tmm
    divides by their transmittance) and either k 0 or up to 1e-3 with d 1-100 um,
    or k up to 2 with d 0.2-2 um (opaque to partly transparent); coherent films
    n in [1, 2.6], k 0 or up to 3, d <= 300 nm; exit any."""
    n0 = float(rng.uniform(1.0, 1.5))
    films = []
    for inc in flags:
        if inc:
            u = rng.random()
            if u < 0.7:
                k = 0.0 if u < 0.3 else rng.uniform(0.0, 1e-3)
                films.append((complex(rng.uniform(1.5, 2.5), k), float(rng.uniform(1e3, 1e5))))
            else:
                films.append((complex(rng.uniform(1.5, 2.5), rng.uniform(0.0, 2.0)),
                              float(rng.uniform(200.0, 2e3))))
        else:
            k = 0.0 if rng.random() < 0.6 else rng.uniform(0.0, 3.0)
            films.append((complex(rng.uniform(1.0, 2.6), k), float(rng.uniform(0.0, 300.0))))
    ne = complex(rng.uniform(1.0, 4.0), 0.0 if rng.random() < 0.5 else rng.uniform(0.0, 4.0))
    return n0, films, flags, ne


PATTERNS = [
    [True], [False, True], [True, False], [False, True, False],
    [False, True, False, False, True, False], [True, True, False], [False, True, True, True],
]


def _near_critical(n0, films, ne, cos0, tol):
    """tmm takes cos(arcsin(x)) of refraction angles, which loses digits near x = 1."""
    s = n0 * math.sqrt(1 - cos0 * cos0)
    return any(complex(n).imag == 0 and abs(s / complex(n).real - 1) < tol
               for n in [f[0] for f in films] + [ne])


def _random_cases(seed, angles):
    """Six random stacks per pattern; ``angles(rng)`` gives each one's angles (deg)."""
    rng = np.random.default_rng(seed)
    cases = []
    for flags in PATTERNS:
        for _ in range(6):
            n0, films, fl, ne = _random_case(rng, flags)
            cos = np.cos(np.radians(angles(rng)))
            cos = np.array([c for c in cos if not _near_critical(n0, films, ne, c, 1e-6)])
            cases.append((n0, films, fl, ne, cos, rng.uniform(360.0, 830.0, cos.size)))
    return cases


def test_random_stacks_match_tmm_both_polarisations():
    cases = _random_cases(2024, lambda rng: rng.uniform(0.0, 88.0, 6))
    worst = 0.0
    for case, got in zip(cases, run(cases)):
        ref = tmm_ref(case[0], case[1], case[2], case[3], case[4], case[5])
        for key in ("Rs", "Rp", "Ts", "Tp"):
            worst = max(worst, np.max(np.abs(got[key] - ref[key])))
    assert worst <= 1e-10, worst  # as above


# --------------------------------------------------------------------------
# Limits
# --------------------------------------------------------------------------
def test_all_coherent_is_the_coherent_core():
    films = [(1.38, 100.0), (2.1 + 0.2j, 40.0), (1.5, 2e4)]
    cos = Float64(COS)
    wl = Float64(np.linspace(400.0, 700.0, COS.size))
    R, T = incoherent_rt(1.0, cos, films, 0.17 + 3.1j, wl, [False] * 3)
    R0, T0 = unpolarized_rt(1.0, cos, films, 0.17 + 3.1j, wl)
    # stack_rt (power recursion) vs stack_amplitudes (amplitudes): same
    # recursion, rounding only; a 20 um film has a phase ~ 1e3 rad, ulp ~ 1e-13.
    np.testing.assert_allclose(np.array(R), np.array(R0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(T), np.array(T0), rtol=0, atol=1e-12)
    Rs, Rp, Ts, Tp = incoherent_rt_sp(1.0, cos, films, 0.17 + 3.1j, wl, [False] * 3)
    ref = optics.stack_rt(1.0, cos, films, 0.17 + 3.1j, wl)
    for a, b in zip((Rs, Rp, Ts, Tp), ref):
        assert np.array_equal(np.array(a), np.array(b))  # it *is* the core


def test_zero_thickness_incoherent_film_matching_a_neighbour_is_no_film():
    """An incoherent film with the index of the exit medium (or of the ambient)
    bounds a sub-stack with a transparent interface: the stack is the same as
    without it. (An incoherent film of thickness 0 is *not* no film in general:
    it removes the interference between its two sides -- see the next test.)"""
    cos = COS
    coh = [(1.38, 100.0), (2.1 + 0.2j, 40.0)]
    cases = [(1.0, coh + [(1.52, 0.0)], [False, False, True], 1.52, cos, 520.0),
             (1.0, coh, [False, False], 1.52, cos, 520.0),
             (1.33, [(1.33, 0.0)] + coh, [True, False, False], 1.52, cos, 520.0),
             (1.33, coh, [False, False], 1.52, cos, 520.0)]
    a, b, c, d = run(cases)
    for key in ("Rs", "Rp", "Ts", "Tp"):
        np.testing.assert_allclose(a[key], b[key], rtol=0, atol=1e-14)  # rounding only
        np.testing.assert_allclose(c[key], d[key], rtol=0, atol=1e-14)


def test_zero_thickness_incoherent_film_adds_intensities():
    """Ambient | film (d = 0, incoherent) | exit: the two interfaces add in power,
    R = R01 + T01^2 R12 / (1 - R10 R12), which is not the bare interface R02."""
    cos = np.cos(np.radians(np.linspace(0.0, 80.0, 9)))
    got = run([(1.0, [(1.5, 0.0)], [True], 2.0, cos, 600.0)])[0]
    for pol in "sp":
        R01, R12 = fresnel_R(pol, 1.0, 1.5, cos), fresnel_R(pol, 1.5, 2.0, np.sqrt(1 - (1 - cos ** 2) / 1.5 ** 2))
        ref = R01 + (1 - R01) ** 2 * R12 / (1 - R01 * R12)
        np.testing.assert_allclose(got["R" + pol], ref, rtol=0, atol=1e-14)
        assert np.all(np.abs(got["R" + pol] - fresnel_R(pol, 1.0, 2.0, cos)) > 1e-3)


def test_thickness_of_lossless_incoherent_film_does_not_matter_and_absorbing_is_continuous():
    base = [(1.38, 100.0), (1.6, None), (2.0, 60.0)]
    flags = [False, True, False]
    mk = lambda n, d: [(base[0][0], 100.0), (n, d), (2.0, 60.0)]
    cases = [(1.0, mk(1.6, d), flags, 0.2 + 3.4j, COS, 480.0) for d in (0.0, 1e3, 1e6)]
    cases += [(1.0, mk(1.6 + 0.01j, d), flags, 0.2 + 3.4j, COS, 480.0) for d in (0.0, 1e-3)]
    out = run(cases)
    for key in ("Rs", "Rp", "Ts", "Tp"):
        np.testing.assert_array_equal(out[1][key], out[0][key])  # P = exp(0) = 1 exactly
        np.testing.assert_array_equal(out[2][key], out[0][key])
        # d = 1e-3 nm: 1 - P = 4 pi Im(q) d / lambda < 3e-7
        np.testing.assert_allclose(out[4][key], out[3][key], rtol=0, atol=1e-6)


def test_energy_conservation_lossless():
    rng = np.random.default_rng(5)
    cases = []
    for flags in PATTERNS:
        for _ in range(5):
            films = [(complex(rng.uniform(1.0, 2.6)), float(rng.uniform(1e3, 1e5) if f else rng.uniform(0, 300)))
                     for f in flags]
            cos = np.cos(np.radians(np.linspace(0.0, 89.9, 31)))
            cases.append((float(rng.uniform(1.0, 1.8)), films, flags, float(rng.uniform(1.0, 2.5)), cos,
                          float(rng.uniform(360, 830))))
    for got in run(cases):
        for pol in ("s", "p", ""):
            # float64; lossless sub-stacks conserve energy to ~1e-15 each and the
            # series keeps R + T = 1 exactly in exact arithmetic
            np.testing.assert_allclose(got["R" + pol] + got["T" + pol], 1.0, rtol=0, atol=1e-12)


def test_reversed_stack_is_reciprocal():
    """Lit from the substrate (films and flags reversed, as KernelStack does for
    inside=True), T per polarisation equals the forward T at the Snell-matched
    angle, also with absorbing films (Lorentz reciprocity holds for each
    coherent sub-stack and for the incoherent series)."""
    films = [(1.38, 90.0), (1.9 + 0.05j, 4e3), (2.2 + 0.4j, 30.0), (1.5 + 2e-4j, 2e4), (1.7, 70.0)]
    flags = [False, True, False, True, False]
    th = np.radians(np.linspace(0.0, 85.0, 18))
    th_rev = np.arcsin(np.sin(th) / 1.52)
    fwd, rev = run([(1.0, films, flags, 1.52, np.cos(th), 633.0),
                    (1.52, films[::-1], flags[::-1], 1.0, np.cos(th_rev), 633.0)])
    for key in ("Ts", "Tp"):
        np.testing.assert_allclose(fwd[key], rev[key], rtol=0, atol=1e-12)
    assert np.all(np.abs(fwd["R"] - rev["R"]) > 1e-4)  # absorbing: R is not reciprocal


@pytest.mark.parametrize("Arr", [Float64, Float])
def test_no_nan_at_grazing_and_for_opaque_films(Arr):
    cos = np.array([0.0, 1e-7, 1e-4, 0.3, 1.0])
    metal = 2.0 + 20.0j
    cases = [
        (1.0, [(metal, 1e5)], [True], 1.5, cos, 550.0),
        (1.3, [(1.4, 100.0), (metal, 1e5), (1.5, 1e5)], [False, True, True], 0.2 + 3.0j, cos, 400.0),
        (1.5, [(1.5, 1e5), (1.0, 1e4), (1.5, 0.0)], [True, True, True], 1.0, cos, 700.0),  # TIR inside
        (1.0, [(metal, 1e5), (metal, 1e5)], [False, True], metal, cos, 830.0),
    ]
    for got in run(cases, Arr):
        for key, v in got.items():
            assert np.all(np.isfinite(v)), key
            assert np.all((v >= 0) & (v <= 1)), key
        assert np.all(got["R"] + got["T"] <= 1.0 + 1e-6)
        assert np.all(got["R"][0] == 1.0) and np.all(got["T"][0] == 0.0)
    # Adversarial stacks: any n0 (TIR), evanescent and metallic incoherent films of
    # any thickness (0 included), metal exits: always finite and bounded.
    rng = np.random.default_rng(4)
    adv = []
    for _ in range(60):
        L = int(rng.integers(1, 4))
        flags = [True] + [bool(rng.random() < 0.5) for _ in range(L - 1)]
        pick = lambda: complex(rng.uniform(0.1, 3.0), rng.choice([0.0, rng.uniform(0.0, 20.0)]))
        films = [(pick(), float(rng.choice([0.0, rng.uniform(0.0, 500.0), 1e5]))) for _ in range(L)]
        adv.append((float(rng.uniform(1.0, 3.0)), films, flags, pick(),
                    np.cos(np.radians(np.linspace(0.0, 90.0, 16))), float(rng.uniform(360, 830))))
    for got in run(adv, Arr):
        for key, v in got.items():
            assert np.all(np.isfinite(v)) and np.all((v >= 0) & (v <= 1)), key
        assert np.all(got["R"] + got["T"] <= 1.0 + 1e-6)
    # An opaque incoherent film (P underflows to 0) is a substrate: R is that of
    # the stack ending in it, and nothing is transmitted.
    a, b = run([cases[1], (1.3, [(1.4, 100.0)], [False], metal, cos, 400.0)], Arr)
    tol = 1e-14 if Arr is Float64 else 1e-6
    for key in ("Rs", "Rp"):
        np.testing.assert_allclose(a[key], b[key], rtol=0, atol=tol)
    assert np.all(a["Ts"] == 0) and np.all(a["Tp"] == 0)


# --------------------------------------------------------------------------
# float32 and the array types of the render kernels
# --------------------------------------------------------------------------
def _round32(case):
    f = lambda x: float(np.float32(x))
    c = lambda z: complex(f(complex(z).real), f(complex(z).imag))
    n0, films, flags, ne, cos, wl = case
    return (f(n0), [(c(n), f(d)) for n, d in films], flags, c(ne),
            np.asarray(cos, np.float32).astype(np.float64), np.asarray(wl, np.float32).astype(np.float64))


def test_float32_matches_float64():
    """Coherent sub-stacks of <= 300 nm films carry float32 errors <= 1e-5 (the
    bound of tests/optics/test_core.py::test_float32_matches_float64_moderate_stacks). An
    incoherent film adds no phase, only P = exp(-x) with x formed to a few ulp:
    |dP| <= x e^-x * 3 * 2^-24 <= 2e-8 at any thickness. The series terms are
    non-negative with denominators 1 - Rb P^2 R >= 1 - Rb R (>~ 0.3 here), so
    the total stays at the level of the sub-stacks: bound 1e-5 (measured ~5e-7).
    Inputs are rounded to float32 first so that only the arithmetic differs."""
    cases = [_round32(c) for c in _random_cases(17, lambda rng: np.linspace(0.0, 85.0, 24))]
    a, b = run(cases, Float), run(cases, Float64)
    worst = 0.0
    for x, y in zip(a, b):
        for key in x:
            assert np.all(np.isfinite(x[key]))
            worst = max(worst, np.max(np.abs(x[key] - y[key])))
    assert worst <= 1e-5, worst
    # literal (trace-time constant) indices and thicknesses, as scalar variants
    # and constant materials give: the same bound against tmm
    cos = Float(COS.astype(np.float32))
    for name, (n0, films, flags, ne) in NAMED.items():
        R, T = incoherent_rt(n0, cos, films, ne, 550.0, flags)
        ref = tmm_ref(n0, films, flags, ne, np.array(cos, np.float64), 550.0)
        np.testing.assert_allclose(np.array(R), 0.5 * (ref["Rs"] + ref["Rp"]), rtol=0, atol=1e-5, err_msg=name)
        np.testing.assert_allclose(np.array(T), 0.5 * (ref["Ts"] + ref["Tp"]), rtol=0, atol=1e-5, err_msg=name)


def test_python_floats_and_numpy_wrapper():
    n0, films, flags, ne = NAMED["several groups"]
    c = float(COS[3])
    R, T = incoherent_rt(n0, c, films, ne, 550.0, flags)  # scalar path: plain floats
    assert isinstance(R, float) and isinstance(T, float)
    ref = tmm_ref(n0, films, flags, ne, np.array([c]), 550.0)
    assert R == pytest.approx(0.5 * (ref["Rs"][0] + ref["Rp"][0]), abs=1e-10)
    assert T == pytest.approx(0.5 * (ref["Ts"][0] + ref["Tp"][0]), abs=1e-10)
    out = reference_incoherent_rt(n0, COS, [n for n, _ in films], [d for _, d in films], ne,
                                  np.full(COS.size, 550.0), flags)
    ref = tmm_ref(n0, films, flags, ne, COS, 550.0)
    for key in ("Rs", "Rp", "Ts", "Tp"):
        np.testing.assert_allclose(out[key], ref[key], rtol=0, atol=1e-10)
    np.testing.assert_allclose(out["R"], 0.5 * (out["Rs"] + out["Rp"]), rtol=0, atol=1e-15)


@pytest.mark.parametrize("variant", ["llvm_ad_spectral", "scalar_spectral"])
def test_mitsuba_spectrum(variant):
    """mi.Spectrum (four wavelengths, float32) with indices as Cx of Spectrum, as
    KernelStack passes them, and both directions (inside = reversed films and flags)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant(variant)
    try:
        wls = [412.0, 503.0, 611.0, 777.0]
        films = [(1.38, 100.0), (1.6 + 1e-4j, 5e4), (2.2 + 0.3j, 25.0)]
        flags = [False, True, False]
        wl = mi.Spectrum(wls)
        spec = lambda z: optics.Cx(mi.Spectrum([complex(z).real] * 4), mi.Spectrum([complex(z).imag] * 4))
        f = [(spec(n), mi.Float(d)) for n, d in films]
        cos = mi.Float(0.8)
        for inside in (False, True):
            if inside:
                R, T = incoherent_rt(mi.Spectrum(1.52), cos, f[::-1], optics.Cx(mi.Spectrum(1.0), 0.0),
                                     wl, flags[::-1])
                case = (1.52, films[::-1], flags[::-1], 1.0)
            else:
                R, T = incoherent_rt(mi.Spectrum(1.0), cos, f, spec(1.52), wl, flags)
                case = (1.0, films, flags, 1.52)
            R, T = np.array(R, np.float64).ravel(), np.array(T, np.float64).ravel()
            for i, w in enumerate(wls):
                ref = tmm_ref(*case, np.array([0.8]), w)
                # float32, thin coherent sub-stacks: 1e-5 as in test_float32_matches_float64
                assert R[i] == pytest.approx(0.5 * (ref["Rs"][0] + ref["Rp"][0]), abs=1e-5)
                assert T[i] == pytest.approx(0.5 * (ref["Ts"][0] + ref["Tp"][0]), abs=1e-5)
    finally:
        mi.set_variant("llvm_ad_spectral")


# --------------------------------------------------------------------------
# What the incoherent result stands for
# --------------------------------------------------------------------------
def test_wavelength_average_of_coherent_result_converges_to_incoherent():
    """Averaging the *coherent* R and T of a thick film over a 5 nm window (a
    smooth Hann weight) gives the incoherent result once the window spans many
    fringes (spacing lambda^2 / (2 q d): 1.9, 0.5 and 0.1 nm for 50, 200 and
    1000 um of glass at 550 nm). Both sides are averaged over the same window,
    so the slow spectral variation of the thin coherent films cancels; what
    is left is the leakage of the window at the fringe frequency, which falls
    as the number of fringes in the window grows."""
    n = 20001
    wl = np.linspace(547.5, 552.5, n)
    w = np.sin(np.pi * np.arange(n) / (n - 1)) ** 2
    w /= w.sum()
    cos = 0.9
    errs = []
    for d in (5e4, 2e5, 1e6):
        for slab in (1.5, 1.5 + 2e-6j):
            films = [(1.38, 100.0), (slab, d), (2.1, 60.0)]
            c, wl_d = Float64(np.full(n, cos)), Float64(wl)
            Rc, Tc = unpolarized_rt(1.0, c, films, 0.2 + 3.4j, wl_d)
            Ri, Ti = incoherent_rt(1.0, c, films, 0.2 + 3.4j, wl_d, [False, True, False])
            err = max(abs(np.dot(w, np.array(Rc)) - np.dot(w, np.array(Ri))),
                      abs(np.dot(w, np.array(Tc)) - np.dot(w, np.array(Ti))))
            errs.append(err)
            # the coherent R itself swings across the fringes
            assert np.ptp(np.array(Rc)) > 0.05
    lossless, absorbing = errs[0::2], errs[1::2]
    for e in (lossless, absorbing):
        assert e[0] > e[1] > e[2]
        assert e[2] < 1e-6, errs
