"""``python -m thinfilm_mi fit`` (thinfilm_mi/cli/fit.py): JSON output, materials and
progress."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from tests.support.fit import coherent_spectra, measurement_files


def test_command_json_materials_and_progress(tmp_path):
    """The command: --json holds the parameters, residuals and --tolerance's draws (1 % thickness
    errors can only fit worse than the optimum); --materials writes the fitted dispersive material
    as a table that a layers string reads back; the bar runs on stderr."""
    from thinfilm_mi import Stack

    A, d = 1.7, 200.0
    wl = np.arange(400.0, 801.0, 10.0)
    which = {"R": ("R", 0.0, "s")}
    spectra = coherent_spectra(["?"], [d], wl=wl, which=which, index=[np.full(wl.size, A + 0j)])
    data = measurement_files(tmp_path, spectra, np.random.default_rng(6), which=which, wl=wl)
    doc = {"substrate": "BK7", "layers": "F 195", "data": data, "starts": 2,
           "materials": {"F": {"model": "cauchy", "A": 1.68, "free": ["A"]}}}
    import yaml

    (tmp_path / "m.yml").write_text(yaml.safe_dump(doc))
    proc = subprocess.run([sys.executable, "-m", "thinfilm_mi", "fit", str(tmp_path / "m.yml"), "--json",
                           "--materials", str(tmp_path / "mat"), "--tolerance", "1%:20"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    tol = out["tolerance"]
    assert tol["draws"] == 20 and tol["reduced_chi2"]["mean"] > out["reduced_chi2"]
    assert [p["name"] for p in out["parameters"]] == ["d[0]", "F.A"]
    assert out["layers"].startswith("fit_F.csv ") and len(out["datasets"][0]["residuals"]) == wl.size
    assert "fit:" in proc.stderr            # the progress bar
    layers = proc.stderr.split("material tables: ")[1].splitlines()[0]
    R = Stack(layers, substrate="BK7").rt(wl).R
    # the written table and layers are the fitted stack: its R is the fit's model, to what the
    # layers string keeps of the thickness (1e-4 nm, at |dR/dd| < 2e-3 per nm here)
    np.testing.assert_allclose(R, out["datasets"][0]["fitted"], atol=1e-6)


def test_command_warns_of_an_implausible_chi2_and_takes_the_global_stage(tmp_path, capsys):
    """Issue 50: data whose noise is 10 times the σ they declare give χ²/dof ~ 100, which the
    table and --json flag with a warning naming the likely causes; --global chooses the stage
    before the local descents (none: only those), and an unknown stage is an error naming it."""
    import yaml

    wl = np.arange(400.0, 801.0, 10.0)
    which = {"R": ("R", 0.0, "s")}
    spectra = coherent_spectra(["SiO2"], [300.0], wl=wl, which=which)
    data = measurement_files(tmp_path, spectra, np.random.default_rng(8), sigma=0.002, which=which, wl=wl)
    data[0]["sigma"] = 0.0002
    (tmp_path / "m.yml").write_text(yaml.safe_dump({"substrate": "BK7", "layers": "SiO2 290", "data": data,
                                                    "starts": 2}))
    command = [sys.executable, "-m", "thinfilm_mi", "fit", str(tmp_path / "m.yml"), "--quiet"]
    table = subprocess.run(command, capture_output=True, text=True)
    assert table.returncode == 0, table.stderr
    lines = table.stdout.splitlines()
    assert lines[0].startswith("fit: 1 parameters, 41 points, 2 starts (1 nominal, 1 evolve)"), lines[0]
    assert ", p-value " in lines[1]
    warning = next(line for line in lines if line.startswith("warning: χ²/dof"))
    for cause in ("local minimum", "missing film", "dispersion", "back side", "σ may be too small"):
        assert cause in warning, warning
    js = subprocess.run(command + ["--json", "--global", "none"], capture_output=True, text=True)
    assert js.returncode == 0, js.stderr
    out = json.loads(js.stdout)
    # χ² of ~100 per degree of freedom over 40: its p-value underflows far below the threshold
    assert out["p_value"] < 1e-3 and out["reduced_chi2"] > 50
    assert out["warnings"][0].startswith("χ²/dof") and "local minimum" in out["warnings"][0]
    assert sorted(s["origin"] for s in out["starts"]) == ["nominal", "random"]
    from thinfilm_mi.cli.tools import main

    assert main(command[3:] + ["--global", "scan"]) != 0           # in this process: a subprocess costs ~3 s
    err = capsys.readouterr().err
    assert "global stage: expected one of evolve, none, got 'scan'" in err and len(err.strip().splitlines()) == 1
