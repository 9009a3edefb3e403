"""Materials: named datasets, database pages, Mitsuba presets, user files, errors.

Reference values are published numbers (cited at each test), not numbers read
back from this package's own files.
"""
from __future__ import annotations

import math
import re
import socket
import warnings

import numpy as np
import pytest

import thinfilm_mi as tf
from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials import catalog as M
from thinfilm_mi.materials import sources

REQUIRED = ["Au", "Ag", "Cu", "Al", "Cr", "Ti", "Ni", "Si", "a-Si", "Ge", "SiO2", "TiO2", "Ta2O5",
            "Al2O3", "MgF2", "ZnS", "Si3N4", "ITO", "BK7", "fused silica", "water", "air", "vacuum"]
VISIBLE = np.linspace(360.0, 830.0, 471)  # 1 nm steps, both ends of Mitsuba's range included


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


# -- dispersion formulas: hand values ---------------------------------------------------------
def _rii_yaml(tmp_path, name, formula, coefficients, rng="0.2 2.0", extra=""):
    p = tmp_path / f"{name}.yml"
    p.write_text(f"REFERENCES: test\nDATA:\n  - type: formula {formula}\n"
                 f"    wavelength_range: {rng}\n    coefficients: {coefficients}\n{extra}")
    return p


def test_formulas_against_hand_computation(tmp_path):
    lam = 0.55  # um
    # 1 and 2: one-term Sellmeier n^2 = 1 + 1.1 lam^2 / (lam^2 - 0.1^2)
    sell = math.sqrt(1 + 1.1 * lam**2 / (lam**2 - 0.01))
    cases = [
        (1, "0 1.1 0.1", sell),
        (2, "0 1.1 0.01", sell),
        (3, "2.25 0.01 -2", math.sqrt(2.25 + 0.01 / lam**2)),
        # 4: the same Sellmeier as C1=1, C2=1.1, C3=2, C4=0.1, C5=2 plus a lam^2 term
        (4, "1 1.1 2 0.1 2 0 0 0 0 0.003 2", math.sqrt(1 + 1.1 * lam**2 / (lam**2 - 0.01) + 0.003 * lam**2)),
        (5, "1.5 0.004 -2", 1.5 + 0.004 / lam**2),
        (6, "0 0.05 200", 1 + 0.05 / (200 - lam**-2)),
        (7, "1.5 0.01 0.001 0.002", 1.5 + 0.01 / (lam**2 - 0.028) + 0.001 / (lam**2 - 0.028) ** 2
         + 0.002 * lam**2),
        (8, "0.25", math.sqrt(2.0)),  # (n^2-1)/(n^2+2) = 1/4  ->  n^2 = 2
        (9, "2.25 0.01 0.04", math.sqrt(2.25 + 0.01 / (lam**2 - 0.04))),
    ]
    for formula, coeffs, n in cases:
        mat = M.resolve(_rii_yaml(tmp_path, f"f{formula}", formula, coeffs))
        assert abs(mat.index(550.0).real - n) < 1e-12, formula
        assert mat.wavelength_range == (200.0, 2000.0)


def test_formula_plus_tabulated_k_and_bad_types(tmp_path):
    extra = "  - type: tabulated k\n    data: |\n        0.3 0.0\n        0.9 0.06\n"
    mat = M.resolve(_rii_yaml(tmp_path, "fk", 5, "1.5", extra=extra))
    assert mat.wavelength_range == (300.0, 900.0)  # overlap of the n and k ranges
    assert abs(mat.index(600.0) - (1.5 + 0.03j)) < 1e-12  # linear in wavelength
    bad = tmp_path / "bad.yml"
    bad.write_text("DATA:\n  - type: tabulated n2\n    data: |\n        0.5 1e-20\n")
    with pytest.raises(MaterialError, match="bad.yml.*unsupported"):
        M.resolve(bad)



