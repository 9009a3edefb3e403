"""Measurement files (thinfilm_mi/design/fitfile.py): each bad file fails in one error that
names the file and the entry, from the command too."""
from __future__ import annotations

import subprocess
import sys

import pytest

from thinfilm_mi.design import fit
from thinfilm_mi.errors import ThinFilmError

BAD = {
    "missing column": ("value", "wavelength,sigma\n500,0.1\n", "data[0] (d.csv): missing column 'value'"),
    "sigma <= 0": ("", "wavelength,value,sigma\n500,0.1,0.01\n510,0.1,0\n",
                   "data[0] (d.csv): sigma must be > 0, got 0 (line 3)"),
    "outside a material's data": ("ag", "wavelength,value\n150,0.1\n200,0.1\n",
                                  "data[0] (d.csv): wavelength 150 nm is out of reach: material 'Ag'"),
    "unknown model": ("model", "wavelength,value\n500,0.1\n510,0.1\n",
                      "materials.H: unknown model 'drude'; expected one of constant, cauchy"),
    "parameter in no data": ("unused", "wavelength,value\n500,0.1\n510,0.1\n",
                             "materials.X: appears in no film of layers, so in no data"),
    "unknown bound": ("bounds", "wavelength,value\n500,0.1\n510,0.1\n",
                      "bounds.x: not a free parameter; free parameters: d[0], d[1], H.A"),
    "sigma on some data only": ("mixed", "wavelength,value\n500,0.1\n510,0.1\n",
                                "data[1] (d.csv): either every data set carries sigma"),
    "no index at the start": ("pole", "wavelength,value\n300,0.1\n510,0.1\n",
                              "materials.H: its sellmeier parameters"),
    "parameter without effect": ("zero", "wavelength,value\n500,0.1\n510,0.1\n520,0.1\n",
                                 "H.A: appears in no data"),
}


@pytest.mark.parametrize("case", list(BAD), ids=list(BAD))
def test_bad_files_give_one_clear_error(tmp_path, case):
    """Issue 43, check 5: each error names the file and the entry, in one line, from the command too."""
    what, csv_text, message = BAD[case]
    (tmp_path / "d.csv").write_text(csv_text)
    doc = {"substrate": 1.52, "layers": "H 100; 1.46 80", "data": [{"file": "d.csv", "quantity": "R"}],
           "materials": {"H": {"model": "cauchy", "A": 2.0, "free": ["A"]}}}
    if what == "ag":
        doc["layers"] = "Ag 10"
        del doc["materials"]
    elif what == "model":
        doc["materials"]["H"]["model"] = "drude"
    elif what == "unused":
        doc["materials"]["X"] = {"model": "constant", "n": 1.4}
    elif what == "bounds":
        doc["bounds"] = {"x": [0, 1]}
    elif what == "mixed":
        doc["data"].append({"file": "d.csv", "quantity": "T", "sigma": 0.01})
    elif what == "pole":
        # a resonance at 400 nm (C1 = 0.16 µm²): n² < 0 just below it
        doc["materials"]["H"] = {"model": "sellmeier", "B1": 1.0, "C1": 0.16, "free": ["B1"]}
    elif what == "zero":
        # the index of a film of no thickness (and none fitted) changes nothing
        doc["layers"], doc["thickness"] = "H 0; 1.46 80", "fixed"
    import yaml

    (tmp_path / "m.yml").write_text(yaml.safe_dump(doc))
    with pytest.raises(ThinFilmError) as err:
        fit(tmp_path / "m.yml")
    assert str(tmp_path / "m.yml") in str(err.value) and message in str(err.value), str(err.value)
    proc = subprocess.run([sys.executable, "-m", "thinfilm_mi", "fit", str(tmp_path / "m.yml"), "--quiet"],
                          capture_output=True, text=True) if case == "sigma <= 0" else None
    if proc is not None:
        assert proc.returncode == 2 and proc.stdout == ""
        assert proc.stderr.count("\n") == 1 and message in proc.stderr, proc.stderr


def test_a_wavelength_given_twice_with_two_values_is_refused_from_the_command(tmp_path):
    """A data file that repeats a wavelength with two values is refused as a material file is:
    the file, the line, the first occurrence; rows that go down in wavelength, several angles
    at one wavelength and a row written twice stay."""
    import yaml

    doc = {"substrate": 1.52, "layers": "1.46 80", "data": [{"file": "d.csv", "quantity": "R"}]}
    (tmp_path / "m.yml").write_text(yaml.safe_dump(doc))
    (tmp_path / "d.csv").write_text("wavelength,value\n400,0.1\n400,0.2\n404,0.2\n")
    proc = subprocess.run([sys.executable, "-m", "thinfilm_mi", "fit", str(tmp_path / "m.yml"), "--quiet"],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stdout == "", proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert (f"{tmp_path / 'm.yml'}: data[0] (d.csv): line 3 of {tmp_path / 'd.csv'} repeats the wavelength "
            "400 nm with another value (first on line 2); give one value per wavelength") in proc.stderr
    (tmp_path / "d.csv").write_text("wavelength,angle,value,sigma\n404,0,0.1,0.01\n400,0,0.2,0.01\n"
                                    "400,45,0.3,0.01\n400,0,0.2,0.02\n")
    with pytest.raises(ThinFilmError, match=r"line 5 of .* repeats the wavelength 400 nm at 0° with another "
                                            r"value \(first on line 3\)"):
        fit(tmp_path / "m.yml")
    from thinfilm_mi.design.fitfile import load_measurements

    (tmp_path / "d.csv").write_text("wavelength,angle,value\n404,0,0.1\n400,0,0.2\n400,45,0.3\n400,0,0.2\n")
    (d,) = load_measurements(tmp_path / "m.yml").datasets
    assert d.wavelengths.tolist() == [404, 400, 400, 400] and d.angles.tolist() == [0, 0, 45, 0]
