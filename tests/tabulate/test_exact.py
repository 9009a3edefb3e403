"""Tables of the exact values (thinfilm_mi/tabulate/exact.py), through the BSDFs: their
verified error, both sides with total internal reflection, ``auto`` and what prevents a
table, shared and cached tables, dropped films, incoherent thick films, kernel reuse,
the probe, deep stacks through the film loop."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
import tmm

import thinfilm_mi as tf
from tests.support.kernels import compiled, interaction
from tests.support.stacks import benchmark_layers
from tests.support.tables import F32, STACK, f32, random_points, ref_R
from thinfilm_mi.optics import unpolarized
from thinfilm_mi.render import media as media_mod
from thinfilm_mi.render import stack_build, stack_plan
from thinfilm_mi.tabulate import axes, policy, quantities

pytestmark = pytest.mark.usefixtures("llvm")


def test_table_matches_float64_within_its_verified_error():
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu",
                         "tabulate": True})
    assert bsdf.stack.mode() == "table"
    table = bsdf.stack.plan[False].table
    assert table.error <= 1e-3
    cos, wls = random_points(20000)
    R = bsdf.stack.reflectance(interaction(wls), mi.Float(cos.astype(np.float32)))
    R = np.array(R)
    ref = tf.Stack(STACK, substrate="Cu", ambient=media_mod.DEFAULT_EXT_IOR)
    err = max(np.max(np.abs(R[i] - ref_R(ref, cos, wls[i]))) for i in range(4))
    assert err <= 1.5 * table.error + F32, err
    assert err > 1e-6   # it really is the interpolated table, not the recursion


@pytest.mark.parametrize("layers", ["1.38 110; 2.1 70", "Au 20"])
@pytest.mark.parametrize("inside", [False, True])
def test_dielectric_tables_both_sides_with_tir(inside, layers):
    """Inside glass the exit medium totally reflects: the angle axis is split at the
    critical angle, each segment a cubic spline of its own (ghost nodes mirrored
    at normal and grazing incidence, extrapolated at the critical angle), so the
    kink costs no accuracy; the gold film (the paper's Fig. 8b) adds its surface
    plasmon dip just beyond the critical angle. The lossless stack has one table of
    ``R`` lit from the ambient, which serves the glass side through Snell's law
    (render/mirror.py), with ``T = 1 - R``."""
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers,
                         "int_ior": 1.6, "tabulate": True})
    side = bsdf.stack.plan[inside]
    lossless = layers != "Au 20"
    assert bsdf.stack.mirrored == lossless and bsdf.stack.mode() == "table"
    table = bsdf.stack.mirror_table(side) if lossless and inside else side.table
    assert table is not None and table.channels == (1 if lossless else 2)
    assert table.axis.name == ("tir" if inside and not lossless else "plain")
    cos, wls = random_points(20000, seed=2)
    # Points straddling the critical angle (cos = sqrt(1 - 1.000277^2/1.6^2) = 0.78049).
    cos[:2000] = f32(0.7804861 + np.linspace(-1e-3, 1e-3, 2000))
    R, T = bsdf.stack.reflectance(interaction(wls), mi.Float(cos.astype(np.float32)),
                                  inside=inside, transmission=True)
    ref = tf.Stack(layers, substrate=1.6, ambient=media_mod.DEFAULT_EXT_IOR)
    if inside:
        ref = ref.reversed()
    # At the critical angle R's slope in cos is unbounded: the float32 cosine alone
    # moves the exact float32 recursion by ~2e-4 there, the mapped lookup too.
    exact = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers, "int_ior": 1.6,
                          "tabulate": False}).stack.reflectance(
        interaction(wls), mi.Float(cos.astype(np.float32)), inside=inside, transmission=True)
    for i in range(4):
        for got, f32_exact, want in ((R, exact[0], ref_R(ref, cos, wls[i])),
                                     (T, exact[1], ref_R(ref, cos, wls[i], T=True))):
            tol = 1.5 * (table.error + max(F32, np.max(np.abs(np.array(f32_exact)[i] - want))))
            assert np.max(np.abs(np.array(got)[i] - want)) <= tol


def test_auto_mode_and_what_prevents_a_table():
    one = mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 300"})
    assert policy.AUTO_MIN_FILMS == 1 and one.stack.mode() == "table"     # one film is enough
    exact = mi.load_dict({"type": "thinfilm_conductor", "layers": "1.46 300", "tabulate": False})
    assert exact.stack.mode() == "exact"
    three = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu"})
    assert three.stack.mode() == "table"
    textured = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu",
                             "thickness": {"type": "checkerboard"}})
    assert textured.stack.mode() == "exact"     # a thickness texture cannot be tabulated
    with pytest.raises(Exception, match="tabulate"):
        mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "tabulate": True,
                      "thickness": {"type": "checkerboard"}})
    with pytest.raises(Exception, match="'tabulate' must be"):
        mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "tabulate": "sometimes"})
    with pytest.raises(Exception, match="'table_error' must be"):
        mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "table_error": -1.0})
    with pytest.raises(Exception, match="'coherence_thickness' must be"):
        mi.load_dict({"type": "thinfilm_conductor", "layers": STACK,
                      "coherence_thickness": float("nan")})


def test_identical_stacks_share_one_table():
    a = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu"})
    b = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu"})
    c = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Au"})
    assert a.stack.plan[False].table is b.stack.plan[False].table
    assert c.stack.plan[False].table is not a.stack.plan[False].table


def test_zero_thickness_films_are_dropped():
    a = mi.load_dict({"type": "thinfilm_dielectric", "layers": "2.0 0; 1.46 300; 0.2+3j 0",
                      "tabulate": False})
    b = mi.load_dict({"type": "thinfilm_dielectric", "layers": "1.46 300", "tabulate": False})
    assert [len(s.films) for s in a.stack.plan.values()] == [1, 1]
    cos, wls = random_points(1000)
    si = interaction(wls)
    for inside in (False, True):
        ra = a.stack.reflectance(si, mi.Float(cos), inside=inside, transmission=True)
        rb = b.stack.reflectance(si, mi.Float(cos), inside=inside, transmission=True)
        assert np.array_equal(np.array(ra[0]), np.array(rb[0]))
        assert np.array_equal(np.array(ra[1]), np.array(rb[1]))
    # ... and come back when a parameter edit makes them non-zero.
    params = mi.traverse(a)
    params["layers.0.thickness"] = 50.0
    params.update()
    assert [len(s.films) for s in a.stack.plan.values()] == [2, 2]


def test_layers_beneath_an_opaque_film_are_ignored():
    """1 um of gold lets through exp(-2 pi k d / lambda) < 1e-9 of the amplitude
    (worst near 400 nm, k = 1.83):
    from outside, the films beneath and the substrate are not evaluated, and T = 0."""
    layers = "1.46 200; Au 1000; 2.3 80; 1.38 100"
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers, "int_ior": 1.5,
                         "tabulate": False})
    out, inn = bsdf.stack.plan[False], bsdf.stack.plan[True]
    assert len(out.films) == 1 and out.opaque and out.exit.label == "Au"
    assert len(inn.films) == 2 and inn.opaque
    cos, wls = random_points(2000)
    R, T = bsdf.stack.reflectance(interaction(wls), mi.Float(cos), transmission=True)
    ref = tf.Stack(layers, substrate=1.5, ambient=media_mod.DEFAULT_EXT_IOR)
    for i in range(4):
        assert np.max(np.abs(np.array(R)[i] - ref_R(ref, cos, wls[i]))) < F32
        assert np.max(np.array(T)[i]) == 0.0 and np.max(ref_R(ref, cos, wls[i], T=True)) < 1e-12


def test_thick_films_are_incoherent_like_tmm_inc_tmm():
    """A 20 um film (beyond the 5 um coherence thickness) on glass: the kernel
    gives tmm's incoherent R and T, free of the ~1 nm fringes of the coherent one."""
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": "1.38 100; 1.9 20000",
                         "int_ior": 1.5, "ext_ior": 1.0, "tabulate": False})
    assert bsdf.stack.plan[False].incoherent == [False, True]
    wl = np.linspace(500.0, 510.0, 41)
    theta = 0.4
    cos = np.full(wl.size, np.cos(theta))
    R, T = bsdf.stack.reflectance(interaction([wl] * 4), mi.Float(cos), transmission=True)
    R, T = np.array(R)[0], np.array(T)[0]
    for j, w in enumerate(wl):
        res = [tmm.inc_tmm(p, [1.0, 1.38, 1.9, 1.5], [np.inf, 100.0, 20000.0, np.inf],
                           ["i", "c", "i", "i"], theta, w) for p in "sp"]
        # tmm is float64; the kernel float32 (the incoherent core holds 1e-5,
        # tests/optics/test_incoherent.py).
        assert abs(R[j] - 0.5 * (res[0]["R"] + res[1]["R"])) < 1e-5
        assert abs(T[j] - 0.5 * (res[0]["T"] + res[1]["T"])) < 1e-5
    coherent = mi.load_dict({"type": "thinfilm_dielectric", "layers": "1.38 100; 1.9 20000",
                             "int_ior": 1.5, "ext_ior": 1.0, "tabulate": False,
                             "coherence_thickness": 1e6})
    Rc = np.array(coherent.stack.reflectance(interaction([wl] * 4), mi.Float(cos)))[0]
    # The coherent R swings through several fringes (~0.014 peak to peak) in
    # these 10 nm; the incoherent one is smooth.
    assert np.ptp(Rc) > 0.005 and np.ptp(R) < 0.05 * np.ptp(Rc)


