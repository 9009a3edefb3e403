"""Band-limited tables (``spectral_resolution``, thinfilm_mi/tabulate/band.py): a verified
table of a resonant stack, off by default, the option's validation, the inside side of a
stack on glass, builds on parallel loader threads."""
import math

import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.band import brute_force, resonant_side
from tests.support.stacks import benchmark_layers
from thinfilm_mi.render import kernel as K
from thinfilm_mi.tabulate import band as band_tables
from thinfilm_mi.tabulate import band_rows
from thinfilm_mi.tabulate import base as tabulate_base

pytestmark = pytest.mark.usefixtures("llvm")


def test_a_resonant_stack_gets_a_verified_band_limited_table(monkeypatch):
    """The 10-film stack on a metal, which no table of the exact values resolves,
    gets a band-limited one at the default target; its lookups agree with
    brute-force R_σ within the verified error (plus the float32 texture's
    rounding), and its colours under D65/A/F11 pass the check."""
    side = resonant_side(monkeypatch)
    stats = tabulate_base.BuildReport()
    table = band_tables.build_table(side, 1e-3, K.GRID, tabulate_base.MAX_TEXELS, 1.0, report=stats)
    assert table is not None, stats
    assert stats["exact_attempt"]["result"] != "table"
    assert table.resolution == 1.0 and table.error <= 1e-3
    assert stats["colour_error"] <= band_tables.COLOUR_TOLERANCE
    # lookups at off-node points against the brute force
    wl = np.array([452.3, 537.9, 611.1])
    for theta in (20.0, 50.0):
        cos = math.cos(math.radians(theta))
        ref = brute_force(side, cos, 1.0 / wl, band_rows.sigma_nu(1.0))
        got = [table.lookup(mi.Float(cos), mi.Spectrum(1.0), mi.Spectrum(1.0),
                            mi.Spectrum(float(w)))[0][0] for w in wl]
        got = np.array([float(g[0]) for g in got])
        np.testing.assert_allclose(got, ref, atol=1e-3 + 1e-4)


def test_band_limiting_is_off_by_default_and_leaves_thin_stacks_alone(monkeypatch):
    """Default settings: no band-limited table (the resonant stack is evaluated
    exactly); with a resolution, a 3-film stack keeps its table of the exact
    values (band-limiting only applies where that fails)."""
    assert K.DEFAULT_SPECTRAL_RESOLUTION == 1.0
    K.TABLE_CACHE.clear()
    b = mi.load_dict({"type": "thinfilm_conductor", "material": "Al", "tabulate": True,
                      "layers": "2.3 130; 1.46 101; 2.3 105", "spectral_resolution": 1.0})
    assert b.stack.mode() == "table"
    report = b.stack.plan[False].build_report
    assert report["result"] == "table" and report["resolution"] == 0.0
    K.TABLE_CACHE.clear()


@pytest.mark.parametrize("value", [-1.0, float("nan"), float("inf"), 21.0, "1", True])
def test_bad_spectral_resolution_is_refused(value):
    with pytest.raises((tf.ThinFilmError, RuntimeError), match="spectral_resolution"):
        mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 300",
                      "spectral_resolution": value})


def test_band_table_of_a_side_lit_from_inside_glass():
    """The split angle axis and the T channel: the inside side of a 10-film stack
    on glass (light from the glass, total reflection beyond the critical angle)
    tabulated band-limited (forced here: its exact values have a table too). The
    table verifies within the target, and its R and T agree with brute-force
    R_σ and T_σ at off-node points on both sides of the critical angle (41.8°)
    within the verified error plus the float32 texture's rounding."""
    layers = benchmark_layers(10)
    # (a lossless stack's inside is read from its outside table, render/mirror.py:
    # the build data of the inside side is taken from the plan, not from a load)
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "int_ior": 1.5, "ext_ior": 1.0,
                         "layers": layers, "tabulate": False})
    inside = K.side_data(bsdf.stack.plan[True], True)
    assert np.all(np.asarray(inside.n0(np.array([500.0]))) > 1.2) and inside.transmission
    table = band_tables.build_band_table(inside, 1e-3, K.GRID, tabulate_base.MAX_TEXELS, 1.0)
    assert table is not None and table.axis.name == "tir" and table.channels == 2
    assert table.error <= 1e-3
    sig = band_rows.sigma_nu(1.0)
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
    K.TABLE_CACHE.clear()
    scene = mi.load_string(f'<scene version="3.0.0">{shapes}</scene>', parallel=True)
    got = {}
    for shape in scene.shapes():
        table = shape.bsdf().stack.plan[False].table
        assert table is not None and table.resolution > 0
        got[round(float(shape.bbox().center().x))] = np.array(table.texture.tensor())
    for j, s in enumerate(stacks):
        K.TABLE_CACHE.clear()
        b = mi.load_dict({"type": "thinfilm_conductor", "material": "Al", "layers": s})
        np.testing.assert_array_equal(got[j], np.array(b.stack.plan[False].table.texture.tensor()))
    K.TABLE_CACHE.clear()
