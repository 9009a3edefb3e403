"""Band-limited tables (``spectral_resolution``, thinfilm_mi/tabulate/band.py): the convolved
reflectance ``R_σ`` against a brute-force fine-grid convolution, a verified table of a
resonant stack, the resonance search and the first level's amplitudes, the sheared axis,
and the option's validation."""
from __future__ import annotations

import math

import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.stacks import benchmark_layers, benchmark_thicknesses
from thinfilm_mi.render import stack_build, stack_plan
from thinfilm_mi.render.textures import GRID
from thinfilm_mi.tabulate import axes, policy
from thinfilm_mi.tabulate import band as band_tables
from thinfilm_mi.tabulate import base as tabulate_base
from thinfilm_mi.tabulate import exact as tables

pytestmark = pytest.mark.usefixtures("llvm")


def _resonant_side(monkeypatch, films=10):
    """The ambient side of a resonant stack (2.3/1.46 films on a constant metal):
    the SideData the kernel hands to the build (captured; spectral_resolution 0, so
    the build only tries, and fails, a table of the exact values)."""
    layers = benchmark_layers(films)
    captured = {}
    build = tables.build_exact_table

    def capture(side, *args, **kwargs):
        captured["side"] = side
        return build(side, *args, **kwargs)

    monkeypatch.setattr(tables, "build_exact_table", capture)
    stack_build.TABLE_CACHE.clear()
    with pytest.warns(UserWarning):
        mi.load_dict({"type": "thinfilm_conductor", "eta": 1.2, "k": 7.0, "layers": layers,
                      "ext_ior": 1.0, "tabulate": True, "spectral_resolution": 0.0})
    stack_build.TABLE_CACHE.clear()
    return captured["side"]


def _brute_force(side, cos, nu_out, sigma_nu, step=0.0005):
    """R at one angle convolved by direct summation with the Gaussian in wavenumber,
    on a grid of ``step`` nm (exact R of the build's float64 evaluator)."""
    out = []
    for nu in nu_out:
        half = 7.0 * sigma_nu
        lam = np.arange(1.0 / (nu + half), 1.0 / (nu - half), step)
        R = tabulate_base.evaluate_side(side, np.full(lam.size, cos), np.arange(lam.size), lam,
                             tabulate_base.side_indices(side, lam))[:, 0]
        x = 1.0 / lam
        g = np.exp(-0.5 * ((x - nu) / sigma_nu) ** 2) * x * x   # dν = dλ / λ²
        out.append(float(np.sum(R * g) / np.sum(g)))
    return np.array(out)


def test_band_limited_values_match_a_brute_force_convolution(monkeypatch):
    """R_σ of the build's rows at a few (angle, wavenumber) points against the exact
    R on a 0.0005 nm grid convolved by direct summation. The 10-film stack has
    resonances ~0.1 nm wide and narrower (R drops by up to 0.3 within them),
    far below the rows' first step (4 bins of 0.3 σ, ~1.2 nm at 560 nm); the
    resonance search of the first level must find them. Measured difference <=
    4.4e-6 at normal, 42° and 71° incidence; the bound 1e-4 is a tenth of the
    default table_error, and a missed resonance errs by ~1e-3 or more (measured
    9e-4 with the looser Simpson tolerance 5e-5, 1.7e-2 without the panels'
    grading)."""
    side = _resonant_side(monkeypatch)
    rows = band_tables.Rows(side, axes.BAND, 1.0)
    xs = np.array([0.0, 0.3, 0.7])
    vals = rows.values(xs)
    bins = rows.b0 + np.array([100, 600, 1100, 1500])
    for i, x in enumerate(xs):
        cos = float(axes.band_cos(x))
        ref = _brute_force(side, cos, rows.wavenumbers[bins], rows.sigma)
        np.testing.assert_allclose(vals[i, bins, 0], ref, atol=1e-4, rtol=0)


