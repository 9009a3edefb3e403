"""thinfilm_mi.render.layered.factors: the model's factor table (``factor_table``) against the
exact path, its sharing through the table cache and store, and its key."""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")

import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from tests.support.bsdf import direction, make_si
from thinfilm_mi.render.layered.models import DIFFUSE_MODELS

DIFFUSE_ONLY = mi.BSDFContext()
DIFFUSE_ONLY.component = 1


# -- the factor table (tabulate/diffuse.py FactorTable) against the exact path ---------
def _factors_both_ways(coated, si, cos):
    """``(k_r, t)`` at ``cos`` from the table and from the path without it (the stack's
    recursion, or its own table of ``R``, and ``k_a``)."""
    table = coated.table
    k_r, t, _ = coated.factors_at(si, cos, True, True)
    coated.table = None
    try:
        k_r0, t0, _ = coated.factors_at(si, cos, True, True)
    finally:
        coated.table = table
    return [np.array(x) for x in (k_r, t, k_r0, t0)]


@pytest.mark.parametrize("model", list(DIFFUSE_MODELS))
def test_factor_table_matches_the_exact_path(model):
    """The kernel's ``k_r``, ``t`` read from the factor table against the path it
    replaces, at random angles outside the grazing sliver and random wavelengths: within
    ``table_error`` where that path is the exact float32 recursion (model "exact"; float32
    adds ~1e-5 near grazing) and 2 ``table_error`` where it reads the stack's own table
    of ``R`` (the paper's models: each within ``table_error`` of the exact values)."""
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5", "model": model})
    coated = b.coated
    assert coated.table is not None
    rng = np.random.default_rng(11)
    n = 4000
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wavelengths = mi.Spectrum(*(mi.Float(rng.uniform(360.0, 830.0, n)) for _ in range(4)))
    cos = mi.Float(rng.uniform(0.02, 1.0, n))
    k_r, t, k_r0, t0 = _factors_both_ways(coated, si, cos)
    exact_path = coated.coating.mode() != "table"
    tol = coated.coating.table_error * (1.0 if exact_path else 2.0) + 2e-5
    assert np.abs(k_r - k_r0).max() <= tol
    assert np.abs(t - t0).max() <= tol


def test_factor_table_eval_is_the_model_with_its_factors():
    """``eval`` with the table: the diffuse term ``k_d t_i t_o S cos/π`` of the table's
    factors (S = 1/(1 - k_d R_dh), the table's ``R_dh``)
    weight: the table's factors reach the BSDF's values."""
    kd = 0.7
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5",
                      "model": "multiple", "reflectance": kd})
    table = b.coated.table
    wi, wo = direction(35.0), direction(60.0, 63.0)
    si = make_si(1, wi)
    cells = table.cells(si.wavelengths)
    _, t_i, r_dh, _ = table.lookup(mi.Frame3f.cos_theta(wi), cells)
    _, t_o, _, _ = table.lookup(mi.Frame3f.cos_theta(wo), cells)
    want = kd * t_i * t_o / (1.0 - kd * r_dh) * mi.Frame3f.cos_theta(wo) / math.pi
    got = b.eval(DIFFUSE_ONLY, si, wo)
    assert np.allclose(np.array(got), np.array(want), rtol=1e-5, atol=1e-7)


def test_factor_table_skipped_while_a_film_carries_gradients():
    """Where a film's thickness carries gradients, the kernel evaluates every film
    exactly (the table holds numbers, not derivatives), an edit then builds no table (an
    optimisation's steps), and the table is read again once gradients are disabled."""
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"})
    params = mi.traverse(b)
    si = make_si(1, direction(30.0))
    assert b.coated.table_at(si, True) is not None
    dr.enable_grad(params["layers.0.thickness"])
    params.update()
    assert b.coated.table_at(si, True) is None
    params["layers.0.thickness"] = mi.Float(510.0)
    dr.enable_grad(params["layers.0.thickness"])
    params.update()
    assert b.coated.table is None and b.coated.table_at(si, True) is None
    dr.disable_grad(params["layers.0.thickness"])
    params.update()
    assert b.coated.table is not None and b.coated.table_at(si, True) is not None


@pytest.fixture
def own_tables(tmp_path, monkeypatch):
    """The table store in a temporary directory, this process's table cache empty, and
    the factor tables built here counted (``builds``: one entry per build)."""
    from thinfilm_mi.render import stack_build
    from thinfilm_mi.render.layered import factors as diffuse
    from thinfilm_mi.tabulate import store

    monkeypatch.setenv(store.ENVIRONMENT, str(tmp_path / "tables"))
    stack_build.TABLE_CACHE.clear()
    builds = []

    class Counted(diffuse.FactorTable):
        def __init__(self, *args, **kwargs):
            builds.append(args)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(diffuse, "FactorTable", Counted)
    yield builds
    stack_build.TABLE_CACHE.clear()


def test_an_identical_bsdf_shares_the_factor_table(own_tables):
    """A second ``thinfilm_diffuse`` of the same optics takes the first's table from this
    process's table cache: no second build (another albedo does not change the factors)."""
    first = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"})
    assert first.coated.table is not None and len(own_tables) == 1
    second = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5",
                           "reflectance": 0.4})
    assert second.coated.table is first.coated.table
    assert len(own_tables) == 1


