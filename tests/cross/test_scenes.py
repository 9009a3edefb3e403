"""Every scene in scenes/*.xml renders through the command line at a tiny size.

One ``python -m thinfilm_mi render scenes/*.xml`` subprocess renders all of
them (the CLI takes several scenes and sets Mitsuba up once), so scenes added
later are covered without editing this file. Each EXR must read back with the
requested size, RGB channels, finite pixels that are not all black and have
no negative luminance, and its metadata (scene path, variant, spp, seed, no parameters).
Scenes that use Mitsuba's ``stokes`` integrator (which refuses unpolarized variants) are
rendered by the same command in ``llvm_ad_spectral_polarized`` (the CLI switches to the
polarized variant of the requested family and says so) and must also carry the S0..S3
channels, with S0 equal to the RGB image. Every scene is also rendered with
``--variant llvm_ad_rgb`` (the project requires that every scene renders there), by a
second subprocess for all of them at once, with the same checks; there too the
``stokes`` scenes go to ``llvm_ad_spectral_polarized`` (thin films refuse polarized RGB). The
error paths of the CLI (bad -D, missing file, unknown plugin) are in
tests/cli/test_render.py.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("OpenEXR")

from tests.support import ROOT
from thinfilm_mi.batch import scene as tf_scene  # noqa: E402
from thinfilm_mi.batch.exr import read_exr  # noqa: E402
from thinfilm_mi.cli import render as cli  # noqa: E402
from thinfilm_mi.errors import UsageError  # noqa: E402

REPO = ROOT
SCENES = sorted((REPO / "scenes").glob("*.xml"))
WIDTH, HEIGHT, SPP, SEED = 24, 16, 1, 3
POLARIZED_VARIANT = "llvm_ad_spectral_polarized"
RGB_VARIANT = "llvm_ad_rgb"
STOKES = ["S0", "S1", "S2", "S3"]


def needs_polarized(scene: Path) -> bool:
    """Scenes with Mitsuba's ``stokes`` integrator render in polarized variants only."""
    return 'type="stokes"' in scene.read_text()


def variant_of(scene: Path, requested: str = tf_scene.DEFAULT_VARIANT) -> str:
    return POLARIZED_VARIANT if needs_polarized(scene) else requested