def test_sample_is_the_gaussian_sum_of_the_bins_anywhere(monkeypatch):
    """``Rows.sample`` (the Gaussian summed over a row's bins by a recurrence) against the
    sum written out with one exponential a bin, at random wavenumbers inside the bins'
    extent, near its ends and beyond them (no bins there: zero), over rows whose points
    differ. The recurrence's rounding grows by ~1e-16 a bin over 2 reach + 2 bins, hence
    1e-12 of the largest value."""
    side = _resonant_side(monkeypatch)
    rows = band_tables.Rows(side, axes.BAND, 1.0)
    xs = np.array([0.0, 0.45])
    rows.compute(xs)
    raw = np.stack([rows._bins_of[k] for k in rows._keys(xs)])
    rng = np.random.default_rng(3)
    nu = rows.wavenumbers
    span = nu[0] - nu[-1]
    nus = np.stack([rng.uniform(nu[-1] - 0.2 * span, nu[0] + 0.2 * span, 400) for _ in xs])
    got = rows.sample(xs, nus)
    g = np.exp(-0.5 * ((nus[..., None] - nu[None, None, :]) / rows.sig) ** 2) / (
        rows.sig * math.sqrt(2.0 * math.pi))
    # the bins within the Gaussian's reach: bins k0 - reach .. k0 + reach + 1 of bin k0
    k0 = np.floor((rows.top - nus) / rows.w + rows.b0)[..., None]
    b = np.arange(nu.size)[None, None, :]
    g *= (b >= k0 - rows.reach) & (b <= k0 + rows.reach + 1)
    ref = np.einsum("rkb,rbc->rkc", g, raw)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    beyond = (nus > nu[0] + (rows.reach + 2) * rows.w) | (nus < nu[-1] - (rows.reach + 2) * rows.w)
    assert beyond.any() and not np.any(got[beyond])


def test_a_resonant_stack_gets_a_verified_band_limited_table(monkeypatch):
    """The 10-film stack on a metal, which no table of the exact values resolves,
    gets a band-limited one at the default target; its lookups agree with
    brute-force R_σ within the verified error (plus the float32 texture's
    rounding), and its colours under D65/A/F11 pass the check."""
    side = _resonant_side(monkeypatch)
    stats = tabulate_base.BuildReport()
    table = band_tables.build_table(side, 1e-3, GRID, policy.MAX_TEXELS, 1.0, report=stats)
    assert table is not None, stats
    assert stats["exact_attempt"]["result"] != "table"
    assert table.resolution == 1.0 and table.error <= 1e-3
    assert stats["colour_error"] <= band_tables.COLOUR_TOLERANCE
    _check_lookups(table, side)


def _check_lookups(table, side):
    """Lookups at off-node points against the brute force, within the target 1e-3 (plus
    the float32 texture's rounding)."""
    wl = np.array([452.3, 537.9, 611.1])
    for theta in (20.0, 50.0):
        cos = math.cos(math.radians(theta))
        ref = _brute_force(side, cos, 1.0 / wl, band_tables.sigma_nu(1.0))
        got = [table.lookup(mi.Float(cos), mi.Spectrum(1.0), mi.Spectrum(1.0),
                            mi.Spectrum(float(w)))[0][0] for w in wl]
        got = np.array([float(g[0]) for g in got])
        np.testing.assert_allclose(got, ref, atol=1e-3 + 1e-4)


