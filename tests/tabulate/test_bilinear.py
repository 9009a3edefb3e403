"""Tables resampled for bilinear lookups (thinfilm_mi/tabulate/bilinear.py): against the
float64 recursion (tmm-checked in tests/optics) on every angle axis, against the spline
they come from (the coordinate mapping, the split axis's seam), the caps that keep a
spline, and what the build reports."""
import math

import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.kernels import interaction
from tests.support.stacks import benchmark_layers
from tests.support.tables import F32, random_points, ref_R
from thinfilm_mi.render import media as media_mod
from thinfilm_mi.render import stack_build, stack_plan
from thinfilm_mi.render.textures import GRID
from thinfilm_mi.tabulate import band, bilinear, quantities
from thinfilm_mi.tabulate.base import BILINEAR, CUBIC

pytestmark = pytest.mark.usefixtures("llvm")

#: (plugin properties, side, angle axis): a plain axis (one film on gold), a split one
#: (gold on glass lit from the glass: total internal reflection beyond the critical
#: angle, the surface plasmon dip just beyond it) and a band-limited one (30 films)
CASES = [
    ({"type": "thinfilm_conductor", "material": "Au", "layers": "SiO2 500"}, False, "plain"),
    ({"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": "Au 20"}, True, "tir"),
    ({"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": benchmark_layers(30)}, False,
     "band"),
]


def _load(props):
    stack_build.TABLE_CACHE.clear()
    return mi.load_dict(dict(props, tabulate=True))


def _reference(props, inside):
    ref = tf.Stack(props["layers"], substrate=props.get("material", props.get("int_ior")),
                   ambient=media_mod.DEFAULT_EXT_IOR)
    return ref.reversed() if inside else ref


@pytest.mark.parametrize("props, inside, axis", CASES[:2])
def test_resampled_tables_match_float64_within_their_error(props, inside, axis):
    """Through the plugin, as a render reads it: the bilinear table is within its
    ``error`` (spline's plus resampling's, <= ``table_error``) of the float64 recursion
    at random points outside the grazing sliver, both channels where it has two. The
    1.5x and the float32 term are the spline tables' allowance (tests/support/tables.py):
    a bilinear cell errs most at its centre, which the resampling verifies."""
    bsdf = _load(props)
    side = bsdf.stack.plan[inside]
    table = side.table
    assert table.interpolation is BILINEAR and table.axis.name == axis
    assert max(table.factors) > 1 and table.error <= stack_plan.DEFAULT_TABLE_ERROR
    assert side.build_report["interpolation"] == "linear"
    assert side.build_report["spline_error"] <= bilinear.SPLINE_SHARE * stack_plan.DEFAULT_TABLE_ERROR
    cos, wls = random_points(20000, seed=5)
    transmission = table.channels > 1
    out = bsdf.stack.reflectance(interaction(wls), mi.Float(cos.astype(np.float32)),
                                 inside=inside, transmission=transmission)
    out = out if transmission else (out,)
    ref = _reference(props, inside)
    worst = 0.0
    for c, got in enumerate(out):
        for i in range(4):
            want = ref_R(ref, cos, wls[i], T=c == 1)
            worst = max(worst, float(np.max(np.abs(np.array(got)[i] - want))))
    assert worst <= 1.5 * table.error + F32, worst
    assert worst > 1e-6   # the table, not the recursion


@pytest.mark.parametrize("props, inside, axis", CASES)
def test_the_resampling_follows_its_spline(props, inside, axis):
    """The same side's spline (built at SPLINE_SHARE of the target) and its resampling,
    looked up at the same random directions and wavelengths in a kernel: they differ by
    at most what the resampling verified (``error`` minus the spline's), so the fine
    grid's coordinates map onto the spline's, across a split axis's critical angle
    (directions straddling it included) and along a band-limited table's sheared
    wavelength axis. The float32 term: both lookups round their coordinates."""
    bsdf = _load(props)
    side = bsdf.stack.plan[inside]
    data = stack_build.side_data(side, side.transmission and not side.opaque)
    spline = band.build_table(data, bilinear.SPLINE_SHARE * stack_plan.DEFAULT_TABLE_ERROR, GRID,
                              resolution=stack_plan.DEFAULT_SPECTRAL_RESOLUTION)
    assert spline.interpolation is CUBIC and spline.axis.name == axis
    fine = bilinear.resample(spline, data, stack_plan.DEFAULT_TABLE_ERROR, 1 << 22)
    assert fine is not None and fine.interpolation is BILINEAR
    assert (fine.nu, fine.nv) == (spline.nu, spline.nv)
    cos, wls = random_points(20000, seed=6)
    if axis == "tir":   # both sides of the critical angle, 1.6 -> 1.000277
        cos[:2000] = np.float32(0.7804861 + np.linspace(-1e-3, 1e-3, 2000))
    n0 = mi.Spectrum(float(np.asarray(data.n0(GRID))[0]))
    n_exit = mi.Spectrum(float(np.asarray(data.n_exit(GRID)).real[0]))
    wl = mi.Spectrum(*[mi.Float(w.astype(np.float32)) for w in wls])
    c = mi.Float(cos.astype(np.float32))
    a = fine.lookup_channels(c, n0, n_exit, wl)
    b = spline.lookup_channels(c, n0, n_exit, wl)
    dev = max(float(np.max(np.abs(np.array(x) - np.array(y)))) for x, y in zip(a, b))
    assert dev <= (fine.error - spline.error) + F32, (dev, fine.error - spline.error)
    assert dev > 1e-7   # they are different interpolations


