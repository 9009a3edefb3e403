"""``thinfilm-render`` (thinfilm_mi/cli/render.py): scenes, parameters, variants found for
them, files next to the scene, and errors in one line (a huge size, a failing render's
root cause, plugin tracebacks condensed)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

OpenEXR = pytest.importorskip("OpenEXR")

from tests.support import ROOT
from tests.support.cli import error_lines, png_size
from thinfilm_mi.batch import scene as tf_scene  # noqa: E402
from thinfilm_mi.cli import render as cli  # noqa: E402

REPO = ROOT
PREFIX = "thinfilm-render: error:"

# Only built-in plugins. The sphere is a gold conductor in a uniform white
# environment: the background is exactly 1, the sphere yellowish (R > B).
SCENE = """<scene version="3.0.0">
  <default name="spp" value="2"/>
  <default name="resx" value="20"/>
  <default name="resy" value="10"/>
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
    <film type="hdrfilm">
      <integer name="width" value="$resx"/><integer name="height" value="$resy"/>
      <rfilter type="box"/>
    </film>
  </sensor>
  <shape type="sphere"><bsdf type="conductor"><string name="material" value="Au"/></bsdf></shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>
"""


@pytest.fixture
def scene(tmp_path) -> Path:
    path = tmp_path / "tiny.xml"
    path.write_text(SCENE)
    return path


def _read_exr(path):
    with OpenEXR.File(str(path), separate_channels=True) as f:
        header = dict(f.header())
        channels = {k: np.array(v.pixels) for k, v in f.channels().items()}
    return channels, header


def test_render_in_process(scene, tmp_path, capfd):
    out = tmp_path / "res" / "tiny.exr"
    rc = cli.render_main([str(scene), "-o", str(out), "--spp", "3", "--size", "24x16", "--seed", "7"])
    captured = capfd.readouterr()
    assert rc == 0, captured.err
    channels, header = _read_exr(out)
    assert sorted(channels) == ["B", "G", "R"]
    assert channels["R"].shape == (16, 24)
    assert header["scene"] == str(scene.resolve())
    assert header["variant"] == "llvm_ad_spectral"
    assert header["spp"] == 3
    assert header["seed"] == 7
    assert float(header["renderTime"]) >= 0.0
    # the picture is the scene: a white background (spectral noise averages out
    # over the top row), a gold sphere in the middle (red above blue)
    background = [channels[c][0, :].mean() for c in "RGB"]
    assert np.allclose(background, 1.0, atol=0.2), background
    centre = [channels[c][6:10, 10:14].mean() for c in "RGB"]
    assert centre[0] > centre[2] + 0.2, centre
    assert 0.5 < centre[0] < 1.1, centre
    assert png_size(out.with_suffix(".png")) == (24, 16)
    assert "3 spp" in captured.err and "samples/s" in captured.err


def test_scene_parameters_and_defaults(scene, tmp_path, monkeypatch, capfd):
    # without --spp/--size the scene's own $spp/$resx/$resy (set here with -D) apply;
    # without -o the output goes to out/<stem>.exr in the working directory
    monkeypatch.chdir(tmp_path)
    rc = cli.render_main([str(scene), "-D", "resx=12", "-D", "resy=6", "-D", "spp=1"])
    assert rc == 0, capfd.readouterr().err
    channels, header = _read_exr(tmp_path / "out" / "tiny.exr")
    assert channels["G"].shape == (6, 12)
    assert header["spp"] == 1
    assert header["parameters"] == "resx=12 resy=6 spp=1"
    assert (tmp_path / "out" / "tiny.png").is_file()


def test_size_override_on_scene_without_film(tmp_path, capfd):
    # no film and no $resx: --size adds a film of that size
    text = SCENE.replace("<film", "<!-- <film").replace("</film>", "</film> -->")
    path = tmp_path / "nofilm.xml"
    path.write_text(text)
    out = tmp_path / "nofilm.exr"
    assert cli.render_main([str(path), "-o", str(out), "--spp", "1", "--size", "9x5"]) == 0
    channels, _ = _read_exr(out)
    assert channels["R"].shape == (5, 9)


def test_render_subprocess(scene, tmp_path):
    out = tmp_path / "sub.exr"
    proc = subprocess.run(
        [sys.executable, "-m", "thinfilm_mi", "render", str(scene), "-o", str(out),
         "--spp", "2", "--size", "8x6"],
        capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr
    channels, header = _read_exr(out)
    assert channels["B"].shape == (6, 8)
    assert header["spp"] == 2
    assert out.with_suffix(".png").is_file()


@pytest.mark.parametrize("case", ["bad-define", "missing-file", "unknown-plugin", "unused-define"])
def test_errors_are_one_line(case, scene, tmp_path, capfd):
    args = {
        "bad-define": [str(scene), "-D", "foo"],
        "missing-file": [str(tmp_path / "nope.xml")],
        "unknown-plugin": None,
        "unused-define": [str(scene), "-D", "nosuchparam=1"],
    }[case]
    if args is None:
        bad = tmp_path / "bad.xml"
        bad.write_text(SCENE.replace('type="conductor"', 'type="no_such_bsdf"'))
        args = [str(bad)]
    rc = cli.render_main(args + ["-o", str(tmp_path / "e.exr")])
    err = capfd.readouterr().err
    lines = error_lines(err)
    assert rc == 2
    assert len(lines) == 1, err
    assert lines[0].startswith(PREFIX)
    assert not (tmp_path / "e.exr").exists()
    if case == "unknown-plugin":
        assert "no_such_bsdf" in lines[0]


# -- scenes that need a polarized variant (issue 30, section 3) ---------------------------
STOKES = SCENE.replace(
    '<integrator type="path"><integer name="max_depth" value="3"/></integrator>',
    '<integrator type="stokes"><integrator type="path"><integer name="max_depth" value="3"/>'
    '</integrator></integrator>').replace(
    '<bsdf type="conductor"><string name="material" value="Au"/></bsdf>',
    '<bsdf type="thinfilm_dielectric"><string name="layers" value="Au 10"/></bsdf>')


@pytest.fixture
def _restore_variant():
    import mitsuba as mi

    previous = mi.variant()
    yield
    if previous is not None:
        mi.set_variant(previous)


@pytest.mark.parametrize("requested", ["llvm_ad_spectral", "llvm_ad_rgb"])
def test_scene_that_needs_a_polarized_variant_renders_as_written(requested, tmp_path, capfd,
                                                                 _restore_variant):
    # The README's `thinfilm-render scenes/*.xml ...` exited 2 on polarized_brewster.xml
    # (the stokes integrator refuses unpolarized variants). Now it is rendered in the
    # polarized spectral variant of the requested backend (thin films refuse polarized
    # RGB), said in one line, and the next scene goes back to the requested variant.
    (tmp_path / "a_stokes.xml").write_text(STOKES)
    (tmp_path / "b_plain.xml").write_text(SCENE)
    out = tmp_path / "out"
    rc = cli.render_main([str(tmp_path / "a_stokes.xml"), str(tmp_path / "b_plain.xml"),
                          "--variant", requested, "--spp", "2", "--size", "12x8",
                          "--out-dir", str(out)])
    err = capfd.readouterr().err
    assert rc == 0, err
    notices = [line for line in err.splitlines() if "polarized" in line]
    assert notices == [f"thinfilm-render: {tmp_path / 'a_stokes.xml'} uses the 'stokes' integrator, "
                       "which needs a polarized variant: rendering it in "
                       f"llvm_ad_spectral_polarized instead of {requested}"], err
    channels, header = _read_exr(out / "a_stokes.exr")
    assert header["variant"] == "llvm_ad_spectral_polarized"
    stokes = [f"S{i}.{c}" for i in range(4) for c in "RGB"]
    assert set(stokes) <= set(channels), sorted(channels)
    # the sphere's reflection polarizes: S1 is not zero everywhere (0 without a polarized render)
    assert np.abs(channels["S1.G"]).max() > 1e-3
    plain, header = _read_exr(out / "b_plain.exr")
    assert header["variant"] == requested and sorted(plain) == ["B", "G", "R"]


def test_polarization_is_found_through_includes_and_parameters(tmp_path):
    # Mitsuba's parser reads the file as the loader will: <include>s, $parameters,
    # <default>s; nothing is instantiated, no variant is set
    (tmp_path / "inc").mkdir()
    (tmp_path / "inc" / "integrator.xml").write_text(
        '<scene version="3.0.0"><integrator type="$integ"/></scene>')
    included = tmp_path / "included.xml"
    included.write_text(SCENE.replace(
        '<integrator type="path"><integer name="max_depth" value="3"/></integrator>',
        '<default name="integ" value="path"/><include filename="inc/integrator.xml"/>'))
    polarizer = tmp_path / "polarizer.xml"
    polarizer.write_text(SCENE.replace('<bsdf type="conductor"><string name="material" value="Au"/>'
                                       '</bsdf>', '<bsdf type="polarizer"/>'))
    plain = tmp_path / "plain.xml"
    plain.write_text(SCENE)
    assert ("Integrator", "path") in tf_scene.scene_plugins(included)
    assert tf_scene.scene_variant(included, {}, "llvm_ad_spectral") == ("llvm_ad_spectral", None)
    variant, notice = tf_scene.scene_variant(included, {"integ": "stokes"}, "llvm_ad_spectral")
    assert variant == "llvm_ad_spectral_polarized" and "'stokes' integrator" in notice
    # no thin-film plugin: the mono family keeps its colour
    variant, notice = tf_scene.scene_variant(polarizer, {}, "llvm_ad_mono")
    assert variant == "llvm_ad_mono_polarized" and "'polarizer' BSDF" in notice
    assert tf_scene.scene_variant(polarizer, {}, "llvm_ad_spectral_polarized") == \
        ("llvm_ad_spectral_polarized", None)
    assert tf_scene.scene_variant(plain, {}, "llvm_ad_rgb") == ("llvm_ad_rgb", None)
    # a scene that does not parse keeps the variant; loading it reports the error
    assert tf_scene.scene_variant(plain, {"nosuch": "1"}, "llvm_ad_spectral") == ("llvm_ad_spectral", None)


@pytest.mark.parametrize("variant, thin_films, expected", [
    ("llvm_ad_spectral", True, "llvm_ad_spectral_polarized"),
    ("llvm_ad_rgb", True, "llvm_ad_spectral_polarized"),
    ("scalar_mono", True, "scalar_spectral_polarized"),
    ("cuda_ad_rgb", False, "cuda_ad_rgb_polarized"),
    ("llvm_ad_mono_polarized", True, "llvm_ad_mono_polarized"),
])


def test_polarized_variant_of_a_family(variant, thin_films, expected):
    assert tf_scene.polarized_variant(variant, thin_films) == expected
    if not thin_films:  # not in the build: the spectral one of the same backend
        assert tf_scene.polarized_variant(variant, False, ["cuda_ad_spectral_polarized"]) == \
            "cuda_ad_spectral_polarized"


def test_files_resolved_next_to_the_scene(tmp_path, monkeypatch, capfd):
    # a mesh named relative to the scene file loads whatever the working directory
    (tmp_path / "scene" / "m").mkdir(parents=True)
    (tmp_path / "scene" / "m" / "quad.obj").write_text(
        "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3\nf 1 3 4\n")
    text = SCENE.replace('<shape type="sphere">',
                         '<shape type="obj"><string name="filename" value="m/quad.obj"/>')
    path = tmp_path / "scene" / "quad.xml"
    path.write_text(text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    rc = cli.render_main([str(path), "-o", str(tmp_path / "q.exr"), "--spp", "1", "--size", "8x6"])
    assert rc == 0, capfd.readouterr().err
    channels, _ = _read_exr(tmp_path / "q.exr")
    assert channels["R"].shape == (6, 8)


def test_plugin_value_error_is_one_line(tmp_path, capfd):
    # a thin-film BSDF refusing its parameters (a ValueError raised in Python)
    import thinfilm_mi

    if not hasattr(thinfilm_mi, "register"):
        pytest.skip("thin-film plugins not registered by this version")
    bad = tmp_path / "neg.xml"
    bad.write_text(SCENE.replace(
        '<bsdf type="conductor"><string name="material" value="Au"/></bsdf>',
        '<bsdf type="thinfilm_conductor"><string name="layers" value="1.46 -5"/></bsdf>'))
    rc = cli.render_main([str(bad), "-o", str(tmp_path / "neg.exr")])
    lines = error_lines(capfd.readouterr().err)
    assert rc == 2
    assert len(lines) == 1 and lines[0].startswith(PREFIX)
    assert "-5" in lines[0] and "Traceback" not in lines[0]


def test_unknown_plugin_error_subprocess(scene, tmp_path):
    bad = tmp_path / "bad.xml"
    bad.write_text(SCENE.replace('type="sphere"', 'type="no_such_shape"'))
    proc = subprocess.run([sys.executable, "-m", "thinfilm_mi", "render", str(bad)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    lines = error_lines(proc.stderr)
    assert proc.returncode == 2
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(PREFIX) and "no_such_shape" in lines[0]
    assert "Traceback" not in proc.stderr


def test_verbose_adds_traceback(tmp_path, capfd):
    rc = cli.render_main([str(tmp_path / "nope.xml"), "--verbose"])
    err = capfd.readouterr().err
    assert rc == 2
    assert "Traceback" in err
    assert error_lines(err)[-1].startswith(PREFIX)


def test_one_line_condenses_plugin_tracebacks():
    msg = ('[parser.cpp:1718] At s.xml (line 12, col 25): failed to instantiate bsdf plugin of '
           'type "x": Traceback (most recent call last):\n  File "p.py", line 7, in __init__\n'
           'ValueError: thickness: must be >= 0, got -3')
    assert tf_scene.one_line(msg) == ('At s.xml (line 12, col 25): failed to instantiate bsdf plugin '
                                 'of type "x": ValueError: thickness: must be >= 0, got -3')


def test_one_line_keeps_a_multi_line_exception_message():
    # the exception's whole message, not only its last line (issue 30: a YAML error's
    # last line was 'in "<unicode string>", line 3, column 9)', without the file)
    msg = ('At s.xml (line 3, col 25): failed to instantiate bsdf plugin of type "x": '
           'Traceback (most recent call last):\n  File "p.py", line 7, in __init__\n'
           '    self.films = films_from_props(props)\n             ^^^^^^^^^^^^^^^^\n'
           "MaterialError: material file 'f.yml': not valid\n  in line 2\nsecond line")
    assert tf_scene.one_line(msg) == ('At s.xml (line 3, col 25): failed to instantiate bsdf plugin of '
                                 "type \"x\": MaterialError: material file 'f.yml': not valid "
                                 "in line 2 second line")


def test_scene_with_a_malformed_material_file_names_it(tmp_path, capfd):
    (tmp_path / "film.yml").write_text("DATA:\n  - type: [tabulated nk\n    data: 1\n")
    bad = tmp_path / "yml.xml"
    bad.write_text(SCENE.replace(
        '<bsdf type="conductor"><string name="material" value="Au"/></bsdf>',
        f'<bsdf type="thinfilm_conductor"><string name="layers" value="{tmp_path / "film.yml"} 100"/></bsdf>'))
    rc = cli.render_main([str(bad), "-o", str(tmp_path / "yml.exr")])
    lines = error_lines(capfd.readouterr().err)
    assert rc == 2 and len(lines) == 1
    assert f"{tmp_path / 'film.yml'}" in lines[0] and "line 3, column 9" in lines[0], lines[0]


def test_console_script_declared():
    text = (REPO / "pyproject.toml").read_text()
    assert 'thinfilm-render = "thinfilm_mi.cli.render:render_main"' in text


def test_teapot_mesh_loads():
    # scenes/meshes/teapot.ply (scripts/make_teapot.py): y-up, height 1, on y = 0, with normals
    import mitsuba as mi

    path = REPO / "scenes" / "meshes" / "teapot.ply"
    if not path.is_file():
        pytest.skip("scenes/meshes/teapot.ply not built")
    previous = mi.variant()
    mi.set_variant("llvm_ad_rgb")
    try:
        mesh = mi.load_dict({"type": "ply", "filename": str(path)})
    finally:
        if previous is not None:
            mi.set_variant(previous)
    bbox = mesh.bbox()
    lo, hi = np.array(bbox.min), np.array(bbox.max)
    assert np.allclose([lo[1], hi[1]], [0.0, 1.0], atol=1e-5)
    assert np.allclose(lo[[0, 2]], -hi[[0, 2]], atol=1e-5)
    assert hi[0] > 1.5 * hi[2]  # spout and handle along x
    assert mesh.has_vertex_normals() and mesh.face_count() > 10_000
    assert path.stat().st_size < 1.5e6


import mitsuba as mi

mi.set_variant("llvm_ad_spectral")
from thinfilm_mi.batch.scene import root_cause  # noqa: E402


def test_render_with_a_huge_size_is_one_clear_line(capsys, tmp_path):
    scene = ROOT / "scenes" / "demo.xml"
    rc = cli.render_main([str(scene), "--size", "100000x100000", "--spp", "1",
                          "-o", str(tmp_path / "x.exr")])
    err = [l for l in capsys.readouterr().err.strip().splitlines() if "error" in l]
    assert rc == 2 and len(err) == 1
    assert "--size '100000x100000'" in err[0] and "at most" in err[0]


def test_render_failure_reports_the_root_cause():
    try:
        try:
            raise MemoryError("cannot allocate 40 GiB for the film")
        except MemoryError as inner:
            raise RuntimeError("error while performing a custom differentiable operation. "
                               "(see above).") from inner
    except RuntimeError as e:
        assert "40 GiB" in str(root_cause(e))
