"""Tables of Mueller components (thinfilm_mi/tabulate/mueller.py) for
``*_spectral_polarized`` variants: against the exact components, thick incoherent
films, band-limited rows, the plugins reading them, ``auto`` and deep stacks."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from drjit.llvm import Float64

import thinfilm_mi  # noqa: F401  (registers the plugins in every variant)
from tests.support.mueller import channels
from tests.support.polarized import polarized_variant, pytestmark  # noqa: F401  (the skip mark, variant fixture)
from tests.support.stacks import benchmark_thicknesses
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.optics.incoherent_mueller import incoherent_mueller
from thinfilm_mi.render import stack_build
from thinfilm_mi.render.amplitudes import polarized_response
from thinfilm_mi.render.media import DEFAULT_EXT_IOR
from thinfilm_mi.tabulate import axes, band
from thinfilm_mi.tabulate import base as tabulate_base
from thinfilm_mi.tabulate.mueller import MUELLER
from thinfilm_mi.tabulate.policy import MUELLER_AUTO_MAX_FLOATS as AUTO_MAX_FLOATS
from thinfilm_mi.tabulate.policy import MUELLER_AUTO_MIN_FILMS as AUTO_MIN_FILMS

# A float32 kernel value against float64: rounding below 3e-5 for these stacks
# (tests/tabulate/test_exact.py, the same recursion and lookups).
F32 = 3e-5


def f32(x):
    return np.asarray(x, np.float32).astype(np.float64)


def layers(n, lo, hi, seed=6):
    d = np.random.default_rng(seed).uniform(lo, hi, n)
    return "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(n))


# ---------------------------------------------------------------------------
# Tables through the render path
# ---------------------------------------------------------------------------
def _si(wls):
    si = dr.zeros(mi.SurfaceInteraction3f, len(wls[0]))
    si.wavelengths = mi.UnpolarizedSpectrum(*[mi.Float(np.asarray(w, np.float32)) for w in wls])
    return si


def _render_components(stack, inside, cos, wls) -> np.ndarray:
    """``polarized_response`` as the 8 channels, shape (4 wavelengths, points, 8)."""
    p = polarized_response(stack, _si(wls), mi.Float(cos.astype(np.float32)), inside=inside,
                           transmission=True)
    out = []
    for P, shape in ((p.R, p.reflection), (p.T, p.transmission)):
        out.append([P, P * shape.b, P * shape.c_re, P * shape.c_im])
    (R, B, cr, ci), (T, BT, tr, ti) = out
    return np.stack([np.array(x) for x in (R, T, B, cr, ci, BT, tr, ti)], axis=-1)


def _exact_components(stack, inside, cos, wls) -> np.ndarray:
    """The float64 components the table was built from (its side's build data)."""
    data = stack_build.side_data(stack.plan[inside], True, quantity=MUELLER)
    out = []
    for wl in wls:
        w = np.asarray(wl, np.float64)
        out.append(tabulate_base.evaluate_side(data, cos, np.arange(cos.size), w,
                                               tabulate_base.side_indices(data, w)))
    return np.stack(out)


def _points(n, seed, critical=None):
    """Incidence outside the grazing sliver the builds do not verify (as
    tests/tabulate/test_exact.py), and 500 points within 1e-3 of the critical angle."""
    rng = np.random.default_rng(seed)
    cos = f32(rng.uniform(tabulate_base.GRAZING_COS, 1.0, n))
    if critical is not None:
        cos[:500] = f32(critical + np.linspace(-1e-3, 1e-3, 500))
    return cos, [f32(rng.uniform(360.0, 830.0, n)) for _ in range(4)]


# Each channel of a lookup is within 1.5x its table's verified error of the exact
# value (tests/tabulate/test_exact.py: the spline errs most near the checked midpoints),
# plus float32 rounding. The render path then projects the four components of a
# lobe onto the cone of physical matrices (amplitudes.physical), which keeps them at
# least as close to the exact (physical) ones in the Euclidean norm, i.e. within
# sqrt(4) = 2 times the largest channel error: 2 (1.5 err + F32). (Measured: at
# most 0.83x the table's verified error, 3.3e-4, over the four tables below.)
def _tolerance(table):
    return 2.0 * (1.5 * table.error + F32)


@pytest.mark.parametrize("films", [10, 30])
def test_dielectric_mueller_tables_match_the_exact_components(films):
    """10 and 30 films (10-30 nm: tables of the exact values, spectral_resolution 0)
    on glass, lit from outside and from inside through the critical angle (a split
    angle axis); every channel of reflection and transmission."""
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers(films, 10.0, 30.0),
                         "int_ior": 1.52, "tabulate": True, "spectral_resolution": 0.0})
    critical = math.sqrt(1.0 - (DEFAULT_EXT_IOR / 1.52) ** 2)
    for inside in (False, True):
        side = bsdf.stack.plan[inside]
        table = side.table
        assert table is not None and table.channels == 8 and table.resolution == 0.0
        assert table.axis.name == ("tir" if inside else "plain")
        cos, wls = _points(6000, 2 + inside, critical if inside else None)
        ours = _render_components(bsdf.stack, inside, cos, wls)
        ref = _exact_components(bsdf.stack, inside, cos, wls)
        err = np.abs(ours - ref).max(axis=(0, 1))
        assert err.max() <= _tolerance(table), (inside, err, table.error)
        assert err.max() > 1e-6                       # really the interpolated table
        assert np.abs(ref[..., 3:5]).max() > 0.3      # the cross terms are compared
        if inside:   # beyond the critical angle: total reflection, a pure retarder
            tir = cos < critical - 1e-4
            assert np.abs(ours[:, tir, 1]).max() <= _tolerance(table)
            assert np.abs(ref[:, tir, 0] - 1.0).max() < 1e-9