def test_rii_data_types(tmp_path):
    """Each DATA type of sources.RII_DATA_TYPES gives its parts: ``tabulated nk`` both n and k
    (the first entry that gives a part wins); an unknown or empty type names the entry."""
    nk = tmp_path / "nk.yml"
    nk.write_text("DATA:\n  - type: tabulated nk\n    data: |\n        0.4 1.5 0.1\n        0.8 1.7 0.3\n"
                  "  - type: tabulated k\n    data: |\n        0.4 9.0\n        0.8 9.0\n")
    mat = sources.load_file(nk)
    assert abs(mat.index(600.0) - (1.6 + 0.2j)) < 1e-12  # linear between the two rows
    for bad_type in ("''", "formula", "formula 2 3", "tabulated"):
        bad = tmp_path / "bad.yml"
        bad.write_text(f"DATA:\n  - type: {bad_type}\n    data: |\n        0.5 1.0\n")
        with pytest.raises(MaterialError, match=r"DATA\[0\].*unsupported data type"):
            sources.load_file(bad)


# -- files --------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".csv", ".yml", ".spd"])
def test_file_round_trip(tmp_path, suffix):
    wl = np.linspace(360.0, 830.0, 48)
    for name in ["Au", "SiO2", "Si"]:
        written = M.save_material(name, tmp_path / f"{name}{suffix}", wl)
        back = M.resolve(str(tmp_path / f"{name}{suffix}"))
        # 10 significant digits are written: relative 1e-9 covers the rounding
        np.testing.assert_allclose(back.index(wl), M.resolve(name).index(wl), rtol=1e-9, atol=1e-12)
        assert back.wavelength_range == (360.0, 830.0)
        assert written.exists()
    if suffix == ".spd":
        assert (tmp_path / "Au.k.spd").exists()
        assert M.resolve(tmp_path / "Au.eta.spd").index(550.0) == M.resolve(str(tmp_path / "Au.spd")).index(550.0)


def test_material_file_formats_are_one_registry(tmp_path):
    """Each suffix belongs to one format object of ``sources.MATERIAL_FILES``, which reads
    it (``resolve`` knows a file by it, any case) and, but for ``.txt``, writes it."""
    formats = {s: f for f in sources.MATERIAL_FILES for s in f.suffixes}
    assert sorted(formats) == sorted(sources.FILE_SUFFIXES) == [".csv", ".spd", ".txt", ".yaml", ".yml"]
    assert len(formats) == len(sources.FILE_SUFFIXES)                       # no suffix in two formats
    for suffix, fmt in formats.items():
        assert sources.file_format(f" Dir/Film{suffix.upper()} ") is fmt
        assert sources.is_material_file(f"film{suffix}")
    assert sources.file_format("film.eta.spd") is sources.SPD and sources.file_format("SiO2") is None
    assert not sources.is_material_file("film.dat")
    assert [s for s, f in formats.items() if not f.writable] == [".txt"]
    with pytest.raises(MaterialError, match=r"unknown format for .*film\.txt.* \(use \.csv, \.yml or \.spd\)"):
        M.save_material("SiO2", tmp_path / "film.txt")
    assert sources.SPD.pair(tmp_path / "Au.k.spd") == (tmp_path / "Au.eta.spd", tmp_path / "Au.k.spd")
    assert sources.SPD.pair(tmp_path / "a.b.SPD") == (tmp_path / "a.b.eta.spd", tmp_path / "a.b.k.spd")


def test_mitsuba_spd_file_equals_preset():
    d = sources.mitsuba_ior_dir()
    assert d is not None
    via_file = M.resolve(d / "Cu.eta.spd")
    np.testing.assert_array_equal(via_file.index(VISIBLE), M.resolve("mitsuba:Cu").index(VISIBLE))


