"""The recursion as a symbolic loop over the films (``optics.stack_rt_loop``, used by
the kernels for stacks of ``unpolarized.LOOP_MIN_FILMS`` films or more).

References: the unrolled core (``optics.stack_rt``, itself checked against tmm
and closed forms in tests/test_optics.py), tmm directly, and the float64 numpy
API (``thinfilm_mi.Stack``).
"""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tmm
from _kernels import compiled, interaction, loop_rt
from drjit.llvm import Float64

import thinfilm_mi as tf
from thinfilm_mi.optics import core as optics
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.render import kernel as K
from thinfilm_mi.render import media as media_mod


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


@pytest.fixture
def llvm():
    mi.set_variant("llvm_ad_spectral")


def points(n, seed=3):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0, n), [rng.uniform(360.0, 830.0, n) for _ in range(4)]


# Dispersive datasets (TiO2's knots are off the 1 nm grid, so the loop's grid is
# the union of knots), an absorbing metal film and constant indices.
DISPERSIVE = "; ".join(["TiO2 61", "SiO2 95", "Cr 4", "TiO2 70", "1.38 120", "SiO2 82",
                        "TiO2 55", "2.0+0.01j 40"])
# Float32 kernel against float64: rounding ~1e-6 per operation, amplified in the
# resonances of an 8-film stack with phases up to ~10 rad: the measured worst
# case over these points is ~1e-5; 1e-4 leaves margin.
F32_DEEP = 1e-4


# Formula materials without absorption (Sellmeier): the loop's grid is the 1 nm
# grid (cells found by arithmetic) and the buffer holds eta only.
NON_ABSORBING = "SiO2 95; 2.3 60; MgF2 110; Si3N4 70; SiO2 95; 1.7 30"


@pytest.mark.parametrize("layers, uniform, real", [(DISPERSIVE, False, False),
                                                   (NON_ABSORBING, True, True)])


def test_conductor_reads_the_loop_and_matches_float64(llvm, layers, uniform, real):
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Al",
                         "tabulate": False})
    side = bsdf.stack.plan[False]
    assert side.loop is not None
    assert (side.loop.uniform, side.loop.real) == (uniform, real)
    cos, wls = points(4000)
    R = np.array(bsdf.stack.reflectance(interaction(wls), mi.Float(cos)))
    ref = tf.Stack(layers, substrate="Al", ambient=media_mod.DEFAULT_EXT_IOR)
    for i in range(4):
        exact = ref.rt(wls[i], np.arccos(cos)).R
        assert np.max(np.abs(R[i] - exact)) < F32_DEEP


def test_loop_and_unrolled_kernels_agree(llvm, monkeypatch):
    """The same BSDF evaluated through the loop and through the unrolled films
    (the loops' thresholds raised): both float32, different operation order."""
    spec = {"type": "thinfilm_conductor", "layers": DISPERSIVE, "material": "Au",
            "tabulate": False}
    cos, wls = points(3000, seed=4)
    looped = mi.load_dict(spec)
    monkeypatch.setattr(K, "LOOP_MIN_FILMS", 1000)
    monkeypatch.setattr(K, "REAL_LOOP_MIN_FILMS", 1000)
    unrolled = mi.load_dict(spec)
    assert looped.stack.plan[False].loop is not None
    assert unrolled.stack.plan[False].loop is None
    si, c = interaction(wls), mi.Float(cos)
    a = np.array(looped.stack.reflectance(si, c))
    b = np.array(unrolled.stack.reflectance(si, c))
    assert np.max(np.abs(a - b)) < F32_DEEP


def test_dielectric_inside_with_loop_matches_float64(llvm):
    """thinfilm_dielectric lit from the glass: R and T of the reversed stack, with
    total internal reflection beyond the critical angle (T = 0 there)."""
    layers = "1.38 110; 2.3 70; 1.38 110; 2.3 70; 1.46 200"
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers, "int_ior": 1.52,
                         "ext_ior": 1.0, "tabulate": False})
    inside = bsdf.stack.plan[True]
    assert inside.loop is not None
    cos, wls = points(2000, seed=6)
    R, T = bsdf.stack.reflectance(interaction(wls), mi.Float(cos), inside=True, transmission=True)
    R, T = np.array(R), np.array(T)
    rev = list(reversed(tf.materials.stack.parse_layers(layers)))
    ref = tf.Stack(rev, substrate=1.0, ambient=1.52)
    for i in range(4):
        r = ref.rt(wls[i], np.arccos(cos))
        assert np.max(np.abs(R[i] - r.R)) < F32_DEEP
        assert np.max(np.abs(T[i] - r.T)) < F32_DEEP
    assert np.all(T[:, cos < 0.7] == 0) or np.max(T[:, cos < 0.7]) < 1e-6  # beyond 41 deg: TIR