def test_a_thick_films_table_holds_the_incoherent_components():
    """A film thicker than coherence_thickness: the table holds the polarized
    incoherent average (optics.incoherent_mueller), not the coherent fringes."""
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "int_ior": 1.52, "tabulate": True,
                         "layers": "1.46 300; 1.6 20000; 2.3 80; 1.38 120"})
    assert bsdf.stack.plan[False].incoherent == [False, True, False, False]
    table = bsdf.stack.plan[False].table
    assert table is not None
    cos, wls = _points(4000, 5)
    ours = _render_components(bsdf.stack, False, cos, wls)
    n = cos.size
    ref = []
    for wl in wls:
        films = [(Cx(n_, 0.0), d) for n_, d in ((1.46, 300.0), (1.6, 20000.0), (2.3, 80.0),
                                               (1.38, 120.0))]
        ref.append(channels(incoherent_mueller(DEFAULT_EXT_IOR, Float64(cos), films, Cx(1.52, 0.0),
                                               Float64(wl), [False, True, False, False]), n))
    err = np.abs(ours - np.stack(ref)).max()
    assert err <= _tolerance(table), (err, table.error)


def test_band_limited_mueller_rows_match_a_brute_force_convolution():
    """A 10-film stack on a metal (resonances ~0.1 nm wide, as in
    tests/tabulate/test_band.py): the band-limited rows of its Mueller components
    against each exact component convolved by direct summation on a 0.0005 nm
    grid. Bound 1e-4 as there (a tenth of the default table_error; a missed
    resonance errs by ~1e-3 or more); measured <= 1.3e-5."""
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "eta": 1.2, "k": 7.0, "ext_ior": 1.0,
                         "layers": layers(10, 50.0, 200.0), "tabulate": False})
    data = stack_build.side_data(bsdf.stack.plan[False], False, quantity=MUELLER)
    rows = band.Rows(data, axes.BAND, 1.0)
    xs = np.array([0.0, 0.55])
    vals = rows.values(xs)
    assert vals.shape[-1] == 4
    bins = rows.b0 + np.array([300, 1000, 1500])
    sigma = rows.sigma
    for i, x in enumerate(xs):
        cos = float(axes.band_cos(x))
        for b in bins:
            nu = rows.wavenumbers[b]
            lam = np.arange(1.0 / (nu + 7.0 * sigma), 1.0 / (nu - 7.0 * sigma), 0.0005)
            exact = tabulate_base.evaluate_side(data, np.full(lam.size, cos), np.arange(lam.size),
                                                lam, tabulate_base.side_indices(data, lam))
            g = np.exp(-0.5 * ((1.0 / lam - nu) / sigma) ** 2) / lam ** 2   # dν = dλ / λ²
            ref = (exact * g[:, None]).sum(axis=0) / g.sum()
            np.testing.assert_allclose(vals[i, b], ref, atol=1e-4, rtol=0)
    assert np.abs(vals[..., 2:]).max() > 0.1


