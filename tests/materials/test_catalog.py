"""The material catalog (thinfilm_mi/materials/catalog.py): named datasets, database
pages, aliases, caching, errors and suggestions.

Reference values are published numbers (cited at each test), not numbers read
back from this package's own files.
"""
from __future__ import annotations

import socket
import warnings

import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.materials import VISIBLE
from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials import catalog as M
from thinfilm_mi.materials import sources

REQUIRED = ["Au", "Ag", "Cu", "Al", "Cr", "Ti", "Ni", "Si", "a-Si", "Ge", "SiO2", "TiO2", "Ta2O5",
            "Al2O3", "MgF2", "ZnS", "Si3N4", "ITO", "BK7", "fused silica", "water", "air", "vacuum"]


# -- published values -------------------------------------------------------------
def test_gold_550_johnson_christy():
    # Johnson & Christy 1972, Table I: 0.43 + 2.455i at 2.26 eV (548.6 nm) and
    # 0.29 + 2.863i at 2.13 eV (582.1 nm); linear interpolation to 550 nm moves n by
    # 0.006 and k by 0.017, so 0.02 / 0.03 hold J&C and exclude e.g. Palik (n ~ 0.33).
    z = tf.refractive_index("Au", 550.0)
    assert z.dtype == np.complex128
    assert abs(z.real - 0.42) < 0.02 and abs(z.imag - 2.47) < 0.03


def test_tables_are_linear_in_wavelength():
    # Johnson & Christy's rows at 548.6 nm (0.43 + 2.455i) and 582.1 nm (0.29 + 2.863i);
    # halfway between them, linear interpolation in wavelength gives their mean exactly.
    z = tf.refractive_index("Au", [548.6, 565.35, 582.1])
    np.testing.assert_allclose(z, [0.43 + 2.455j, 0.36 + 2.659j, 0.29 + 2.863j], rtol=0, atol=1e-12)


def test_silicon_550_green_2008():
    # Green 2008, Table 1 at 550 nm: n = 4.077, k = 0.0280 (alpha = 6.4e3 /cm).
    # 550 nm is a table point, so only print rounding separates us: 1e-3 / 5e-4.
    z = tf.refractive_index("Si", 550.0)
    assert abs(z.real - 4.077) < 1e-3 and abs(z.imag - 0.0280) < 5e-4


def test_fused_silica_malitson():
    # Malitson 1965, Table: measured n = 1.46008 at the Hg e-line 546.07 nm; his
    # Sellmeier fit reproduces the table to ~1e-5, so 3e-5.
    assert abs(tf.refractive_index("SiO2", 546.07).real - 1.46008) < 3e-5
    # and at 550 nm the often-quoted 1.460 (1.4599)
    z = tf.refractive_index("fused silica", 550.0)
    assert abs(z.real - 1.4599) < 1e-4 and z.imag == 0


def test_bk7_schott_catalogue():
    # SCHOTT N-BK7 data sheet: nd = 1.51680 (587.56 nm), ne = 1.51872 (546.07 nm),
    # given to 5 decimals, and the catalogue Sellmeier reproduces them to 1e-5.
    assert abs(tf.refractive_index("BK7", 587.5618).real - 1.51680) < 2e-5
    assert abs(tf.refractive_index("BK7", 546.074).real - 1.51872) < 2e-5
    # at 550 nm: 1.5185 (interpolated between the two lines above)
    assert abs(tf.refractive_index("N-BK7", 550.0).real - 1.5185) < 2e-4
    # k from SCHOTT's internal transmittance: ~1e-8, tiny but >= 0
    assert 0 <= tf.refractive_index("BK7", 550.0).imag < 1e-7


def test_air_ciddor():
    # Ciddor 1996 standard air (15 C, 101325 Pa, 450 ppm CO2): (n - 1) = 2.7784e-4 at
    # 550 nm (NIST engineering-metrology toolbox gives 2.7784e-4 at the same conditions);
    # 1e-8 is the rounding of the quoted value.
    assert abs(tf.refractive_index("air", 550.0).real - 1 - 2.7784e-4) < 1e-8
    assert tf.refractive_index("vacuum", [400.0, 700.0]).tolist() == [1 + 0j, 1 + 0j]


