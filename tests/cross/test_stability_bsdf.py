"""Stress tests of every thin-film BSDF: sample / eval / pdf on extreme stacks.

Every plugin of :data:`thinfilm_mi.plugins.PLUGINS` is covered (a plugin whose
module does not import yet is skipped with the import error as the reason).
Hypothesis draws stacks of 1, 2, 7 or 30 films (30: see :data:`DRAWS`; n in [1, 6], k in [0, 20],
thickness in [0, 100 um], exactly 0 included; lossless or not), a real
exterior index, a substrate (``eta`` + ``k`` or ``int_ior``, whichever the
plugin takes) and a roughness where the plugin takes one; each BSDF is built
with ``mi.load_dict`` in llvm_ad_spectral from a numeric ``layers`` string and
evaluated on one vectorised batch (all calls traced, then evaluated together):
normal incidence, grazing (cos = 1e-7 and exactly 0), the critical angles of
every film and of the exit medium +- 1e-7, light from inside (negative cos:
TIR from inside dense media), 16 random wavelength quadruples in 360-830 nm per
direction (``si.wavelengths`` set explicitly). Fixed cases add a 30-layer Bragg
mirror, a prism-coupled waveguide over a 100 um k = 20 film,
and an opaque metal coating, through each plugin's default path.

Properties (per lane and wavelength):

* sample, eval, pdf and eval_pdf are finite, weights / values / pdfs >= 0;
  eval_pdf agrees with eval and pdf; sampled directions are unit vectors;
* with one component enabled at a time in importance transport (no radiance
  scaling), a delta component's weight is its R or T: in [0, 1]; the delta
  weights sum to <= 1 + 1e-5; plus the albedos of the other components
  (estimated by stratified sampling of that component) <= 1 + 1e-5 + 5
  standard errors;
* for plugins whose components are all delta and include transmission (a
  smooth interface), R + T = 1 for lossless stacks within the float32 energy
  defect documented in benchmarks/STABILITY.md (per lane, see
  :func:`lossless_tolerance`).

Hypothesis stacks are evaluated exactly (``tabulate=False`` where a plugin
takes it: a table is built per stack at load time, ~1 s, too slow for property
tests); the fixed cases use the default path (tables where chosen).
"""
from __future__ import annotations

import math
from functools import partial

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from drjit.llvm import Float64
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

import thinfilm_mi  # noqa: F401  (registers the plugins)
from tests.support import bsdf
from tests.support.plugin_modules import import_error, plugin_dict
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.optics.unpolarized import unpolarized_rt
from thinfilm_mi.plugins import PLUGINS

VARIANT = "llvm_ad_spectral"
# Few distinct kernel shapes, so that compiled kernels are reused across examples.
# 1 and 2 films are unrolled in the kernel; 7 and 30 go through the loop over
# films (unpolarized.LOOP_MIN_FILMS), whose kernel does not depend on the depth: a
# 30-film draw compiles in about a second (the unrolled 30-film kernels of the
# rough plugins took 10-60 s).
FILM_COUNTS = (1, 2, 7, 30)
U32 = 2.0 ** -24              # float32 unit roundoff
WL_SETS = 16                  # wavelength quadruples per direction
MC = 64                       # stratified samples per (direction, wavelengths) for albedos


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant(VARIANT)


def _skip_if_missing(plugin: str) -> None:
    why = import_error(plugin, VARIANT)
    if why:
        pytest.skip(why)


# ---------------------------------------------------------------------------
# Which optional parameters a plugin takes (probed with valid values: a plugin
# reports parameters it does not take as unreferenced properties)
# ---------------------------------------------------------------------------
PROBES = {
    "eta_k": {"eta": 0.2, "k": 3.0},
    "int_ior": {"int_ior": 1.5},
    "alpha": {"alpha": 0.3},
    "tabulate": {"tabulate": False},
}
_taken: dict = {}


def takes(plugin: str, what: str) -> bool:
    key = (plugin, what)
    if key not in _taken:
        try:
            mi.load_dict(plugin_dict(plugin, **PROBES[what]))
            _taken[key] = True
        except Exception as e:  # noqa: BLE001
            if "unreferenced propert" not in str(e):
                raise
            _taken[key] = False
    return _taken[key]


