"""``python -m thinfilm_mi`` (thinfilm_mi/cli/tools.py): spectrum, materials, demo and
colour commands, their output formats and their one-line errors."""
from __future__ import annotations

import numpy as np
import pytest

from tests.support.cli import error_lines, png_size
from thinfilm_mi import Stack  # noqa: E402
from thinfilm_mi.cli import tools as tf_main  # noqa: E402
from thinfilm_mi.errors import UsageError  # noqa: E402


def test_spectrum_matches_stack(capsys):
    layers, angles = "1.46 500; 0.42+2.47j 20", [0.0, 30.0, 60.0]
    rc = tf_main.main(["spectrum", "--layers", layers, "--substrate", "1.6", "--ambient", "1.0",
                       "--angles", "0,30,60", "--wl", "400:700:20"])
    out = capsys.readouterr().out
    assert rc == 0
    rows = [line.split() for line in out.splitlines() if line.strip() and not line.startswith("#")]
    assert rows[0] == ["wl_nm", "R@0", "T@0", "R@30", "T@30", "R@60", "T@60"]
    table = np.array(rows[1:], dtype=float)
    wl = np.arange(400.0, 701.0, 20.0)
    np.testing.assert_array_equal(table[:, 0], wl)
    stack = Stack(layers, substrate=1.6, ambient=1.0)
    for j, a in enumerate(angles):
        res = stack.rt(wl, np.radians(a))
        np.testing.assert_allclose(table[:, 1 + 2 * j], res.R, atol=1e-6)
        np.testing.assert_allclose(table[:, 2 + 2 * j], res.T, atol=1e-6)


def test_spectrum_plot_and_bad_input(tmp_path, capsys):
    plot = tmp_path / "rt.png"
    assert tf_main.main(["spectrum", "--layers", "1.46 100", "--angles", "0", "--wl", "400:500:50",
                         "--plot", str(plot)]) == 0
    assert plot.is_file() and plot.stat().st_size > 1000
    capsys.readouterr()
    assert tf_main.main(["spectrum", "--layers", "1.46", "--angles", "0"]) == 2
    assert len(error_lines(capsys.readouterr().err)) == 1
    assert tf_main.main(["spectrum", "--layers", "1.46 10", "--angles", "95"]) == 2


