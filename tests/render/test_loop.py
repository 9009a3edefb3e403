"""The films of deep stacks as a loop in the render kernel (thinfilm_mi/render/loop.py):
the plugins read the loop and match float64, the loop and the unrolled kernels agree,
kernels reused across depths, gradients, the ``thickness`` texture, tabulated sides
without loop buffers, the real-amplitude loop chosen for real films."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.kernels import compiled, interaction
from tests.support.stacks import sphere_scene
from thinfilm_mi.render import media as media_mod
from thinfilm_mi.render import stack_plan


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
    """The same BSDF evaluated through the loop and through the unrolled films read
    from their index textures (the buffers' threshold raised): both float32, different
    operation order. The textures hold the datasets on their own knots here, as the
    buffers do (a resampling on a uniform grid moves TiO2's n by up to 1e-4, and these
    resonant stacks' R by ~4e-4: that is the materials' stated bound, not the loop's)."""
    from thinfilm_mi.materials.model import DispersiveMaterial
    monkeypatch.setattr(DispersiveMaterial, "uniform_resampling", lambda self: None)
    spec = {"type": "thinfilm_conductor", "layers": DISPERSIVE, "material": "Au",
            "tabulate": False}
    cos, wls = points(3000, seed=4)
    looped = mi.load_dict(spec)
    monkeypatch.setattr(stack_plan, "BUFFERED_MIN_FILMS", 1000)
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


@pytest.mark.parametrize("layers, constant", [("1.46 100; 2.3 60; 1.46 100", True),
                                              (NON_ABSORBING, False), ("2.3 150", True)])


def test_real_films_run_the_real_loop_at_any_depth(llvm, layers, constant, real_path_calls):
    """Real films above the ambient run the real-amplitude steps from one film on
    (BUFFERED_MIN_FILMS; unrolled below LOOP_MIN_FILMS films); constant ones gather one
    index per lane, shared by the four wavelengths. Float32 kernel against float64."""
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


# The demo's metal-coated glass: Au's and Al's knots off the 1 nm grid, two of them
# inside one nanometre (the cell lookup's bins then hold two inner knots).
METALS = "SiO2 500; Au 20; Al 10"


def test_few_films_unrolled_match_float64_and_the_loop(llvm, monkeypatch):
    """A side of fewer than LOOP_MIN_FILMS films reads the buffers unrolled (power form
    of the recursion): R and T of the metal-coated glass from both sides against
    float64, and against the same BSDF through the symbolic loop (threshold lowered)."""
    from thinfilm_mi.render import loop as loop_mod
    spec = {"type": "thinfilm_dielectric", "layers": METALS, "int_ior": 1.6, "tabulate": False}
    unrolled = mi.load_dict(spec)
    cos, wls = points(4000, seed=21)
    si, c = interaction(wls), mi.Float(cos)
    films = tf.materials.stack.parse_layers(METALS)
    refs = {False: tf.Stack(films, substrate=1.6, ambient=media_mod.DEFAULT_EXT_IOR),
            True: tf.Stack(list(reversed(films)), substrate=media_mod.DEFAULT_EXT_IOR,
                           ambient=1.6)}
    # the metals' absorption keeps q away from 0: their q = 0 guard is not traced;
    # SiO2 above air has a real root (optics.film_bounds)
    outside = unrolled.stack.plan[False].loop
    assert [b.q_away for b in outside.bounds] == [True, True, True]
    assert outside.bounds[0].n2_min is not None and outside.exit_bounds.n2_min is not None
    ours = {}
    for inside, ref in refs.items():
        assert unrolled.stack.plan[inside].loop is not None
        R, T = (np.array(x) for x in unrolled.stack.reflectance(si, c, inside=inside,
                                                                  transmission=True))
        ours[inside] = R, T
        for i in range(4):
            r = ref.rt(wls[i], np.arccos(cos))
            assert np.max(np.abs(R[i] - r.R)) < F32_DEEP
            assert np.max(np.abs(T[i] - r.T)) < F32_DEEP
    monkeypatch.setattr(loop_mod, "LOOP_MIN_FILMS", 1)
    looped = mi.load_dict(spec)
    for inside in (False, True):
        R, T = (np.array(x) for x in looped.stack.reflectance(si, c, inside=inside,
                                                                transmission=True))
        # both float32, another order of operations (and rescaling) only
        assert np.max(np.abs(R - ours[inside][0])) < F32_DEEP
        assert np.max(np.abs(T - ours[inside][1])) < F32_DEEP


@pytest.mark.parametrize("layers", [METALS, "TiO2 61; SiO2 95; Cr 4", "Au 20"])


def test_binned_cell_lookup_matches_the_search(llvm, layers):
    """The cell lookup of a non-uniform grid by bins (one packet gather per wavelength)
    finds the cell and weight the binary search over the knots finds, at random
    wavelengths, at every knot and just below it."""
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers, "int_ior": 1.6,
                         "tabulate": False})
    loop = bsdf.stack.plan[False].loop
    assert not loop.uniform and loop.bins is not None
    grid = np.array(loop.grid, np.float32)
    rng = np.random.default_rng(5)
    w = np.concatenate([rng.uniform(355.0, 835.0, 20000), grid,
                        np.nextafter(grid, np.float32(0.0)), [grid[0] - 3, grid[-1] + 3]])
    w = mi.Float(w.astype(np.float32))
    i, t = (np.array(x) for x in loop._cell(w))
    bins = loop.bins
    loop.bins = None
    try:
        i_ref, t_ref = (np.array(x) for x in loop._cell(w))
    finally:
        loop.bins = bins
    # the same cell, or the neighbouring one where w is a knot (weight 1 of one = 0 of
    # the other); the weights agree to the rounding of a product against a quotient
    same = i == i_ref
    assert np.all(same | ((np.abs(i.astype(int) - i_ref) == 1)
                          & np.isin(np.array(w), grid)))
    assert np.max(np.abs(t[same] - t_ref[same])) < 1e-6