# ---------------------------------------------------------------------------
# Strategies
# ---------------------------------------------------------------------------
index = st.tuples(st.floats(1.0, 6.0), st.one_of(st.just(0.0), st.floats(0.0, 20.0)))
thickness = st.one_of(st.just(0.0), st.floats(0.0, 500.0), st.floats(0.0, 100_000.0))


@st.composite
def stacks(draw, L: int):
    lossless = draw(st.booleans())
    films = []
    for _ in range(L):
        n, k = draw(index)
        films.append((n, 0.0 if lossless else k, draw(thickness)))
    ext = draw(st.one_of(st.just(1.0), st.floats(1.0, 2.5)))
    sub_n = draw(st.one_of(st.floats(1.0, 6.0), st.floats(0.05, 1.0)))
    sub_k = 0.0 if lossless else draw(st.one_of(st.just(0.0), st.floats(0.0, 20.0)))
    int_ior = draw(st.one_of(st.just(1.5), st.floats(1.0, 6.0)))
    if abs(int_ior - ext) < 0.01:  # rough interfaces need refraction (they refuse equal media)
        int_ior = ext + 0.5
    alpha = draw(st.one_of(st.just(1e-3), st.floats(1e-3, 1.0)))
    return {"films": films, "ext": ext, "sub": (sub_n, sub_k), "int_ior": int_ior,
            "alpha": alpha, "lossless": lossless}


def layers_string(films) -> str:
    return "; ".join(f"{n!r}{k:+.17g}j {d!r}" for n, k, d in films)


def build(plugin: str, s: dict, tabulate=False):
    props = plugin_dict(plugin, layers=layers_string(s["films"]), ext_ior=s["ext"])
    if takes(plugin, "eta_k"):
        props["eta"], props["k"] = s["sub"]
    if takes(plugin, "int_ior"):
        props["int_ior"] = s["int_ior"]
    if takes(plugin, "alpha"):
        props["alpha"] = s["alpha"]
    if tabulate is False and takes(plugin, "tabulate"):
        props["tabulate"] = False
    return mi.load_dict(props)


# ---------------------------------------------------------------------------
# The batch of directions and wavelengths
# ---------------------------------------------------------------------------
def critical_cosines(n_from: float, indices) -> list[float]:
    """cos(theta) in a medium of index n_from at which q of each real lower index vanishes."""
    out = []
    for n in indices:
        if 0 < n < n_from:
            s = n / n_from
            out.append(math.sqrt((1 - s) * (1 + s)))
    return out


def directions(s: dict, transmissive: bool) -> np.ndarray:
    """Cosines of incidence: normal, grazing, random, critical +- 1e-7 (outside and,
    for transmissive plugins, inside: negative)."""
    cos = [1.0, 0.999, 0.7, 0.3, 1e-3, 1e-7, 0.0]
    film_n = [n for n, k, _ in s["films"] if k == 0.0]
    crit = critical_cosines(s["ext"], film_n + [s["sub"][0]] if s["sub"][1] == 0 else film_n)
    if transmissive:
        crit_in = critical_cosines(s["int_ior"], film_n + [s["ext"]])
        cos += [-c for c in (1.0, 0.6, 1e-3, 1e-7)]
        for c in crit_in[:6]:
            cos += [-min(max(c + dc, 0.0), 1.0) for dc in (0.0, 1e-7, -1e-7)]
    for c in crit[:6]:
        cos += [min(max(c + dc, 0.0), 1.0) for dc in (0.0, 1e-7, -1e-7)]
    return np.array(cos)


def interaction(cos: np.ndarray, rng, repeat: int):
    """One lane per (direction, wavelength quadruple); random azimuths."""
    c = np.repeat(cos, repeat)
    n = c.size
    sin = np.sqrt(np.maximum(0.0, (1 - c) * (1 + c)))
    phi = rng.uniform(0, 2 * math.pi, n)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(sin * np.cos(phi), sin * np.sin(phi), c)
    wl = rng.uniform(360.0, 830.0, (4, n))
    si.wavelengths = mi.Spectrum(*[mi.Float(w) for w in wl])
    return si, c, wl