def test_a_sheared_v_axis_found_too_coarse_is_made_finer_and_the_table_verified(monkeypatch):
    """The rounds' other refinement: where a round's error along the wavelength axis
    exceeds half the target, the build makes the v spacing finer (on this sheared axis of
    a side lit from the ambient: more v nodes next round; the unsheared axis is
    :func:`test_band_table_of_a_side_lit_from_inside_glass`). A first spacing three times
    the quantity's own forces it (measured: v error 0.0196 at 363 nodes, then 1.0e-4 at
    1207); the table is verified and its lookups agree with the brute force as at the
    default spacing."""
    side = _resonant_side(monkeypatch)
    quantity = type(side.quantity)
    monkeypatch.setattr(quantity, "v_spacing", 3 * quantity.v_spacing)
    stats = tabulate_base.BuildReport()
    table = band_tables.build_table(side, 1e-3, GRID, policy.MAX_TEXELS, 1.0, report=stats)
    assert table is not None and table.error <= 1e-3, stats
    (_, nv_first, _, err_v_first), *_, (_, nv_last, _, err_v_last) = stats["errors"]
    assert err_v_first > 0.5e-3 and nv_last > nv_first and err_v_last <= 0.5e-3, stats["errors"]
    _check_lookups(table, side)


def test_band_limiting_is_off_by_default_and_leaves_thin_stacks_alone(monkeypatch):
    """Default settings: no band-limited table (the resonant stack is evaluated
    exactly); with a resolution, a 3-film stack keeps its table of the exact
    values (band-limiting only applies where that fails)."""
    assert stack_plan.DEFAULT_SPECTRAL_RESOLUTION == 1.0
    stack_build.TABLE_CACHE.clear()
    b = mi.load_dict({"type": "thinfilm_conductor", "material": "Al", "tabulate": True,
                      "layers": "2.3 130; 1.46 101; 2.3 105", "spectral_resolution": 1.0})
    assert b.stack.mode() == "table"
    report = b.stack.plan[False].build_report
    assert report["result"] == "table" and report["resolution"] == 0.0
    stack_build.TABLE_CACHE.clear()


def test_near_zeros_finds_a_narrow_pole():
    """A zero 0.01 sample steps off the axis, between samples of a smooth function,
    is found at its position and distance (the resonance search of the first
    level); a zero farther than RESOLVE_DISTANCE is not reported."""
    x = np.arange(40.0)
    for z0, found in ((17.3 + 0.01j, True), (25.6 - 0.4j, True), (10.2 + 9.0j, False)):
        f = (x - z0) * (1.0 + 0.02 * x)
        samples = np.stack([f.real, f.imag], axis=-1)[None]
        r, pos, dist = band_tables.near_zeros(samples, 0)
        assert (r.size == 1) == found
        if found:
            assert abs(pos[0] - z0.real) < 1e-6 and abs(dist[0] - abs(z0.imag)) < 1e-6


def test_amplitudes_give_the_exact_reflectance(monkeypatch):
    """The first level's amplitudes (no resonant denominator) give R = |N|^2/|D|^2
    of the float64 Stack to the rounding of the inputs (measured 1.4e-8: the
    kernel's indices and thicknesses are float32 spectra and values; a wrong
    phase, sign or admittance errs by 1e-2 or more)."""
    side = _resonant_side(monkeypatch, films=10)
    wl = np.linspace(400.0, 700.0, 301)
    cos = np.full(wl.size, 0.8)
    terms, _ = band_tables.amplitudes(side, cos, np.arange(wl.size), wl, tabulate_base.side_indices(side, wl))
    R = band_tables.powers_of(terms, False)[:, 0]
    layers = [(n(np.array([500.0]))[0].real, d) for n, d in side.films]
    ref = tf.Stack(layers=layers, substrate=complex(1.2, 7.0), ambient=1.0).rt(wl, math.acos(0.8)).R
    assert np.max(np.abs(R - ref)) < 1e-7


@pytest.mark.parametrize("value", [-1.0, float("nan"), float("inf"), 21.0, "1", True])
def test_bad_spectral_resolution_is_refused(value):
    with pytest.raises((tf.ThinFilmError, RuntimeError), match="spectral_resolution"):
        mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 300",
                      "spectral_resolution": value})


