"""``python -m thinfilm_mi design`` (thinfilm_mi/cli/design.py): JSON, plot, tolerance and
render outputs, and a bad targets file in one line."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.support.design import AR, numeric_layers
from thinfilm_mi import Stack
from thinfilm_mi.cli import tools as tf_main
from thinfilm_mi.design import (
    evaluate,
)


def test_bad_targets_file_is_one_line_from_the_cli(tmp_path, capsys):
    bad = tmp_path / "bad.yml"
    bad.write_text("substrate: '1.52'\nmaterials: ['1.38']\ntargets:\n"
                   "  - {quantity: R, wavelengths: '500', value: 0, tolerance: 0.01}\n"
                   "  - {quantity: Rx, wavelengths: '500', value: 0, tolerance: 0.01}\n")
    assert tf_main.main(["design", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("python -m thinfilm_mi design: error: ")
    assert f"{bad}: targets[1]: unknown quantity 'Rx'" in err
    (tmp_path / "broken.yml").write_text("targets: [\n")
    assert tf_main.main(["design", str(tmp_path / "broken.yml"), "--quiet"]) == 2
    assert "not valid YAML" in capsys.readouterr().err
    assert tf_main.main(["design", str(tmp_path / "missing.yml"), "--quiet"]) == 2
    assert "cannot read the targets file" in capsys.readouterr().err


# ---------------------------------------------------------------------------
# command line, layering
# ---------------------------------------------------------------------------
def test_cli_json_plot_and_tolerance(tmp_path, capsys):
    fig = tmp_path / "fig.png"
    assert tf_main.main(["design", str(AR), "--json", "--seeds", "2", "--max-layers", "4", "--tolerance",
                         "1%:20", "--plot", str(fig), "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= {"layers", "merit", "seconds", "targets", "tolerance"}
    assert out["tolerance"]["draws"] == 20 and out["tolerance"]["relative"] is True
    assert len(out["targets"]) == 1 and len(out["targets"][0]["achieved"][0]) == 53
    films = numeric_layers(out["layers"])
    assert 1 <= len(films) <= 4
    Stack(out["layers"], substrate=1.52)                 # what every plugin's layers accepts
    again = evaluate(AR, out["layers"])
    assert again.merit == pytest.approx(out["merit"], rel=1e-9)
    assert fig.stat().st_size > 10_000


def test_cli_render_writes_scene_and_images(tmp_path):
    out = tmp_path / "ar.png"
    proc = subprocess.run([sys.executable, "-m", "thinfilm_mi", "design", str(AR), "--evaluate",
                           "1.38 99.6", "--render", str(out), "--size", "24x16", "--spp", "1", "--quiet"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert out.is_file() and out.with_suffix(".exr").is_file()
    xml = out.with_suffix(".xml").read_text()
    assert 'type="thinfilm_dielectric"' in xml and 'value="1.38 99.6"' in xml


def test_render_scene_of_an_absorbing_substrate_is_a_conductor():
    from thinfilm_mi.cli.design import design_scene
    from thinfilm_mi.materials.catalog import resolve

    xml = design_scene("1.46 100", resolve("0.2+3j"), "0.2+3j", "1.0")
    assert 'type="thinfilm_conductor"' in xml and '<float name="k" value="3.0"/>' in xml
    assert 'name="material" value="Au"' in design_scene("1.46 100", resolve("Au"), "Au", "1.0")