def spectrum_np(x) -> np.ndarray:
    """A mi.Spectrum as (lanes, 4) float64."""
    return np.stack([np.array(x[i], dtype=np.float64) for i in range(4)], axis=1)


#: Contexts in importance transport (the adjoint: the harder case for the sampled weights).
context = partial(bsdf.context, mode=mi.TransportMode.Importance)


def is_delta(flags) -> bool:
    return bool(int(flags) & int(mi.BSDFFlags.Delta))


# ---------------------------------------------------------------------------
# Tolerances
# ---------------------------------------------------------------------------
def lossless_tolerance(s: dict, cos: np.ndarray, wl: np.ndarray) -> np.ndarray:
    """Allowed |R + T - 1| of the float32 kernel for a lossless smooth interface, per
    lane and wavelength, shape (lanes, 4).

    Float32 rounding in the recursion acts like an absorption of relative size
    ~u in every medium; near a guided-mode or Fabry-Perot resonance that tiny
    loss is amplified by the resonance's quality factor (benchmarks/STABILITY.md:
    up to 1.5e-2 at the dips of a prism-coupled waveguide). Its measured bound
    is the absorptance A of the same stack with k = 4u|n| in every medium,
    computed here in float64 (across the benchmark's regimes the float32 defect
    never exceeded A(k = u|n|) + 1e-5; 4u gives margin), plus 1e-5 for the sum of
    ~31 interface steps of a few ulp each. Within 1e-3 in cos of a critical
    angle, q = sqrt(n^2 - beta^2) itself is only known to ~sqrt(u) |n| (q^2 is
    rounded to ~u (n^2 + beta^2); the core floors |q| at 2 sqrt(u)(|n| + beta)),
    a relative error of ~4 sqrt(u) ~ 1e-3 in that medium's admittance: 1e-3 per
    medium at its critical angle (a 30-layer mirror has 15 films of one index,
    all critical at once), plus 1e-3 because the plugin's TIR decision, made
    with Mitsuba's real-index Fresnel, may differ from the stack's there.
    """
    n_lanes = wl.shape[1]
    inside = np.tile(cos < 0, 4)
    c = np.tile(np.abs(cos), 4)
    lam = wl.ravel()              # wavelength q of lane i at q * n_lanes + i
    n_in, n_out = s["int_ior"], s["ext"]
    films = [(n, d) for n, _, d in s["films"]]
    L = len(films)

    def arr(a):
        x = Float64(np.ascontiguousarray(a, dtype=np.float64))
        dr.make_opaque(x)
        return x

    f = []
    for j in range(L):
        n = np.where(inside, films[L - 1 - j][0], films[j][0])
        d = np.where(inside, films[L - 1 - j][1], films[j][1])
        f.append((Cx(arr(n), arr(4 * U32 * n)), arr(d)))
    n0 = np.where(inside, n_in, n_out)
    nex = np.where(inside, n_out, n_in)
    R, T = unpolarized_rt(arr(n0), arr(c), f, Cx(arr(nex), arr(4 * U32 * nex)), arr(lam), True)
    A = 1.0 - np.array(R, dtype=np.float64) - np.array(T, dtype=np.float64)
    tol = 1e-5 + np.maximum(A, 0.0).reshape(4, n_lanes).T
    near = np.zeros(n_lanes)
    for side, n0s, nexs in ((False, n_out, n_in), (True, n_in, n_out)):
        sel = (cos < 0) == side
        for cc in critical_cosines(n0s, [n for n, _ in films] + [nexs]):
            near += sel & (np.abs(np.abs(cos) - cc) < 1e-3)
    tol += np.where(near > 0, 1e-3 * (near + 1), 0.0)[:, None]
    return tol