def test_a_table_over_the_cap_stays_a_spline(monkeypatch):
    """Where the resampling would exceed the quantity's floats (or the target leaves it
    nothing), the verified spline is what the render reads; a Mueller table (polarized
    variants) is never resampled."""
    props, inside, _ = CASES[0]
    bsdf = _load(props)
    side = bsdf.stack.plan[inside]
    fine = side.table
    data = stack_build.side_data(side, False)
    spline = band.build_table(data, bilinear.SPLINE_SHARE * stack_plan.DEFAULT_TABLE_ERROR, GRID)
    assert bilinear.resample(spline, data, stack_plan.DEFAULT_TABLE_ERROR, fine.nbytes // 4 - 1) is None
    assert bilinear.resample(spline, data, spline.error, 1 << 22) is None     # no budget left
    monkeypatch.setattr(quantities.PowersQuantity, "linear_max_floats", 1000)
    capped = _load(props).stack.plan[inside]
    assert capped.table.interpolation is CUBIC
    assert capped.build_report["interpolation"] == "cubic"
    assert capped.table.error <= bilinear.SPLINE_SHARE * stack_plan.DEFAULT_TABLE_ERROR
    assert quantities.QUANTITIES["mueller"].linear_max_floats == 0


def test_a_resampled_table_keeps_edits_in_one_kernel():
    """A thickness edit gives a table of other factors and shape: its lookup constants are
    opaque, so the render kernel is reused (the spline's guarantee, kept)."""
    from tests.support.kernels import assert_edits_render_from_cache
    from tests.support.stacks import sphere_scene
    scene = mi.load_dict(sphere_scene({"type": "thinfilm_conductor", "material": "Au",
                                       "layers": "SiO2 500", "tabulate": True}))
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("layers.0.thickness"))
    before = scene.shapes()[0].bsdf().stack.plan[False].table
    assert_edits_render_from_cache(scene, params, {key: 300.0})
    after = scene.shapes()[0].bsdf().stack.plan[False].table
    assert after.interpolation is BILINEAR and before.interpolation is BILINEAR
    assert (after.factors, after.nu, after.nv) != (before.factors, before.nu, before.nv)


#: The random stacks' materials (catalog names): dielectric films, and metal films and substrates
DIELECTRICS = ("SiO2", "TiO2", "Al2O3", "MgF2", "Si3N4", "ZnS", "Ta2O5")
METALS = ("Au", "Ag", "Al", "Cu", "Cr", "Ni", "Ti")


def random_stacks(count: int, seed: int = 2):
    """``(layers, substrate)`` of ``count`` stacks of 1-5 films (a fifth metal, 2-30 nm; the
    others dielectric, 10-500 nm) on a metal."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        films = [f"{METALS[rng.integers(len(METALS))]} {rng.uniform(2, 30):.1f}"
                 if rng.random() < 0.2 else
                 f"{DIELECTRICS[rng.integers(len(DIELECTRICS))]} {rng.uniform(10, 500):.1f}"
                 for _ in range(int(rng.integers(1, 6)))]
        yield "; ".join(films), METALS[rng.integers(len(METALS))]


def test_default_tables_against_tmm_on_random_stacks():
    """``thinfilm_conductor`` at default settings (``tabulate="auto"``: a table of ``R`` from
    one film on, bilinear where it fits) on 24 random stacks of 1-5 films: the lookup, as a
    render reads it, against the float64 recursion at 20000 random points outside the
    grazing sliver, and at the worst point of each stack against tmm. Tables of the exact
    values stay within ``table_error``, which the spline and the resampling share: the
    worst (printed with ``-s``) is the figure docs/guides/tables.md gives beside the
    budget. Stacks whose exact values no table resolves get band-limited tables, whose
    ``R`` is the convolved one (up to 0.2 from the exact value at resonances narrower than
    ``spectral_resolution``; tests/tabulate/test_band.py): counted, not compared."""
    import tmm
    cos, wls = random_points(20000, seed=5)
    worst, where, band = 0.0, None, []
    for layers, metal in random_stacks(24):
        bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": metal})
        table = bsdf.stack.plan[False].table
        assert table is not None, layers
        if table.resolution > 0:
            band.append(layers)
            continue
        got = np.array(bsdf.stack.reflectance(interaction(wls), mi.Float(cos.astype(np.float32)),
                                              inside=False, transmission=False))
        ref = tf.Stack(layers, substrate=metal, ambient=media_mod.DEFAULT_EXT_IOR)
        errors = np.stack([np.abs(got[i] - ref_R(ref, cos, wls[i])) for i in range(4)])
        i, k = np.unravel_index(np.argmax(errors), errors.shape)
        wl = float(wls[i][k])
        n0, films, n_sub = ref.indices(np.array([wl]))
        n_list = [n0[0]] + [n[0] for n in films] + [n_sub[0]]
        d_list = [np.inf] + [layer.thickness for layer in ref.layers] + [np.inf]
        want = np.mean([tmm.coh_tmm(p, n_list, d_list, math.acos(float(cos[k])), wl)["R"]
                        for p in "sp"])
        error = abs(float(got[i][k]) - want)
        # the spline tables' allowance (tests/support/tables.py)
        assert error <= 1.5 * table.error + F32, (layers, metal, error, table.error)
        if error > worst:
            worst, where = error, f"{layers} on {metal}"
    print(f"\nworst |R - tmm| of {24 - len(band)} tables of exact values: {worst:.2g} ({where}); "
          f"{len(band)} band-limited")
    assert worst <= stack_plan.DEFAULT_TABLE_ERROR
    assert len(band) <= 4 and worst > 1e-4   # tables of the exact values, and their error