@pytest.mark.parametrize("v_factor", [1, 3])
def test_band_table_of_a_side_lit_from_inside_glass(monkeypatch, v_factor):
    """The split angle axis and the T channel: the inside side of a 10-film stack
    on glass (light from the glass, total reflection beyond the critical angle)
    tabulated band-limited (forced here: its exact values have a table too). The
    table verifies within the target, and its R and T agree with brute-force
    R_σ and T_σ at off-node points on both sides of the critical angle (41.8°)
    within the verified error plus the float32 texture's rounding. With a first v
    spacing three times the quantity's own, the rounds find the wavelength axis too
    coarse and compute every row again on a finer one (this axis is not sheared: it
    needs the exit medium's index), and the table verifies the same."""
    layers = benchmark_layers(10)
    # (a lossless stack's inside is read from its outside table, render/mirror.py:
    # the build data of the inside side is taken from the plan, not from a load)
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "int_ior": 1.5, "ext_ior": 1.0,
                         "layers": layers, "tabulate": False})
    inside = stack_build.side_data(bsdf.stack.plan[True], True)
    assert np.all(np.asarray(inside.n0(np.array([500.0]))) > 1.2) and inside.transmission
    quantity = type(inside.quantity)
    monkeypatch.setattr(quantity, "v_spacing", v_factor * quantity.v_spacing)
    stats = tabulate_base.BuildReport()
    table = band_tables.build_band_table(inside, 1e-3, GRID, policy.MAX_TEXELS, 1.0, report=stats)
    assert table is not None and table.axis.name == "tir" and table.channels == 2
    assert table.error <= 1e-3
    if v_factor > 1:
        (_, nv_first, _, err_v_first), *_, (_, nv_last, _, _) = stats["errors"]
        assert err_v_first > 0.5e-3 and nv_last > nv_first, stats["errors"]
    sig = band_tables.sigma_nu(1.0)
    for theta in (25.0, 55.0):
        cos = math.cos(math.radians(theta))
        for w in (471.3, 633.7):
            nu0 = 1.0 / w
            lam = np.arange(1.0 / (nu0 + 7 * sig), 1.0 / (nu0 - 7 * sig), 0.0005)
            RT = tabulate_base.evaluate_side(inside, np.full(lam.size, cos), np.arange(lam.size), lam,
                                  tabulate_base.side_indices(inside, lam))
            g = np.exp(-0.5 * ((1.0 / lam - nu0) / sig) ** 2) / (lam * lam)
            ref = (RT * g[:, None]).sum(axis=0) / g.sum()
            n0 = float(inside.n0(np.array([w]))[0])
            ne = float(np.asarray(inside.n_exit(np.array([w]))).real[0])
            got = table.lookup(mi.Float(cos), mi.Spectrum(n0), mi.Spectrum(ne), mi.Spectrum(w))
            got = np.array([float(got[c][0][0]) for c in range(2)])
            np.testing.assert_allclose(got, ref, atol=1e-3 + 1e-4)


def test_band_builds_on_parallel_loader_threads():
    """Mitsuba's parallel scene loading runs plugin constructors on several threads
    at once: two deep stacks build band-limited tables together (float64 kernel
    launches, the rows' numpy work, the shared table cache) and get exactly the
    tables a sequential load builds."""
    def layers(seed):
        d = np.random.default_rng(seed).uniform(50.0, 200.0, 10)
        return "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(10))

    stacks = [layers(6), layers(7)]
    shapes = "".join(
        f'<shape type="sphere"><point name="center" value="{j}, 0, 0"/>'
        f'<bsdf type="thinfilm_conductor"><string name="material" value="Al"/>'
        f'<string name="layers" value="{s}"/></bsdf></shape>' for j, s in enumerate(stacks))
    stack_build.TABLE_CACHE.clear()
    scene = mi.load_string(f'<scene version="3.0.0">{shapes}</scene>', parallel=True)
    got = {}
    for shape in scene.shapes():
        table = shape.bsdf().stack.plan[False].table
        assert table is not None and table.resolution > 0
        got[round(float(shape.bbox().center().x))] = np.array(table.texture.tensor())
    for j, s in enumerate(stacks):
        stack_build.TABLE_CACHE.clear()
        b = mi.load_dict({"type": "thinfilm_conductor", "material": "Al", "layers": s})
        np.testing.assert_array_equal(got[j], np.array(b.stack.plan[False].table.texture.tensor()))
    stack_build.TABLE_CACHE.clear()