def test_table_sweep_reuses_the_kernels():
    """A thickness edit rebuilds the table, whose shape changes, but neither the
    lookup kernel (its shape constants are opaque) nor the float64 build
    kernels (thicknesses opaque, inputs in aligned buffers) are compiled again."""
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu",
                         "tabulate": True})
    params = mi.traverse(bsdf)
    cos, wls = random_points(4000, seed=5)
    si, c = interaction(wls), mi.Float(cos)
    np.array(bsdf.stack.reflectance(si, c))       # compiles the lookup once
    shapes = {(bsdf.stack.plan[False].table.nu, bsdf.stack.plan[False].table.nv)}
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()   # clear
        for d in (400.0, 300.0, 700.0):
            params["layers.0.thickness"] = d
            params.update()
            table = bsdf.stack.plan[False].table
            shapes.add((table.nu, table.nv))
            R = np.array(bsdf.stack.reflectance(si, c))
        fresh = compiled(dr.kernel_history())
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert len(shapes) >= 3, shapes        # the tables did change shape
    assert fresh == [], [k.get("size") for k in fresh]
    ref = tf.Stack(STACK.replace("420", "700"), substrate="Cu", ambient=media_mod.DEFAULT_EXT_IOR)
    assert max(np.max(np.abs(R[i] - ref_R(ref, cos, wls[i])))
               for i in range(4)) <= 1.5 * table.error + F32


