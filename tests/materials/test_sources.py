"""Material sources (thinfilm_mi/materials/sources.py): formulas, user files (CSV, YAML,
Mitsuba spectra) and their errors, the file formats' registry, Mitsuba presets.

Reference values are published numbers (cited at each test), not numbers read
back from this package's own files.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.materials import VISIBLE
from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials import catalog as M
from thinfilm_mi.materials import sources


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