def test_near_zeros_with_exponents_match_the_unscaled_function():
    """The loop's power-of-two rescaling (samples ``f 2^E``, random exponents per
    sample) finds the same zeros, bit for bit, as the unscaled samples: the
    neighbours and the cubic are scaled by exact powers of two."""
    x = np.arange(60.0)
    f = (x - (31.3 + 0.02j)) * (x - (12.6 - 0.5j)) * (1.0 + 0.02 * x)
    E = np.random.default_rng(1).integers(-40, 40, x.size).astype(np.float64)
    plain = np.stack([f.real, f.imag], axis=-1)[None]
    scaled = np.stack([np.ldexp(f.real, -E.astype(int)), np.ldexp(f.imag, -E.astype(int))], axis=-1)[None]
    for a, b in zip(band_tables.near_zeros(plain, 0), band_tables.near_zeros(scaled, 0, E[None])):
        assert np.array_equal(a, b)
    assert band_tables.near_zeros(plain, 0)[0].size == 2


def test_amplitudes_stay_in_range_at_any_depth(monkeypatch):
    """1000 films (MAX_FILMS; the amplitudes grow by up to ~2.8 per film, beyond
    float64's range for their squares from ~340 films without the rescaling, which
    is active here: exponents of hundreds): R = |N|^2/|D|^2 from the rescaled
    amplitudes matches the build's exact float64 evaluation (measured 7e-14; a lost
    exponent or an overflow errs by O(1) or gives NaN)."""
    captured = {}

    def capture(side, *args, **kwargs):
        captured["side"] = side

    monkeypatch.setattr(tables, "build_exact_table", capture)
    layers = benchmark_layers(1000)
    stack_build.TABLE_CACHE.clear()
    with pytest.warns(UserWarning):
        mi.load_dict({"type": "thinfilm_conductor", "eta": 1.2, "k": 7.0, "layers": layers,
                      "ext_ior": 1.0, "tabulate": True, "spectral_resolution": 0.0})
    stack_build.TABLE_CACHE.clear()
    side = captured["side"]
    wl = np.linspace(400.0, 700.0, 301)
    cos = np.tile([1.0, 0.3], wl.size)
    rows = np.repeat(np.arange(wl.size), 2)
    idx = tabulate_base.side_indices(side, wl)
    terms, E = band_tables.amplitudes(side, cos, rows, wl, idx)
    assert E.min() > 100.0
    R = band_tables.powers_of(terms, False)[:, 0]
    ref = tabulate_base.evaluate_side(side, cos, rows, wl, idx)[:, 0]
    assert np.all(np.isfinite(R)) and np.max(np.abs(R - ref)) < 1e-10


def test_the_adaptive_panels_read_the_first_levels_amplitudes(monkeypatch):
    """The panels that refine resonances take ``R`` from the first level's smooth
    amplitudes (a quintic through six samples, ``band_tables.Amplitudes``) instead of
    the films' loop: ``R_σ`` of whole rows agrees with the films' values within 1e-5
    (measured 4.5e-8 on this stack of constant indices; 2e-5 on the benchmark stacks,
    where the clamped dispersive data kink at 360 and 830 nm), with 38 % fewer
    evaluations of the films here (on 30 films, 60 % fewer)."""
    side = _resonant_side(monkeypatch)
    xs = np.array([0.1, 0.5, 0.9])
    out = {}
    for interpolate in (False, True):
        rows = band_tables.Rows(side, axes.BAND, 1.0)
        assert rows.interpolate      # 32 samples per fringe or more here
        rows.interpolate = interpolate
        out[interpolate] = (rows.values(xs), rows.points)
    assert np.max(np.abs(out[True][0] - out[False][0])) < 1e-5
    assert out[True][1] < 0.8 * out[False][1]