# ---------------------------------------------------------------------------
# The plugins
# ---------------------------------------------------------------------------
def _sample(bsdf, wi, wls, mode="Radiance"):
    si = _si(wls)
    si.wi = mi.Vector3f(*(mi.Float(wi[:, i].astype(np.float32)) for i in range(3)))
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    ctx = mi.BSDFContext(getattr(mi.TransportMode, mode))
    rng = np.random.default_rng(9)
    s1 = mi.Float(rng.uniform(0, 1, len(wi)).astype(np.float32))
    _, w = bsdf.sample(ctx, si, s1, mi.Point2f(0.5, 0.5))
    return np.array(w).transpose(3, 2, 0, 1)     # (lane, wavelength, 4, 4)


def test_plugins_read_the_table_and_stay_physical(mode="Radiance"):
    """thinfilm_dielectric (both lobes, both sides) with a table against the same
    stack evaluated exactly (tabulate false): the rotated Mueller matrices agree
    within the table's bound; a rotation into Mitsuba's Stokes bases mixes two
    entries with weights cos 2a, sin 2a (|cos| + |sin| <= sqrt 2 per side), so 2x
    the bound of the components. Random Stokes inputs stay physical (S0 >= 0,
    degree of polarization <= 1, 1e-5 relative for float32 rounding, as
    tests/cross/test_polarized.py). (One transport mode: the table's components do not
    depend on it; the rotations of both are tests/cross/test_polarized.py's.)"""
    props = {"type": "thinfilm_dielectric", "layers": layers(10, 10.0, 30.0), "int_ior": 1.52,
             "spectral_resolution": 0.0}
    table = mi.load_dict(dict(props, tabulate=True))
    exact = mi.load_dict(dict(props, tabulate=False))
    assert table.stack.mode() == "table" and exact.stack.mode() == "exact"
    rng = np.random.default_rng(4)
    n = 2000
    th, ph = rng.uniform(0.0, math.pi, n), rng.uniform(0.0, 2 * math.pi, n)
    wi = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=1)
    wi = wi[np.abs(wi[:, 2]) > tabulate_base.GRAZING_COS]
    wls = [f32(rng.uniform(360.0, 830.0, len(wi))) for _ in range(4)]
    A, B = _sample(table, wi, wls, mode), _sample(exact, wi, wls, mode)
    bound = 2.0 * max(_tolerance(s.table) for s in table.stack.plan.values())
    # same lobe choices except within the table's error of the threshold
    same = np.all(np.isclose(A[:, :, 0, 0] > 0, B[:, :, 0, 0] > 0), axis=1)
    diff = np.abs(A - B)[same].max()
    assert same.mean() > 0.95 and diff <= bound * max(1.0, np.abs(B).max()), diff
    S_in = np.concatenate([np.ones((len(wi), 1)), rng.normal(size=(len(wi), 3))], axis=1)
    S_in[:, 1:] *= (rng.uniform(0, 1, len(wi)) / np.linalg.norm(S_in[:, 1:], axis=1))[:, None]
    S = np.einsum("nwij,nj->nwi", A.astype(np.float64), S_in)
    assert np.all(np.isfinite(S)) and S[..., 0].min() >= -1e-6
    assert np.all(np.linalg.norm(S[..., 1:], axis=-1) <= S[..., 0] * (1 + 1e-5) + 1e-6)