def test_csv_variants(tmp_path):
    um = tmp_path / "um.csv"
    um.write_text("# my film\nwavelength (um), n, k\n0.3, 2.0, 0.1\n0.9, 1.4, 0.0\n")
    mat = M.resolve(str(um))
    assert mat.wavelength_range == (300.0, 900.0)
    assert abs(mat.index(600.0) - (1.7 + 0.05j)) < 1e-12
    plain = tmp_path / "plain.txt"
    plain.write_text("350 1.5\n850 1.6\n")  # no header: nm, n (k = 0)
    assert abs(M.resolve(str(plain)).index(600.0) - 1.55) < 1e-12
    swapped = tmp_path / "swapped.csv"
    swapped.write_text("k;n;wl_nm\n0.1;2;350\n0.1;2;850\n")
    assert M.resolve(str(swapped)).index(500.0) == 2 + 0.1j


@pytest.mark.parametrize("suffix, text, line, first", [
    # issue 39: rows 400,1.5,0 and 400,2.5,0 made n step from 1.5 to 2.5 at 400 nm
    (".csv", "wavelength,n,k\n360,1.5,0\n400,1.5,0\n400,2.5,0\n830,2.5,0\n", 4, 3),
    (".spd", "# n\n360 1.5\n400 1.5\n400 2.5\n830 2.5\n", 4, 3),
    (".yml", "DATA:\n  - type: tabulated nk\n    data: |\n        0.36 1.5 0\n        0.40 1.5 0\n"
             "        0.40 2.5 0\n        0.83 2.5 0\n", 3, 2),
])
def test_a_file_that_repeats_a_wavelength_is_refused_naming_the_line(tmp_path, suffix, text, line, first):
    p = tmp_path / f"film{suffix}"
    p.write_text(text)
    with pytest.raises(MaterialError, match=rf"film{re.escape(suffix)}.*line {line} .*repeats the wavelength "
                                            rf"400 nm \(first on line {first}\)"):
        M.resolve(str(p))


def test_wavelengths_may_decrease_but_not_turn_back(tmp_path):
    down = tmp_path / "down.csv"
    down.write_text("830 1.6 0\n600 1.5 0\n360 1.4 0\n")   # as some spectrometers write
    assert abs(M.resolve(str(down)).index(480.0) - 1.45) < 1e-12
    back = tmp_path / "back.csv"
    back.write_text("360 1.5 0\n600 1.5 0\n500 1.6 0\n830 1.6 0\n")
    with pytest.raises(MaterialError, match=r"back.csv.*line 3 .*turns back to 500 nm after 600 nm"):
        M.resolve(str(back))


def test_layers_quote_a_path_with_a_semicolon_and_a_space(tmp_path):
    plain = tmp_path / "glass.csv"
    plain.write_text("360,1.7,0\n830,1.6,0\n")
    odd = tmp_path / "my films" / "a;b.csv"
    odd.parent.mkdir()
    odd.write_text(plain.read_text())
    text = tf.materials.stack.format_layers([(str(odd), 120.0), ("SiO2", 80.25)])
    assert text == f'"{odd}" 120; SiO2 80.25'
    assert tf.parse_layers(text) == [(str(odd), 120.0), ("SiO2", 80.25)]
    assert tf.parse_layers(f"'{odd}' 120") == [(str(odd), 120.0)]
    wl = np.linspace(360.0, 830.0, 11)
    R = tf.Stack(layers=text, substrate=1.5).rt(wavelength=wl, theta=0.3).R
    np.testing.assert_array_equal(R, tf.Stack(layers=f"{plain} 120; SiO2 80.25", substrate=1.5)
                                  .rt(wavelength=wl, theta=0.3).R)
    with pytest.raises(tf.ThinFilmError, match=r"thickness must be a number of nm, got 'films/a' .*goes in quotes"):
        tf.parse_layers(f"{odd} 120")


@pytest.mark.parametrize("text, words", [
    ("0.3 1.5 0\n0.9 1.5 0\n", "look like µm"),
    ("350 1.5 0\n400 oops 0\n", "line 2.*not numeric"),
    ("350 1.5 -0.01\n850 1.5 0\n", "k must be >= 0"),
    ("350 -1.5 0\n850 1.5 0\n", "n must be > 0"),
    ("350 1.5 0\n450 1.5 0\n", "350-450 nm.*360-830"),
])