def test_table_builds_compile_nothing_after_the_first():
    """The builds of a SiO2-on-Si sweep (the Fig. 8a scene's stack) reuse their
    float64 kernels whatever the probe does: at 410.5 nm the probe's lines along
    u ran at a single wavelength, whose 1-element buffers Dr.Jit traced as
    scalars (another kernel)."""
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": "SiO2 400", "material": "Si",
                         "tabulate": True})
    params = mi.traverse(bsdf)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()   # clear
        for d in np.linspace(400.0, 600.0, 20)[1:8]:
            params["layers.0.thickness"] = float(d)
            params.update()
            assert bsdf.stack.mode() == "table"
        # not in this process's kernel cache yet (compiled, or loaded from disk)
        fresh = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT
                 and (k.get("cache_disk", False) or not k.get("cache_hit", False))]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert fresh == [], [(k.get("operation_count"), k.get("size")) for k in fresh]


def test_gradients_bypass_the_table():
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu",
                         "tabulate": True})
    d = bsdf.stack.thickness[0]
    dr.enable_grad(d)
    cos, wls = random_points(64)
    R = bsdf.stack.reflectance(interaction(wls), mi.Float(cos))
    dr.backward(dr.sum(R[0]))
    assert np.abs(np.array(dr.grad(d))).max() > 0
    dr.disable_grad(d)