def test_auto_tabulates_deep_polarized_stacks():
    """``tabulate="auto"`` in a polarized variant: fewer than AUTO_MIN_FILMS films
    stay exact (their amplitudes cost less than a lookup of 4 channels, and the
    matrices stay at tests/cross/test_polarized.py's tolerances); from it on a Mueller
    table (reflection: 4 channels) within the auto budget of AUTO_MAX_FLOATS;
    gradients bypass it."""
    fewer = mi.load_dict({"type": "thinfilm_conductor",
                          "layers": layers(AUTO_MIN_FILMS - 1, 10.0, 30.0)})
    deep = mi.load_dict({"type": "thinfilm_conductor", "layers": layers(AUTO_MIN_FILMS, 10.0, 30.0)})
    assert fewer.stack.mode() == "exact"
    assert deep.stack.mode() == "table"
    table = deep.stack.plan[False].table
    assert table.channels == 4 and table.texels * 4 <= AUTO_MAX_FLOATS
    assert deep.stack.plan[False].build_report["result"] == "table"
    params = mi.traverse(deep)
    key = next(k for k in params.keys() if k.endswith("layers.0.thickness"))
    dr.enable_grad(params[key])
    assert deep.stack.current_plan(False, False).table is None


@pytest.mark.parametrize("plugin,films,tol", [("thinfilm_conductor", 10, 5e-5),
                                              ("thinfilm_dielectric", 30, 2e-4)])
def test_exact_deep_stacks_run_as_a_film_loop(plugin, films, tol):
    """Without a table, stacks of LOOP_MIN_FILMS films or more are evaluated by a loop
    over the films' buffers (optics.mueller.loop_amplitudes: one loop body in the
    kernel whatever the depth), against tmm's matrices (tests/cross/test_polarized.py's
    construction and rotation), both lobes of the dielectric from both sides.
    Tolerances: 10 films at tests/cross/test_polarized.py's TMM_TOL (measured 1.6e-5);
    30 resonant films on glass carry float32 rounding through 30 steps, measured
    7.6e-5 for the loop and 8.3e-5 for the unrolled recursion it replaces."""
    from tests.support.polarized import directions, interaction, mat, rotated, tmm_matrix

    d = benchmark_thicknesses(films)
    stack = [(2.3 if i % 2 == 0 else 1.46, float(d[i])) for i in range(films)]
    substrate = {"thinfilm_conductor": {"eta": 0.2, "k": 3.0}, "thinfilm_dielectric": {"int_ior": 1.5}}
    n_sub = 0.2 + 3.0j if plugin == "thinfilm_conductor" else 1.5
    bsdf = mi.load_dict({"type": plugin, "layers": "; ".join(f"{n} {t!r}" for n, t in stack),
                         "ext_ior": 1.0, "tabulate": False, **substrate[plugin]})
    assert all(side.loop is not None for side in bsdf.stack.plan.values())
    rng = np.random.default_rng(11)
    dielectric = plugin == "thinfilm_dielectric"
    for component in ((0, 1) if dielectric else (0,)):
        wi = directions(rng, 120, 0.0, np.pi if dielectric else np.pi / 2)
        wi = wi[np.abs(wi[:, 2]) > 0.02][:60]
        wls = rng.uniform(360.0, 830.0, (len(wi), 4))
        ctx = mi.BSDFContext(mi.TransportMode.Radiance)
        ctx.component = component
        bs, w = bsdf.sample(ctx, interaction(wi, wls), mi.Float(0.5), mi.Point2f(0.5, 0.5))
        ours, wo = mat(w), np.array(bs.wo).T.astype(np.float64)
        ref = np.zeros((len(wi), 4, 4, 4))
        for i in range(len(wi)):
            n_list = [1.0, *[n for n, _ in stack], n_sub]
            d_list = [np.inf, *[t for _, t in stack], np.inf]
            if wo[i, 2] <= 0:       # light arrives along -wo from inside
                n_list, d_list = n_list[::-1], d_list[::-1]
            for k in range(4):
                ref[i, k] = tmm_matrix(n_list, d_list, abs(wo[i, 2]), wls[i, k], component == 1)
            if component == 1:
                ref[i] *= (1.0 / n_sub if wi[i, 2] > 0 else n_sub) ** 2
        ref = rotated(ref, wo, wi)
        valid = np.abs(ref[:, :, 0, 0]).max(axis=1) > 0
        assert valid.mean() > 0.3
        assert np.abs(ours - ref)[valid].max() < tol
        assert np.abs(ref[valid][:, :, 2:, 2:]).max() > 0.1