def test_other_short_names_near_handbook_values_at_550():
    # Handbook values at 550 nm with a tolerance that spans the common datasets
    # (refractiveindex.info pages of the same material); a wrong column, unit or
    # dataset mix-up is far outside these.
    expected = {
        "Ag": (0.06, 3.6, 0.06, 0.3),     # J&C 0.059+3.60i; McPeak 0.05+3.5i
        "Cu": (1.0, 2.6, 0.15, 0.2),      # J&C 1.01+2.58i; McPeak 1.05+2.5i
        "Al": (0.96, 6.69, 0.15, 0.4),    # Rakic 1.02+6.63i; McPeak 0.79+5.85i... Palik 0.96+6.69i
        "Cr": (3.2, 3.3, 0.5, 0.5),       # J&C 3.18+3.33i; Palik 3.0+3.3i
        "Ti": (2.5, 3.4, 0.5, 0.5),       # J&C 2.54+3.43i
        "Ni": (1.9, 3.6, 0.2, 0.3),       # J&C 1.92+3.62i; Palik 1.8+3.3i
        "Ge": (5.1, 2.2, 0.3, 0.3),       # Aspnes 5.1+2.3i; Nunley 5.19+2.12i
        "TiO2": (2.4, 0.0, 0.2, 0.01),    # films 2.2-2.5
        "Ta2O5": (2.14, 0.0, 0.05, 0.01), # films 2.10-2.17
        "Al2O3": (1.77, 0.0, 0.12, 1e-6), # sapphire 1.770; amorphous films ~1.65
        "MgF2": (1.378, 0.0, 0.01, 1e-6),  # Dodge n_o 1.3785
        "ZnS": (2.38, 0.0, 0.03, 0.01),   # cubic ZnS 2.37-2.39
        "Si3N4": (2.05, 0.0, 0.03, 1e-6), # Philipp 2.04, Luke 2.05
        "ITO": (1.9, 0.0, 0.15, 0.05),    # ITO films 1.8-2.0
        "water": (1.333, 0.0, 0.002, 1e-6),  # 1.3330 (Hale & Querry), 1.3339 (Daimon, 20 C)
        "a-Si": (4.4, 0.8, 0.4, 0.4),     # evaporated a-Si 4.2-4.6 + 0.5-1.0i
    }
    for name, (n, k, dn, dk) in expected.items():
        z = tf.refractive_index(name, 550.0)
        assert abs(z.real - n) < dn and abs(z.imag - k) < dk, (name, z)


# -- every short name over Mitsuba's range -------------------------------------------
@pytest.mark.parametrize("name", REQUIRED)
def test_every_short_name_finite_over_visible(name):
    mat = tf.resolve_material(name)  # default require_range: 360-830 nm must be covered
    z = mat.index(VISIBLE)
    assert z.dtype == np.complex128 and z.shape == VISIBLE.shape
    assert np.all(np.isfinite(z)) and np.all(z.real > 0) and np.all(z.imag >= 0), name
    assert mat.reference and mat.name
    lo, hi = mat.wavelength_range
    assert lo <= 360.0 and hi >= 830.0


def test_every_listed_name_covers_the_range_and_is_listed():
    rows = M.list_materials()
    names = {r["name"] for r in rows if r["kind"] == "builtin"}
    for name in REQUIRED:
        assert M.resolve(name).name in names
    for r in rows:
        if r["kind"] == "builtin":
            assert r["wavelength_range"][0] <= 360 and r["wavelength_range"][1] >= 830, r
            assert r["reference"] and r["dataset"]
    text = M.format_material_table()
    for r in rows:
        assert r["name"].split(":")[-1] in text
    assert "main/Au/Johnson" in text and "CC0" in text


def test_shipped_extract_matches_the_installed_database():
    # The shipped pages are verbatim copies; if a database release revises one, this
    # fails so that updating the defaults is a deliberate decision.
    for name, entry in sources.builtin_registry()["materials"].items():
        if "constant" in entry:
            continue
        ours = sources.load_builtin(name)
        theirs = sources.load_ri_page(entry["dataset"])
        np.testing.assert_array_equal(ours.index(VISIBLE), theirs.index(VISIBLE), err_msg=name)


# -- names, aliases, caching ----------------------------------------------------------
def test_aliases_and_case():
    silica = M.resolve("SiO2")
    for alias in ["fused silica", "fused_silica", "Fused-Silica", "silica", "sio2"]:
        assert M.resolve(alias) is silica
    assert M.resolve("a-Si") is M.resolve("a_si") is M.resolve("amorphous silicon")
    assert M.resolve("a-Si") is not M.resolve("Si")
    assert M.resolve("AU") is M.resolve("gold")
    assert M.resolve("vacuum").constant == 1
    assert M.resolve("air").constant is None  # Ciddor dispersion, not n = 1


def test_resolve_caches_named_and_database_entries():
    assert M.resolve("Au") is M.resolve("au")
    assert M.resolve("main/Au/McPeak") is M.resolve("main/au/mcpeak")
    mat = M.resolve("Au")
    assert M.resolve(mat) is mat


def test_contract_attributes():
    au = M.resolve("Au")
    assert au.absorbing and au.constant is None and au.reference.startswith("P. B. Johnson")
    assert M.resolve("SiO2").absorbing  # dispersive materials count as possibly absorbing
    c = M.resolve("0.42+2.47i")
    assert c.constant == 0.42 + 2.47j and c.absorbing
    assert not M.resolve(1.46).absorbing
    assert M.resolve(1.46).index(np.zeros((2, 3))).shape == (2, 3)


@pytest.mark.parametrize("bad, words", [(-1.0, "n must be > 0"), ("1.5-0.1j", "k must be >= 0"),
                                        (float("nan"), "finite"), (True, "True")])


def test_constant_validation(bad, words):
    with pytest.raises(MaterialError, match=words):
        M.resolve(bad)