def test_materials_runs(capsys):
    from thinfilm_mi.materials import catalog as materials

    rc = tf_main.main(["materials"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    if hasattr(materials, "format_material_table"):
        assert captured.out.strip()
    else:
        assert "no material table" in captured.err


def test_demo_reflectance_image(tmp_path):
    # the fallback of `demo` while scenes/demo.xml does not exist (and a check of its plot)
    path = tf_main.write_reflectance_image(tmp_path / "demo_reflectance.png")
    assert png_size(path)[0] > 400


import csv
import json

colour = pytest.importorskip("colour")

from thinfilm_mi.colour.report import (  # noqa: E402
    RECORD_KEYS,
    colour_report,
)

# colour-science warns when sd_to_XYZ aligns a table to the requested shape (here on purpose)
pytestmark = pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning")


# --------------------------------------------------------------------------------------
# command line


ARGS = ["colour", "--layers", "1.38 99.6", "--substrate", "1.52", "--angles", "0:80:20",
        "--illuminant", "D65"]


def test_cli_json_and_csv(tmp_path, capsys):
    out_csv = tmp_path / "colour.csv"
    assert tf_main.main(ARGS + ["--json", "--csv", str(out_csv)]) == 0
    records = json.loads(capsys.readouterr().out)
    assert len(records) == 5 * 2
    assert all(list(r) == list(RECORD_KEYS) for r in records)
    assert [(r["angle"], r["quantity"]) for r in records[:4]] == [(0, "R"), (0, "T"), (20, "R"), (20, "T")]
    api = colour_report(Stack("1.38 99.6", substrate=1.52), [0, 20, 40, 60, 80], "D65").as_dicts()
    assert records == json.loads(json.dumps(api))  # the CLI prints the API's records
    assert all(0 <= r["Y"] <= 1 and r["srgb"].startswith("#") and len(r["srgb"]) == 7 for r in records)
    with open(out_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(RECORD_KEYS)
    assert len(rows) == len(records)
    for row, rec in zip(rows, records):
        assert row["quantity"] == rec["quantity"] and row["srgb"] == rec["srgb"]
        for k in ("angle", "X", "Y", "Z", "x", "y", "L", "a", "b"):
            assert float(row[k]) == rec[k]  # repr round-trips float64 exactly


def test_cli_table_and_polarization(capsys):
    assert tf_main.main(ARGS) == 0
    out = capsys.readouterr().out
    rows = [l.split() for l in out.splitlines() if l.strip() and not l.startswith("#")]
    assert rows[0][:3] == ["angle", "qty", "X%"] and rows[0][-1] == "Yv%"
    assert len(rows) == 1 + 10
    assert rows[1][:2] == ["0", "R"] and float(rows[1][3]) == pytest.approx(1.302, abs=1e-3)
    assert tf_main.main(ARGS + ["--polarization", "s,p", "--json", "--observer", "10"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert len(records) == 5 * 2 * 2
    assert list(records[0])[:3] == ["angle", "quantity", "polarization"]


@pytest.mark.parametrize("extra, word", [
    (["--illuminant", "D50"], "illuminant"),
    (["--illuminant", "blackbody:0"], "temperature"),
    (["--angles", "0,90"], "--angles"),
    (["--angles", "0:x"], "--angles"),
    (["--polarization", "circular"], "polarizations"),
    (["--observer", "5"], "--observer"),
])


def test_cli_bad_input_is_one_line(extra, word, capsys):
    assert tf_main.main(ARGS + extra) == 2
    err = [l for l in capsys.readouterr().err.splitlines() if l.strip()]
    assert len(err) == 1 and "error:" in err[0] and word in err[0], err


def test_cli_figure_opens(tmp_path, capsys):
    import matplotlib.image

    fig = tmp_path / "sub" / "colour.png"
    assert tf_main.main(ARGS + ["--plot", str(fig), "--illuminant", "blackbody:2856"]) == 0
    assert str(fig) in capsys.readouterr().err
    img = matplotlib.image.imread(fig)
    assert img.shape[0] > 500 and img.shape[1] > 1000 and img.shape[2] in (3, 4)
    rgb = img[..., :3]
    # not blank: many pixels differ from the white background, in more than one colour
    assert (rgb.min(axis=-1) < 0.9).mean() > 0.02
    assert len(np.unique((rgb * 255).astype(np.uint8).reshape(-1, 3), axis=0)) > 50


def test_parse_angles_ranges():
    np.testing.assert_array_equal(tf_main.parse_angles("0:80:10"), np.arange(0, 81, 10.0))
    np.testing.assert_array_equal(tf_main.parse_angles("0, 30 60"), [0.0, 30.0, 60.0])
    np.testing.assert_array_equal(tf_main.parse_angles("90"), [90.0])  # spectrum allows grazing

    with pytest.raises(UsageError, match=r"--angles.*\[0, 90\)"):
        tf_main.parse_angles("90", below_90=True)


import mitsuba as mi

mi.set_variant("llvm_ad_spectral")
from thinfilm_mi.cli.tools import main as module_main  # noqa: E402


def test_spectrum_with_too_many_wavelengths_is_one_clear_line(capsys):
    rc = module_main(["spectrum", "--layers", "1.46 100", "--wl", "360:830:1e-7"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "--wl" in err[0] and "4700000001 values" in err[0] and "at most" in err[0]


def test_closed_pipe_ends_quietly():
    # `python -m thinfilm_mi materials | head -1`: the reader may close the pipe before
    # the command writes; closing the read end first makes that order certain. The
    # command must end without a traceback, with the closed-pipe status
    import os
    import subprocess
    import sys

    from thinfilm_mi.cli.parser import CLOSED_PIPE

    read, write = os.pipe()
    os.close(read)
    try:
        proc = subprocess.run([sys.executable, "-m", "thinfilm_mi", "materials"],
                              stdout=write, stderr=subprocess.PIPE, timeout=120)
    finally:
        os.close(write)
    err = proc.stderr.decode()
    assert proc.returncode == CLOSED_PIPE, err
    assert "Traceback" not in err and "BrokenPipe" not in err, err