@pytest.mark.parametrize("layers", ["SiO2 500", "2.3 150", "MgF2 95"])


def test_one_real_film_on_glass_in_closed_form_matches_float64(llvm, layers, monkeypatch):
    """One real film above the ambient's index on a real substrate (LoopFilms.airy): R
    in closed form (the Airy sum of the two interfaces), here through both sides of a
    mirrored dielectric (the substrate side at the Snell-mapped angle, total reflection
    beyond the critical angle), against float64, and equal to the recursion's value
    (the real-amplitude steps, the closed form switched off) within float32 rounding."""
    bsdf = mi.load_dict({"type": "thinfilm_dielectric", "layers": layers, "int_ior": 1.6})
    loop = bsdf.stack.plan[False].loop
    assert loop is not None and loop.airy and bsdf.stack.mode() == "exact"
    cos, wls = points(4000, seed=31)
    si, c = interaction(wls), mi.Float(cos)
    films = tf.materials.stack.parse_layers(layers)
    refs = {False: tf.Stack(films, substrate=1.6, ambient=media_mod.DEFAULT_EXT_IOR),
            True: tf.Stack(films[::-1], substrate=media_mod.DEFAULT_EXT_IOR, ambient=1.6)}
    ours = {}
    for inside, ref in refs.items():
        R, T = (np.array(x) for x in bsdf.stack.reflectance(si, c, inside=inside,
                                                              transmission=True))
        ours[inside] = R
        for i in range(4):
            r = ref.rt(wls[i], np.arccos(cos))
            assert np.max(np.abs(R[i] - r.R)) < F32_DEEP
            assert np.max(np.abs(T[i] - r.T)) < F32_DEEP
    monkeypatch.setattr(loop, "airy", False)
    for inside in (False, True):
        R = np.array(bsdf.stack.reflectance(si, c, inside=inside))
        # both float32 from the same indices: the rounding of a few operations
        assert np.max(np.abs(R - ours[inside])) < 1e-5


@pytest.mark.parametrize("plugin", ["thinfilm_dielectric", "thinfilm_roughdielectric"])
@pytest.mark.parametrize("before,key,value,after", [
    # a real film above both media (real root, one-film closed form) edited below the glass
    ("2.0 100", "ball.bsdf.layers.0.eta.value", 1.2, "1.2 100"),
    # a lossless film among metals (a literal zero imaginary part) edited to absorb
    ("1.46 500; Au 20", "ball.bsdf.layers.0.k.value", 0.05, "1.46+0.05i 500; Au 20"),
], ids=["real-film-below-the-glass", "lossless-film-absorbs"])
def test_an_edit_across_a_trace_time_bound_renders_as_a_fresh_load(llvm, plugin, before, key,
                                                                   value, after):
    """The unrolled sides specialise on what the films' values allow when the kernel is
    traced (``LoopFilms``: real roots, the closed form, literal zero absorption, no ``q =
    0`` guard). An edit through ``mi.traverse(scene)`` that leaves those bounds re-derives
    them: the render equals a fresh load of the edited stack bit for bit (1 spp, box
    filter), and differs from before the edit."""
    bsdf = {"type": plugin, "tabulate": False, "int_ior": 1.6}
    scene = mi.load_dict(sphere_scene({**bsdf, "layers": before}))
    params = mi.traverse(scene)
    first = np.array(mi.render(scene, seed=3))
    params[key] = value
    params.update()
    edited = np.array(mi.render(scene, seed=3))
    fresh = np.array(mi.render(mi.load_dict(sphere_scene({**bsdf, "layers": after})), seed=3))
    assert np.array_equal(edited, fresh)
    assert np.abs(edited - first).max() > 1e-2