def test_other_depths_and_thicknesses_reuse_the_loop_kernel(llvm):
    """The film count, thicknesses and indices are kernel inputs: a 6-film and a
    13-film stack of the same materials, and a thickness edit, share one kernel."""
    def make(count):
        layers = "; ".join(f"{'TiO2' if i % 2 == 0 else 'SiO2'} {50 + 9 * i}" for i in range(count))
        return mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Ag",
                             "tabulate": False})

    cos, wls = points(500, seed=8)
    si, c = interaction(wls), mi.Float(cos)
    first = make(6)
    np.array(first.stack.reflectance(si, c))          # compiles once
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()   # clear
        deeper = make(13)
        R13 = np.array(deeper.stack.reflectance(si, c))
        params = mi.traverse(first)
        params["layers.2.thickness"] = 140.0
        params.update()
        R6 = np.array(first.stack.reflectance(si, c))
        fresh = compiled(dr.kernel_history())
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert fresh == [], [k.get("size") for k in fresh]
    for bsdf, R in ((deeper, R13), (first, R6)):
        layers = [(ix.material.name, float(d[0] if dr.is_array_v(d) else d))
                  for ix, d in zip(bsdf.stack.indices, bsdf.stack.thickness)]
        ref = tf.Stack(layers, substrate="Ag", ambient=media_mod.DEFAULT_EXT_IOR)
        assert np.max(np.abs(R[0] - ref.rt(wls[0], np.arccos(cos)).R)) < F32_DEEP


def test_gradients_through_a_film_index_bypass_the_loop(llvm):
    """The loop's buffers are plain data: with a gradient on a film's index the
    side is evaluated through the textures, and the gradient arrives."""
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "material": "Al", "tabulate": False,
                         "layers": "1.46 100; 2.3 60; 1.46 100; 2.3 60; 1.46 100"})
    assert bsdf.stack.plan[False].loop is not None
    params = mi.traverse(bsdf)
    key = "layers.1.eta.value"
    value = params[key]
    dr.enable_grad(value)
    params.update()
    cos, wls = points(64)
    R = bsdf.stack.reflectance(interaction(wls), mi.Float(cos))
    dr.backward(dr.sum(R[0]))
    assert np.abs(np.array(dr.grad(params[key]))).max() > 0


def test_thickness_texture_scales_the_loop_films(llvm):
    """A ``thickness`` texture multiplies every film's thickness at the hit: with a
    constant 0.5 the looped stack equals the stack of half-thick films."""
    layers = "SiO2 190; 2.3 120; MgF2 220; 2.3 140; SiO2 160"
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Cu",
                         "thickness": 0.5})
    assert bsdf.stack.plan[False].loop is not None
    cos, wls = points(2000, seed=9)
    R = np.array(bsdf.stack.reflectance(interaction(wls), mi.Float(cos)))
    half = [(m, d / 2) for m, d in tf.materials.stack.parse_layers(layers)]
    ref = tf.Stack(half, substrate="Cu", ambient=media_mod.DEFAULT_EXT_IOR)
    for i in range(4):
        assert np.max(np.abs(R[i] - ref.rt(wls[i], np.arccos(cos)).R)) < F32_DEEP


def test_tabulated_sides_build_no_loop_buffers(llvm):
    """A side read from its table never evaluates its films, so no loop buffers are
    built for it; the same stack exact gets them."""
    layers = "1.46 100; 1.38 80; 1.46 60; 1.38 90"
    tabled = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Cu",
                           "tabulate": True})
    side = tabled.stack.plan[False]
    assert side.table is not None and side.loop is None
    exact = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Cu",
                          "tabulate": False})
    assert exact.stack.plan[False].loop is not None


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


@pytest.fixture
def real_path_calls(monkeypatch):
    """Counts the calls of the real-amplitude loop (so a test knows it ran)."""
    calls = []
    original = optics.stack_rt_loop_real

    def spy(*args, **kw):
        calls.append(kw.get("films_max"))
        return original(*args, **kw)
    monkeypatch.setattr(optics, "stack_rt_loop_real", spy)
    return calls


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


@pytest.mark.parametrize("layers, constant", [("1.46 100; 2.3 60; 1.46 100", True),
                                              (NON_ABSORBING, False), ("2.3 150", True)])


def test_real_films_run_the_real_loop_at_any_depth(llvm, layers, constant, real_path_calls):
    """Real films above the ambient use the loop from one film on
    (REAL_LOOP_MIN_FILMS); constant ones gather one index per lane, shared by the
    four wavelengths. Float32 kernel against float64."""
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Al",
                         "tabulate": False})
    loop = bsdf.stack.plan[False].loop
    assert loop is not None and loop.real_steps and loop.constant == constant
    cos, wls = points(4000, seed=11)
    R = np.array(bsdf.stack.reflectance(interaction(wls), mi.Float(cos)))
    assert real_path_calls
    ref = tf.Stack(layers, substrate="Al", ambient=media_mod.DEFAULT_EXT_IOR)
    for i in range(4):
        assert np.max(np.abs(R[i] - ref.rt(wls[i], np.arccos(cos)).R)) < F32_DEEP


def test_films_below_the_ambient_index_keep_the_complex_loop(llvm, real_path_calls):
    """A film of index below the ambient's (evanescent beyond its critical angle):
    the general loop, not the real-amplitude one."""
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": "2.3 70; 1.38 110; 2.3 70",
                         "ext_ior": 1.52, "int_ior": 1.6, "tabulate": False})
    for inside in (False, True):
        loop = bsdf.stack.plan[inside].loop
        assert loop is None or not loop.real_steps
    cos, wls = points(100)
    bsdf.stack.reflectance(interaction(wls), mi.Float(cos))
    assert real_path_calls == []


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