def test_scalar_variant_uses_tables_too():
    mi.set_variant("scalar_spectral")
    auto = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu"})
    assert auto.stack.mode() == "exact"   # "auto" does not tabulate in scalar variants
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu",
                         "tabulate": True})
    assert bsdf.stack.mode() == "table"
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.Spectrum(400.0, 500.0, 600.0, 700.0)
    R = np.array(bsdf.stack.reflectance(si, 0.6))
    ref = tf.Stack(STACK, substrate="Cu", ambient=media_mod.DEFAULT_EXT_IOR)
    exact = ref.rt(np.array([400.0, 500, 600, 700]), np.arccos(0.6)).R
    assert np.max(np.abs(R - exact)) <= 1.5 * bsdf.stack.plan[False].table.error + F32


@pytest.mark.parametrize("ends", [(None, None), (axes.MIRROR, axes.EXTRAPOLATE),
                                  (axes.EXTRAPOLATE, axes.MIRROR)])


def test_probe_lines_know_their_interpolation_error(ends):
    """The probe's subsampled lines against the closed form for a sinusoid: at a
    midpoint the interpolating cubic spline gives H(theta) f, H = ((23 cos(theta/2)
    + cos(3 theta/2))/24) / ((2 + cos theta)/3), theta = omega k (uniform B-spline
    interpolation on an unbounded grid). Only the middle half is compared (the
    ``ok`` mask): there the ends (evaluated, mirrored or extrapolated ghosts, 3
    nodes, clamped beyond) are at least 4 nodes away and perturb the spline by
    less than 0.27^4 ~ 5e-3 of their own error (at most ~1e-2 here, where the
    sinusoid is not even about an end), hence the 1e-4 absolute slack; checked
    for the subsamplings that resolve the sinusoid (theta < 3: more than two
    nodes a period; beyond it an extrapolated ghost is meaningless)."""
    from thinfilm_mi.tabulate import exact as tables
    intervals, min_nodes = 1024, 17
    ext = tables.ghost_count(intervals, min_nodes) if ends[0] is None else 0
    assert tables.ghost_count(intervals, min_nodes) == 3 * 64
    omega = 2.0 * np.pi / 37.3
    x = np.arange(-ext, intervals + ext + 1.0)
    f = np.cos(omega * x + 0.4)[:, None, None]
    ok = np.zeros((x.size, 1), bool)
    ok[ext + 256:ext + 768] = True
    (levels,) = tables.line_levels(f, ok, intervals, min_nodes, ends)
    assert [k for k, _, _ in levels] == [2, 4, 8, 16, 32, 64]
    for k, err, at in levels:
        theta = omega * k
        if theta >= 3.0:
            continue
        h = ((23 * np.cos(theta / 2) + np.cos(1.5 * theta)) / 24) / ((2 + np.cos(theta)) / 3)
        mids = np.arange(k // 2, intervals, k)
        mids = mids[(mids >= 256) & (mids < 768)]
        expected = np.abs(1 - h) * np.abs(np.cos(omega * mids + 0.4))
        assert abs(err - expected.max()) <= 1e-4 + 1e-6 * expected.max(), (k, err, expected.max())
        if expected.max() > 1e-3:
            assert at == mids[np.argmax(expected)]


def test_probe_sizes_the_first_table_and_rejects_hopeless_stacks():
    """The probe's estimate is verified like any table (one round for STACK), and a
    stack no table of the exact values within the budgets resolves -- 30 random
    films on Al, with cavity resonances ~0.1 nm wide -- is rejected by the probe
    alone, for a small fraction of the evaluations a failing build used to spend
    (up to policy.MAX_BUILD_POINTS). (``spectral_resolution`` 0: no band-limited
    table is tried after it; tests/tabulate/test_band.py covers those.)"""
    stack_build.TABLE_CACHE.clear()
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu",
                         "tabulate": True})
    assert bsdf.stack.mode() == "table"
    report = bsdf.stack.plan[False].build_report
    assert report["result"] == "table" and report["rounds"] == 1
    assert report["probe_points"] < 0.5 * report["points"]
    layers = benchmark_layers(30)
    with pytest.warns(UserWarning, match="cannot be tabulated"):
        deep = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Al",
                             "tabulate": True, "spectral_resolution": 0.0})
    assert deep.stack.mode() == "exact"
    report = deep.stack.plan[False].build_report
    assert report["result"] == "rejected by the probe"
    assert report["rounds"] == 0
    assert report["points"] < 0.05 * policy.MAX_BUILD_POINTS