# 3 examples per (plugin, film count): 60 stacks in all.
SETTINGS = settings(max_examples=3, deadline=None, derandomize=True,
                    phases=(Phase.explicit, Phase.reuse, Phase.generate),  # no slow shrinking
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# ---------------------------------------------------------------------------
# The checks
# ---------------------------------------------------------------------------
def check_bsdf(bsdf, s: dict, seed: int, lossless: bool, light: bool = False) -> None:
    """Trace every call first, then evaluate them together: one kernel per lane count.

    ``light``: fewer traced calls (sample in importance transport only, eval and
    pdf but not eval_pdf), for 30-film stacks whose kernels take long to compile.
    """
    rng = np.random.default_rng(seed)
    n_comp = bsdf.component_count()
    flags = [bsdf.flags(i) for i in range(n_comp)]
    transmissive = any(int(f) & int(mi.BSDFFlags.Transmission) for f in flags)
    cos = directions(s, transmissive)
    si, c, wl = interaction(cos, rng, WL_SETS)
    n = c.size
    out = {}

    def u1():
        return mi.Float(rng.random(n))

    def u2():
        return mi.Point2f(rng.random(n), rng.random(n))

    # 1. Every component at once, both transport modes.
    modes = (mi.TransportMode.Importance,) if light else (mi.TransportMode.Radiance,
                                                          mi.TransportMode.Importance)
    for mode in modes:
        bs, w = bsdf.sample(context(mode=mode), si, u1(), u2())
        out[("sample", mode)] = (w, bs.pdf, bs.wo)
    # 2. eval / pdf / eval_pdf on directions over the whole sphere, grazing included.
    z = np.concatenate([rng.uniform(-1, 1, n - 3), [0.0, 1e-7, -1e-7]])
    rho = np.sqrt(np.maximum(0.0, 1 - z * z))
    phi = rng.uniform(0, 2 * math.pi, n)
    wo = mi.Vector3f(rho * np.cos(phi), rho * np.sin(phi), z)
    ctx = context()
    f, p = bsdf.eval(ctx, si, wo), bsdf.pdf(ctx, si, wo)
    out["eval"] = (f, p) + ((f, p) if light else tuple(bsdf.eval_pdf(ctx, si, wo)))
    # 3. One component at a time (importance transport: no radiance scaling).
    glossy = [i for i in range(n_comp) if not is_delta(flags[i])]
    for i in range(n_comp):
        if i not in glossy:
            out[("delta", i)] = bsdf.sample(context(i), si, u1(), u2())[1]
    # Albedo of each non-delta component: the mean weight of MC stratified
    # samples per lane (one wavelength quadruple per direction).
    lanes = np.arange(0, n, WL_SETS)
    m = lanes.size
    if glossy:
        si_g, _, _ = interaction(c[lanes], rng, MC)
        si_g.wavelengths = mi.Spectrum(*[mi.Float(np.repeat(wl[k][lanes], MC)) for k in range(4)])
        j = np.arange(MC)
        g = math.isqrt(MC)
        v1 = mi.Float(np.tile((j + 0.5) / MC, m))
        v2 = mi.Point2f(np.tile(((j % g) + rng.random(MC)) / g, m),
                        np.tile(((j // g) + rng.random(MC)) / g, m))
        for i in glossy:
            out[("glossy", i)] = bsdf.sample(context(i), si_g, v1, v2)[1]
    dr.eval(out)

    for mode in modes:
        w, pdf, wo_s = out[("sample", mode)]
        w, pdf, wo_s = spectrum_np(w), np.array(pdf, np.float64), np.array(wo_s, np.float64)
        assert np.all(np.isfinite(w)) and np.all(w >= 0), (mode, w[~(np.isfinite(w) & (w >= 0))])
        assert np.all(np.isfinite(pdf)) and np.all(pdf >= 0)
        ok = np.any(w > 0, axis=1)
        wo_s = wo_s.reshape(3, -1)[:, ok]
        assert np.all(np.isfinite(wo_s))
        # a float32 normalisation: a few ulp
        np.testing.assert_allclose(np.linalg.norm(wo_s, axis=0), 1.0, atol=1e-5)

    f, p, f2, p2 = out["eval"]
    f, f2 = spectrum_np(f), spectrum_np(f2)
    p, p2 = np.array(p, np.float64), np.array(p2, np.float64)
    for v in (f, p, f2, p2):
        assert np.all(np.isfinite(v)) and np.all(v >= 0)
    # the same float32 arithmetic by two routes: agree to a few ulp of the value
    np.testing.assert_allclose(f2, f, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(p2, p, rtol=1e-4, atol=1e-6)

    delta_sum = np.zeros((n, 4))
    delta_t = False
    for i in range(n_comp):
        if i in glossy:
            continue
        w = spectrum_np(out[("delta", i)])
        # R (or T) is clamped to [0, 1] in the core; the weight is that times 1.0
        assert np.all(np.isfinite(w)) and np.all(w >= 0) and np.all(w <= 1.0 + 1e-6), (i, w.max())
        delta_sum += w
        delta_t |= bool(int(flags[i]) & int(mi.BSDFFlags.Transmission))
    # R + T <= 1: the core clips T to [0, 1 - R] per wavelength; 1e-5 covers the
    # float32 sum of the two.
    assert np.all(delta_sum <= 1 + 1e-5), delta_sum.max()

    if glossy:
        total = delta_sum[lanes].copy()
        var = np.zeros((m, 4))
        for i in glossy:
            w = spectrum_np(out[("glossy", i)]).reshape(m, MC, 4)
            assert np.all(np.isfinite(w)) and np.all(w >= 0)
            total += w.mean(axis=1)
            var += w.var(axis=1) / MC
        # energy: <= 1 + 1e-5 + 5 standard errors of the estimate (the iid standard
        # error over-estimates that of the stratified estimate).
        bound = 1 + 1e-5 + 5 * np.sqrt(var)
        assert np.all(total <= bound), (total.max(), (total - bound).max())

    if lossless and delta_t and not glossy:
        tol = lossless_tolerance(s, c, wl)
        dev = np.abs(delta_sum - 1)
        assert np.all(dev <= tol), (dev.max(), np.unravel_index(np.argmax(dev - tol), dev.shape))


#: The coating's top is the same film stack (the same loop kernel at 7 and 30 films) as
#: ``thinfilm_dielectric``'s, which draws 30-film stacks here; a 30-film draw under the
#: coating's walk proves that stack again at the cost of minutes of compilation. The
#: coating still meets a 30-film stack in :func:`test_tabulated_stacks_stay_physical`.
DRAWS = [(p, c) for p in PLUGINS for c in FILM_COUNTS
         if not (p == "thinfilm_coating" and c == 30)]


@pytest.mark.parametrize("plugin, count", DRAWS, ids=[f"{p}-{c}" for p, c in DRAWS])
@SETTINGS
@given(data=st.data(), seed=st.integers(0, 2 ** 31))
def test_extreme_stacks_stay_physical(plugin, count, data, seed):
    _skip_if_missing(plugin)
    s = data.draw(stacks(count), label="stack")
    check_bsdf(build(plugin, s), s, seed, lossless=s["lossless"])


FIXED = [  # extreme stacks, through the default (tabulated where the plugin tabulates) path
    {"films": [(2.35 if i % 2 == 0 else 1.46, 0.0, 550 / 4 / (2.35 if i % 2 == 0 else 1.46))
               for i in range(30)], "ext": 1.0, "sub": (1.52, 0.0), "int_ior": 1.52,
     "alpha": 0.05, "lossless": True},
    {"films": [(1.0, 0.0, 600.0), (2.2, 0.0, 300.0), (5.5, 20.0, 100_000.0)], "ext": 1.9,
     "sub": (0.1, 20.0), "int_ior": 1.3, "alpha": 1e-3, "lossless": False},
    # an opaque metal coating: transmission factors ~1e-60 (positive in float64,
    # 0 in float32) must give a BSDF, not a load error
    {"films": [(0.5, 20.0, 100.0)] * 4 + [(0.4, 2.5, 20.0)], "ext": 1.0, "sub": (0.2, 3.0),
     "int_ior": 1.5, "alpha": 0.3, "lossless": False},
]


#: The 30-film Bragg mirror goes through every plugin.
THIRTY = list(PLUGINS)


@pytest.mark.parametrize("plugin, case", [(p, 0) for p in THIRTY] + [(p, 1) for p in PLUGINS]
                         + [(p, 2) for p in PLUGINS],
                         ids=[f"{p}-bragg30" for p in THIRTY]
                         + [f"{p}-guide-thick-metal" for p in PLUGINS]
                         + [f"{p}-opaque-metal-coating" for p in PLUGINS])


def test_tabulated_stacks_stay_physical(plugin, case):
    _skip_if_missing(plugin)
    s = FIXED[case]
    check_bsdf(build(plugin, s, tabulate=None), s, 7 + case, lossless=s["lossless"],
               light=len(s["films"]) > 7)