def test_bad_csv_files_name_the_problem(tmp_path, text, words):
    p = tmp_path / "film.csv"
    p.write_text(text)
    with pytest.raises(MaterialError, match=words) as err:
        M.resolve(str(p))
    assert "film.csv" in str(err.value)


@pytest.mark.parametrize("text, where", [
    # an unclosed flow list: PyYAML reports where it gave up and where the list opened
    ("DATA:\n  - type: [tabulated nk\n    data: |\n      0.5 1.5 0\n",
     "at line 3, column 9: did not find expected ',' or ']' (while parsing a flow sequence at line 2, column 11)"),
    ("DATA:\n  - type: tabulated nk\n\tdata: 1\n",
     "at line 3, column 1: found a tab character that violates indentation"),
])


def test_malformed_yaml_names_the_file_and_the_line(tmp_path, text, where):
    # issue 30: PyYAML's own message says 'in "<unicode string>", line 2, column 6'
    p = tmp_path / "film.yml"
    p.write_text(text)
    with pytest.raises(MaterialError) as err:
        M.resolve(str(p))
    msg = str(err.value)
    assert str(p) in msg and "not valid YAML " + where in msg, msg
    assert "unicode string" not in msg and "\n" not in msg
    # the same through a stack's layers (how scenes name a file)
    with pytest.raises(tf.ThinFilmError, match="film.yml.*line 3"):
        tf.Stack(layers=f"{p} 100", substrate=1.5)


def test_binary_yaml_file_is_named(tmp_path):
    p = tmp_path / "film.yml"
    p.write_bytes(b"\xff\xfe\x00DATA")
    with pytest.raises(MaterialError, match="film.yml.*not UTF-8 text"):
        M.resolve(str(p))


def test_missing_file_is_named(tmp_path):
    with pytest.raises(MaterialError, match="nope.csv.*no such file"):
        M.resolve(str(tmp_path / "nope.csv"))


# -- Mitsuba presets --------------------------------------------------------------------------
def test_mitsuba_presets():
    au = M.resolve("mitsuba:Au")
    assert au is not M.resolve("Au") and au.name == "mitsuba:Au"
    # Mitsuba's Au (luxpop / Palik) at 550 nm: within the Au dataset spread around J&C
    z = au.index(550.0)
    assert abs(z.real - 0.42) < 0.15 and abs(z.imag - 2.47) < 0.4
    with pytest.raises(MaterialError, match=r"mitsuba:Li.*306.*751.*360-830"):  # does not reach 830 nm
        M.resolve("mitsuba:Li")
    with pytest.raises(MaterialError, match="mitsuba:Au"):
        M.resolve("mitsuba:Aux")


def test_mitsuba_tio2_labels_are_swapped():
    # Rutile is positive uniaxial: Devore 1951 at 560 nm gives n_o = 2.65, n_e = 2.95.
    # Mitsuba's "TiO2" holds the extraordinary and "TiO2-e" the ordinary index.
    n_o = M.resolve("main/TiO2/Devore-o", require_range=None).index(560.0).real
    n_e = M.resolve("main/TiO2/Devore-e", require_range=None).index(560.0).real
    with pytest.warns(UserWarning, match="swapped"):
        plain = M.resolve("mitsuba:TiO2_palik").index(560.0).real
    with pytest.warns(UserWarning, match="swapped"):
        e = M.resolve("mitsuba:TiO2-e_palik").index(560.0).real
    # 0.02: the luxpop table rounds to 0.01 and Devore's fit is good to ~0.01
    assert abs(plain - n_e) < 0.02 and abs(e - n_o) < 0.02
    assert "extraordinary" in M.resolve("mitsuba:TiO2_palik").reference


def test_warning_free_for_ordinary_names():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        M.resolve("TiO2")
        M.resolve("mitsuba:Ag")