def render_all(scenes: list[Path], variant: str, out: Path) -> tuple[str, int]:
    """Render ``scenes`` in one CLI subprocess into ``out``; returns its stderr and exit
    status (checked by :func:`test_every_scene_rendered`, so that a scene that fails
    fails its own test, not every scene's)."""
    proc = subprocess.run(
        [sys.executable, "-m", "thinfilm_mi", "render", *map(str, scenes), "--out-dir", str(out),
         "--size", f"{WIDTH}x{HEIGHT}", "--spp", str(SPP), "--seed", str(SEED),
         "--variant", variant],
        capture_output=True, text=True, cwd=out, timeout=900)
    return proc.stderr, proc.returncode


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Render every scene once; returns (output folder, the CLI's stderr, its exit status)."""
    out = tmp_path_factory.mktemp("scenes")
    return out, *render_all(SCENES, tf_scene.DEFAULT_VARIANT, out)


@pytest.fixture(scope="module")
def rendered_rgb(tmp_path_factory):
    """Every scene rendered with --variant llvm_ad_rgb by one CLI subprocess; returns
    (output folder, the CLI's stderr, its exit status)."""
    out = tmp_path_factory.mktemp("scenes_rgb")
    return out, *render_all(SCENES, RGB_VARIANT, out)


def check_image(scene: Path, exr: Path, variant: str, err: str, stokes: list[str]) -> np.ndarray:
    """The checks every rendered scene passes; returns its RGB image."""
    assert exr.is_file(), [line for line in err.splitlines() if scene.name in line] or err[-4000:]
    channels, header = read_exr(exr)
    assert sorted(channels) == sorted(["B", "G", "R", *stokes])
    image = np.stack([channels[c] for c in "RGB"], axis=-1)
    assert image.shape == (HEIGHT, WIDTH, 3)
    assert np.all(np.isfinite(image)), f"{scene.name}: NaN/inf pixels"
    # single spectral samples can fall outside the sRGB gamut (a negative channel),
    # but their luminance Y (CIE y-bar >= 0 weighting of a radiance >= 0) cannot; an
    # RGB variant's colours (integrated spectra) can be outside the gamut too
    luminance = image @ np.array([0.2126, 0.7152, 0.0722])
    assert luminance.min() >= -1e-4, f"{scene.name}: negative luminance {luminance.min()}"
    assert image.mean() > 1e-3, f"{scene.name}: black image"
    assert header["scene"] == str(scene.resolve())
    assert header["variant"] == variant
    assert header["spp"] == SPP
    assert header["seed"] == SEED
    assert header["parameters"] == ""
    assert exr.with_suffix(".png").is_file()
    assert f"-> {exr}" in err  # the one-line summary of this scene
    return image


def test_scenes_exist():
    names = {p.stem for p in SCENES}
    assert "demo" in names
    # the paper's Fig. 8-10 scenes (README and notebooks/02_rendering.ipynb use them)
    assert any(n.startswith("fig8") for n in names)
    assert any(n.startswith("fig9") for n in names)
    assert any(n.startswith("fig10") for n in names)


def test_paper_scenes_name_the_papers_model():
    # thinfilm_diffuse defaults to model "exact"; the Fig. 9/10 scenes render the paper's
    # figures, so they name the paper's model as published ("single", eq. 8-10)
    paper = [p for p in SCENES if p.read_text().startswith("<!-- Hirayama et al., Fig.")
             and "thinfilm_diffuse" in p.read_text()]
    assert len(paper) == 5, [p.name for p in paper]
    for scene in paper:
        assert '<default name="model" value="single"/>' in scene.read_text(), scene.name


def _check_scene(scene: Path, out: Path, err: str, requested: str) -> None:
    exr = out / f"{scene.stem}.exr"
    stokes = [f"{s}.{c}" for s in STOKES for c in "RGB"] if needs_polarized(scene) else []
    image = check_image(scene, exr, variant_of(scene, requested), err, stokes)
    if stokes:
        assert (f"{scene} uses the 'stokes' integrator, which needs a polarized variant: "
                f"rendering it in {POLARIZED_VARIANT} instead of {requested}") in err
        channels, _ = read_exr(exr)
        S = np.stack([np.stack([channels[f"{s}.{c}"] for c in "RGB"], -1) for s in STOKES])
        assert np.all(np.isfinite(S))
        # the film's RGB is the intensity S0 (up to float32 rounding of the conversions);
        # the degree of polarization is checked per wavelength in tests/cross/test_polarized.py
        assert np.allclose(S[0], image, rtol=1e-4, atol=1e-5)
        assert np.abs(S[1:]).max() > 0   # the stokes channels are filled


@pytest.mark.parametrize("scene", SCENES, ids=[p.stem for p in SCENES])
def test_scene_renders(scene, rendered):
    _check_scene(scene, *rendered[:2], tf_scene.DEFAULT_VARIANT)


@pytest.mark.parametrize("scene", SCENES, ids=[p.stem for p in SCENES])
def test_scene_renders_in_rgb(scene, rendered_rgb):
    _check_scene(scene, *rendered_rgb[:2], RGB_VARIANT)


@pytest.mark.parametrize("fixture", ["rendered", "rendered_rgb"])
def test_every_scene_rendered(fixture, request):
    # both CLI runs exit 0: no scene failed (the failing scene's own test says why)
    _, err, returncode = request.getfixturevalue(fixture)
    assert returncode == 0, err[-4000:]


def test_several_scenes_need_out_dir_not_o(tmp_path):
    # -o names one file; with several scenes it is a one-line usage error, nothing rendered
    with pytest.raises(UsageError, match="--out-dir"):
        cli.plan_outputs([str(SCENES[0]), str(SCENES[-1])], str(tmp_path / "x.exr"))
    with pytest.raises(UsageError, match="both be written"):
        cli.plan_outputs(["a/s.xml", "b/s.xml"], None, tmp_path)
    assert cli.plan_outputs(["a/s.xml", "b/t.xml"], None, tmp_path) == [tmp_path / "s.exr",
                                                                         tmp_path / "t.exr"]


def test_failing_scene_does_not_stop_the_others(tmp_path, capfd):
    # a missing scene among several: one error line, the good scene is still rendered, exit 2
    good = tmp_path / "good.xml"
    good.write_text("""<scene version="3.0.0"><integrator type="path"/>
  <sensor type="perspective"><film type="hdrfilm"><integer name="width" value="4"/>
  <integer name="height" value="3"/></film></sensor>
  <emitter type="constant"/></scene>""")
    rc = cli.render_main([str(tmp_path / "missing.xml"), str(good), "--out-dir", str(tmp_path / "o"),
                          "--spp", "1"])
    err = capfd.readouterr().err
    assert rc == 2
    errors = [line for line in err.splitlines() if "error:" in line]
    assert len(errors) == 1 and "missing.xml" in errors[0]
    channels, _ = read_exr(tmp_path / "o" / "good.exr")
    assert channels["R"].shape == (3, 4)
    assert not (tmp_path / "o" / "missing.exr").exists()