def test_an_edit_back_to_previous_values_reuses_the_factor_table(own_tables):
    """Through ``mi.traverse``: a new thickness builds a new table, the old thickness
    again takes the first table back from the cache (no build)."""
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"})
    params = mi.traverse(b)
    table = b.coated.table
    params["layers.0.thickness"] = 510.0
    params.update()
    assert b.coated.table is not None and b.coated.table is not table
    assert len(own_tables) == 2
    params["layers.0.thickness"] = 500.0
    params.update()
    assert b.coated.table is table and len(own_tables) == 2


BASE_KEY = {"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5", "model": "exact"}


def _factor_key(d: dict) -> str:
    from thinfilm_mi.render.layered.factors import factor_table_key
    coated = mi.load_dict(d).coated
    return factor_table_key(coated.factors(), coated.coating, coated.media())


@pytest.mark.parametrize("model, change", [
    ("exact", {"layers": "SiO2 501; Au 5"}),          # a film's thickness
    ("exact", {"layers": "SiO2 500; Au 5.5"}),        # the last (metal) film's thickness
    ("exact", {"layers": "1.46 500; Au 5"}),          # a film's index
    ("exact", {"layers": "SiO2 500; Ag 5"}),          # the metal film's index
    ("exact", {"ext_ior": 1.1}),                      # the ambient
    ("exact", {"base_ior": 1.5}),                     # the base medium
    ("exact", {"model": "single"}),                   # the model's factors
    ("exact", {"table_error": 2e-3}),                 # the target
    ("exact", {"coherence_thickness": 400.0}),        # SiO2 500 then incoherent
    ("single", {"layers": "SiO2 500; Au 5.5"}),       # film N's thickness
    ("single", {"layers": "SiO2 500; Ag 5"}),         # film N's index
    ("single", {"layers": "SiO2 501; Au 5"}),         # the coating's film
])
def test_the_factor_table_key_changes_with_each_input(own_tables, model, change):
    """Key completeness: each input the table's values depend on, changed alone, gives
    another key."""
    base = dict(BASE_KEY, model=model)
    assert _factor_key(dict(base, **change)) != _factor_key(base)


@pytest.mark.parametrize("cap, value", [("FACTOR_MAX_FLOATS", 1 << 20),
                                        ("FACTOR_STEPS", (1.0, 0.5)),
                                        ("FACTOR_FIRST_NODES", 17),
                                        ("FACTOR_ANGLE_SHARE", 0.4)])
def test_the_factor_table_key_changes_with_the_builds_caps(own_tables, monkeypatch, cap, value):
    from thinfilm_mi.tabulate import factors as factor_build
    key = _factor_key(BASE_KEY)
    monkeypatch.setattr(factor_build, cap, value)
    assert _factor_key(BASE_KEY) != key


def test_the_factor_table_key_changes_with_the_variant_but_not_with_the_albedo(own_tables):
    """Another variant holds its own buffers; the albedo, and the choice between the
    paper's two models (the same factors), leave the key as it is."""
    key = _factor_key(BASE_KEY)
    assert _factor_key(dict(BASE_KEY, reflectance=0.3)) == key
    single = _factor_key(dict(BASE_KEY, model="single"))
    assert _factor_key(dict(BASE_KEY, model="multiple")) == single
    mi.set_variant("llvm_ad_spectral_polarized")
    try:
        assert _factor_key(BASE_KEY) != key
    finally:
        mi.set_variant("llvm_ad_spectral")


def test_factor_table_edits_render_from_the_cached_kernel(own_tables):
    """Edits through ``mi.traverse`` that give the factor table another layout (fewer
    cells in the band of finer wavelengths, a coarser step there, no band at all) render
    from the kernel compiled before them: the layout is read as opaque values. (With it
    as literals each of these edits compiled the render kernel again, ~0.3-0.4 s.) Only
    the render is checked: an edit's own small kernels (4-22 operations: R_dh, T_hemi's
    spectra, the index's distribution) take NumPy arrays, whose alignment gives Dr.Jit a
    kernel of its own now and then (see benchmarks/sample_profile.py's ``inputs``)."""
    from tests.support.kernels import render_kernels, same_instances
    from tests.support.specular import lit_floor_scene
    scene = lit_floor_scene({"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"}, size=16)
    params = mi.traverse(scene)
    (bsdf,) = [s.bsdf() for s in scene.shapes() if hasattr(s.bsdf(), "coated")]
    key = "obj.bsdf.layers.0.eta.values"
    with same_instances():   # no dropped scene freed between renders (another kernel)
        image, kernels = render_kernels(scene)
        layouts, images = [bsdf.coated.table.layout()], [image]
        for edits in ({"obj.bsdf.layers.0.thickness": 420.0},
                      {"obj.bsdf.layers.0.thickness": 300.0, key: params[key] * 0.98}):
            for k, v in edits.items():
                params[k] = v
            params.update()
            image, edited = render_kernels(scene)
            images.append(image)
            assert set(edited) <= set(kernels), "a parameter edit changed the render kernel"
            assert np.abs(images[-1] - images[-2]).mean() > 1e-3   # the edit took effect
            layouts.append(bsdf.coated.table.layout())
    assert layouts[0]["band"] > 0
    assert layouts[1]["band"] != layouts[0]["band"] and layouts[1]["fine_step"] != layouts[0]["fine_step"]
    assert layouts[2]["band"] == 0