# -- errors ---------------------------------------------------------------------------------
def test_unknown_name_suggests_close_matches():
    with pytest.raises(MaterialError) as err:
        M.resolve("Aux")
    assert isinstance(err.value, ValueError)
    assert "'Aux'" in str(err.value) and "'Au'" in str(err.value)
    with pytest.raises(MaterialError, match="'Si'"):
        M.resolve("silcon")
    with pytest.raises(MaterialError, match="mitsuba:W"):  # bare names do not fall back
        M.resolve("W")


def test_unknown_database_page_names_it_and_suggests():
    with pytest.raises(MaterialError, match="main/Au/Jonson.*main/Au/Johnson"):
        M.resolve("main/Au/Jonson")
    with pytest.raises(MaterialError, match="Unobtainium"):
        M.resolve("main/Unobtainium/X")


def test_wavelength_outside_data_is_an_error_not_nan():
    with pytest.raises(MaterialError, match=r"'Au'.*100\.0 nm.*187\.9-1937"):
        tf.refractive_index("Au", [550.0, 100.0])
    with pytest.raises(MaterialError, match="nan"):
        tf.refractive_index("SiO2", [np.nan])
    # the ends of Mitsuba's range are inside every dataset
    assert np.all(np.isfinite(tf.refractive_index("Si", [360.0, 830.0])))


def test_dataset_not_covering_visible_is_rejected_for_rendering():
    # Devore 1951 rutile: 430-1530 nm
    with pytest.raises(MaterialError, match=r"main/TiO2/Devore-o.*430-1530 nm.*360-830"):
        M.resolve("main/TiO2/Devore-o")
    mat = M.resolve("main/TiO2/Devore-o", require_range=None)
    # Devore's n_o at 550 nm: 2.6520 (rutile handbook value 2.65)
    assert abs(mat.index(550.0).real - 2.652) < 0.005
    with pytest.raises(MaterialError, match="400"):
        mat.index(400.0)
    # refractive_index() only needs the wavelengths asked for
    assert tf.refractive_index("main/TiO2/Devore-o", 600.0).real > 2.5


def test_database_pages_load_offline(monkeypatch):
    def no_network(*a, **k):
        raise AssertionError("network access")

    monkeypatch.setattr(socket, "socket", no_network)
    monkeypatch.setattr(socket, "create_connection", no_network)
    mat = M.resolve("main/Ag/McPeak")  # not used elsewhere in this file: loaded here
    # McPeak 2015 silver at 550 nm: 0.05 + 3.5i (spread of Ag datasets ~0.05 / 0.2)
    z = mat.index(550.0)
    assert abs(z.real - 0.06) < 0.05 and abs(z.imag - 3.55) < 0.2


def test_warning_free_for_ordinary_names():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        M.resolve("TiO2")
        M.resolve("mitsuba:Ag")


# -- conductor_spectra --------------------------------------------------------------
def test_conductor_spectra_give_mitsubas_own_conductor(llvm):
    """A ``roughconductor`` given ``conductor_spectra("mitsuba:Al")`` reflects what
    Mitsuba's ``material="Al"`` (its ``irregular`` spectra) does, at random directions and
    wavelengths: the spectra stay within 1e-4 of the data in n and k, which moves Al's
    Fresnel reflectance (dR/dn, dR/dk < 0.05 over 360-830 nm) by < 1e-5, well inside the
    1e-4 allowed here (float32 arithmetic adds ~1e-7)."""
    import drjit as dr
    import mitsuba as mi
    spectra = M.conductor_spectra("mitsuba:Al")
    assert spectra["eta"]["type"] == spectra["k"]["type"] == "regular"
    ours = mi.load_dict({"type": "roughconductor", "alpha": 0.3, **spectra})
    theirs = mi.load_dict({"type": "roughconductor", "alpha": 0.3, "material": "Al"})
    n = 4096
    rng = np.random.default_rng(3)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.n = mi.Normal3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(si.n)
    si.wi = mi.warp.square_to_cosine_hemisphere(mi.Point2f(*rng.random((2, n))))
    si.wavelengths = mi.Spectrum(*(mi.Float(rng.uniform(360.0, 830.0, n)) for _ in range(4)))
    wo = mi.warp.square_to_cosine_hemisphere(mi.Point2f(*rng.random((2, n))))
    a = np.array(ours.eval(mi.BSDFContext(), si, wo))
    b = np.array(theirs.eval(mi.BSDFContext(), si, wo))
    scale = np.maximum(np.abs(b), 1.0)
    assert np.max(np.abs(a - b) / scale) < 1e-4
    assert np.count_nonzero(b) > n     # the comparison covers lit lanes


def test_conductor_spectra_of_a_constant_and_of_bad_names():
    """A constant gives floats; an unknown name raises, naming it."""
    assert M.conductor_spectra("0.2+3.1j") == {"eta": pytest.approx(0.2), "k": pytest.approx(3.1)}
    with pytest.raises(MaterialError, match="Alumium"):
        M.conductor_spectra("Alumium")