def test_a_sheared_table_of_r_and_t_matches_a_brute_force_convolution():
    """30 films on glass, lit from the ambient: a band-limited table of ``R`` and ``T``
    on the sheared axis (``tabulate.band.Shear``). Its lookups agree with ``R_σ`` and
    ``T_σ`` convolved by direct summation (measured 4.2e-5 over 25 points, the
    verified error 2.5e-4) within the verified error plus 1e-4 (the float32 texture
    and the brute force's σ/400 steps); an axis sheared the wrong way, or nodes
    sampled at the plain wavenumbers, errs by 1e-2 or more."""
    b = mi.load_dict({"type": "thinfilm_dielectric", "layers": benchmark_layers(30), "int_ior": 1.5,
                      "tabulate": False})
    side = stack_build.side_data(b.stack.plan[False], True)
    table = band_tables.build_band_table(side, 1e-3, GRID, policy.MAX_TEXELS, 1.0)
    assert table is not None and table.shear is not None and table.channels == 2
    sig = band_tables.sigma_nu(1.0)
    for theta in (0.0, 50.0, 75.0):
        cos = math.cos(math.radians(theta))
        for wl in (405.3, 561.2, 781.4):
            nu = 1.0 / wl
            lam = 1.0 / np.arange(nu - 6 * sig, nu + 6 * sig, sig / 400)
            vals = tabulate_base.evaluate_side(side, np.full(lam.size, cos), np.arange(lam.size), lam,
                                               tabulate_base.side_indices(side, lam))
            g = np.exp(-0.5 * ((1.0 / lam - nu) / sig) ** 2)
            ref = (vals * g[:, None]).sum(axis=0) / g.sum()
            got = table.lookup(mi.Float(cos), mi.Spectrum(1.0), mi.Spectrum(1.0), mi.Spectrum(wl))
            got = np.array([float(got[c][0][0]) for c in range(2)])
            np.testing.assert_allclose(got, ref, atol=table.error + 1e-4, rtol=0)


def test_the_shear_follows_the_films_and_refuses_bad_data():
    """``P(s)`` is the films' ``Σ d_j Re sqrt(n_j² - n0² s) / Σ d_j n_j`` within the
    cubic's fit (measured 1.9e-5 for the 2.3/1.46 stack; bound 1e-4), 1 at normal incidence and
    falling to grazing; a stored shear that is not one raises (the table store then
    rebuilds)."""
    from thinfilm_mi.tabulate.band import Shear

    d = benchmark_thicknesses(30)
    films = [((lambda wl, n=2.3 if i % 2 == 0 else 1.46: np.full(np.shape(wl), n + 0j)), float(d[i]))
             for i in range(30)]
    shear = Shear.of(films, 1.0)
    s = np.linspace(0.0, 1.0, 101)
    n = np.array([2.3 if i % 2 == 0 else 1.46 for i in range(30)])
    want = (d[None, :] * np.sqrt(n[None, :] ** 2 - s[:, None])).sum(1) / (d * n).sum()
    np.testing.assert_allclose(shear.factor_np(s), want, atol=1e-4, rtol=0)
    assert abs(shear.factor_np(0.0) - 1.0) < 1e-4 and np.all(np.diff(shear.factor_np(s)) < 0)
    assert shear.low == pytest.approx(tabulate_base.SIGMA_MIN * shear.factor_np(1.0), rel=1e-3)
    assert Shear.from_plain(shear.to_plain()).coeffs == shear.coeffs
    for bad in ({"coeffs": [1.0, 0.1], "low": 0.001}, {"coeffs": [1.0, float("nan"), 0, 0], "low": 0.001},
                {"coeffs": [1.0, 0, 0, 0], "low": -1.0}):
        with pytest.raises(ValueError):
            Shear.from_plain(bad)
    assert Shear.of([], 1.0) is None