def test_auto_keeps_only_tables_that_fit_the_cache():
    """A table too large for the cache costs as much per lookup as the recursion
    (benchmarks/SPEED.md): ``auto`` does not keep such a table of the exact values,
    after the probe alone; ``tabulate=true`` still builds it. Without band-limiting
    ``auto`` then renders exactly; by default it tabulates ``R_σ`` instead, which
    fits the cache (the 1 nm resolution damps the fringes of these 3 µm of optical
    thickness by exp(-2 π² (σ_ν 2 Σ n d)²) < 1 %, yet the table is 160x824)."""
    layers = "2.3 800; 1.46 800"
    stack_build.TABLE_CACHE.clear()
    big = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Al",
                        "tabulate": True})
    table = big.stack.plan[False].table
    assert table is not None and policy.AUTO_MAX_TEXELS < table.texels <= policy.MAX_TEXELS
    assert table.resolution == 0.0
    auto = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Al",
                         "spectral_resolution": 0.0})
    assert auto.stack.mode() == "exact"
    assert auto.stack.plan[False].build_report["rounds"] == 0   # the probe's estimate alone
    auto = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Al"})
    table = auto.stack.plan[False].table
    assert table is not None and table.resolution == stack_plan.DEFAULT_SPECTRAL_RESOLUTION
    assert table.texels <= policy.AUTO_MAX_TEXELS and table.error <= 1e-3


def test_a_table_build_does_not_import_scipy():
    """Importing scipy.linalg costs ~0.2 s in a new process: table builds do without."""
    import subprocess
    import sys
    code = ("import sys, mitsuba as mi; mi.set_variant('llvm_ad_spectral'); import thinfilm_mi\n"
            f"b = mi.load_dict({{'type': 'thinfilm_conductor', 'layers': {STACK!r}, "
            "'material': 'Cu', 'tabulate': True})\n"
            "assert b.stack.mode() == 'table'\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("layers", ["1.46 100; 2.3 60; 1.38 90; 2.1 50; 1.46 80",
                                    "1.46 100; 2.3 60; 0.2+3j 6; 2.1 50; 1.46 80"])


def test_deep_stacks_build_through_the_film_loop(layers, monkeypatch):
    """From tabulate_base.BUILD_LOOP_MIN_FILMS films the build evaluates the stack as a
    loop over buffers of the films (real and complex loops): the table meets the
    independent float64 reference like the unrolled builds (tolerance as in the
    first test)."""
    from thinfilm_mi.tabulate import base as tabulate_base
    calls = []
    loop = unpolarized.unpolarized_rt_loop

    def counted(*a, **k):
        calls.append(k["film_n_min"])
        return loop(*a, **k)
    monkeypatch.setattr(quantities.POWERS, "rt_loop", counted)
    stack_build.TABLE_CACHE.clear()
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": layers, "material": "Cu",
                         "tabulate": True})
    stack_build.TABLE_CACHE.clear()
    table = bsdf.stack.plan[False].table
    assert table is not None and bsdf.stack.plan[False].build_report["result"] == "table"
    assert len(layers.split(";")) >= tabulate_base.BUILD_LOOP_MIN_FILMS and calls
    assert all((m is None) == ("j" in layers) for m in calls)   # complex loop iff absorbing
    cos, wls = random_points(20000, seed=8)
    R = np.array(bsdf.stack.reflectance(interaction(wls), mi.Float(cos.astype(np.float32))))
    ref = tf.Stack(layers, substrate="Cu", ambient=media_mod.DEFAULT_EXT_IOR)
    err = max(np.max(np.abs(R[i] - ref_R(ref, cos, wls[i]))) for i in range(4))
    assert err <= 1.5 * table.error + F32, err
