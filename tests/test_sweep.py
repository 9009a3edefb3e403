"""Parameter sweeps on Dask (thinfilm_mi.batch.sweeps, ``thinfilm-render sweep``).

The cluster tests share one LocalCluster of 2 worker processes on 127.0.0.1
(the embedded default, built by ``sweeps.local_cluster``) and render 3x2 grids
of a 16x16 (or 32x32) sphere coated with SiO2 on Au/Ag. Every wait is bounded
(``timeout=`` on sweeps and on ``wait_for_workers``); nothing synchronises by
sleeping: the worker kill and the interruption are triggered from the sweep's
own ``on_frame`` callback, i.e. when the first frame has finished and the
others are still queued or running.
"""
from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

OpenEXR = pytest.importorskip("OpenEXR")
pytest.importorskip("distributed")

import mitsuba as mi  # noqa: E402

from thinfilm_mi.batch import exr, grid, outputs, sweeps, worker  # noqa: E402
from thinfilm_mi.batch import scene as tf_scene  # noqa: E402
from thinfilm_mi.cli import render as cli  # noqa: E402
from thinfilm_mi.errors import UsageError  # noqa: E402

TIMEOUT = 120  # seconds: bound of every sweep (they take a few seconds)
THICKNESS = "sphere.bsdf.layers.0.thickness"

SCENE = """<scene version="3.0.0">
  <default name="thickness" value="300"/>
  <default name="material" value="Au"/>
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film>
  </sensor>
  <shape type="sphere" id="sphere">
    <bsdf type="thinfilm_conductor">
      <string name="material" value="$material"/>
      <string name="layers" value="SiO2 $thickness"/>
    </bsdf>
  </shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>
"""


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("sweep_scene") / "coated_sphere.xml"
    path.write_text(SCENE)
    return path


@pytest.fixture(scope="module")
def cluster():
    cluster = sweeps.local_cluster(2)
    yield cluster
    cluster.close(timeout=60)


@pytest.fixture
def client(cluster):
    from distributed import Client

    with Client(cluster, timeout="60s") as client:
        # a worker killed by an earlier test is restarted by its nanny: wait for it
        client.wait_for_workers(2, timeout=60)
        yield client


def _run(scene, out, client, defines, parameters=None, **kw):
    return sweeps.sweep(scene, defines, parameters, out, client=client, timeout=TIMEOUT,
                        size=kw.pop("size", (16, 16)), spp=kw.pop("spp", 4), **kw)


def _manifest(out: Path) -> list[dict[str, str]]:
    with open(out / outputs.MANIFEST, newline="") as f:
        return list(csv.DictReader(f))


def _parts(out: Path) -> list[Path]:
    return sorted(p for p in out.rglob("*") if outputs.PART_MARK in p.name)


def _mtimes(out: Path, rows) -> dict[str, int]:
    return {r["exr"]: (out / r["exr"]).stat().st_mtime_ns for r in rows}


# --------------------------------------------------------------------------------------
# the grid, without a cluster


def test_values_ranges_lists_and_errors():
    assert grid.parse_values("100:800:25") == tuple(str(v) for v in range(100, 801, 25))
    assert grid.parse_values("100:180:25") == ("100", "125", "150", "175")  # STOP off the grid
    assert grid.parse_values("0.1:0.5:0.1") == ("0.1", "0.2", "0.3", "0.4", "0.5")  # no float noise
    assert grid.parse_values("3:1:-1") == ("3", "2", "1")
    assert grid.parse_values(" Au, Ag ,Cu") == ("Au", "Ag", "Cu")
    assert grid.parse_values("SiO2 500; Au 20") == ("SiO2 500; Au 20",)
    assert grid.parse_values(range(0, 30, 10)) == ("0", "10", "20")
    assert grid.parse_values(np.array([0.5, 1.0])) == ("0.5", "1")
    assert grid.parse_values(2.5) == ("2.5",)
    for bad, word in [("100:800", "START:STOP:STEP"), ("1:5:0", "STEP"), ("5:1:1", "STEP"),
                      ("1,,2", "empty"), ("", "no value"), ("1,2,1", "repeated"),
                      ("0:1e9:1", "more than"), ([], "no value"), (object(), "expected")]:
        with pytest.raises(UsageError, match=word):
            grid.parse_values(bad, "-D x=")


def test_axes_names_and_values_are_checked():
    with pytest.raises(UsageError, match="not a valid parameter name"):
        grid.parse_axes(["2x=1"], "define")
    with pytest.raises(UsageError, match="expected name=VALUES"):
        grid.parse_axes(["thickness"], "define")
    with pytest.raises(UsageError, match="given twice"):
        grid.parse_axes(["a=1", "a=2"], "define")
    with pytest.raises(UsageError, match="must be numbers"):
        grid.parse_axes({THICKNESS: "thick"}, "traverse")
    with pytest.raises(UsageError, match="clash"):
        grid.build_frames(grid.parse_axes(["status=1,2"], "define"))



def test_axis_kinds_registry():
    """-D and -P axes are the AxisKind objects of grid.AXIS_KINDS; parse_axes takes the
    object or its name, and the frames sort the axes' values by it."""
    assert list(grid.AXIS_KINDS) == ["define", "traverse"]
    assert [k.flag for k in grid.AXIS_KINDS.values()] == ["-D", "-P"]
    assert grid.parse_axes(["a=1,2"], grid.DEFINE) == grid.parse_axes(["a=1,2"], "define")
    assert grid.parse_axes([f"{THICKNESS}=1"], "traverse")[0].kind is grid.TRAVERSE
    with pytest.raises(UsageError, match=r"-P 'x': expected name=VALUES, e.g. -P sphere\.bsdf"):
        grid.parse_axes(["x"], grid.TRAVERSE)
    with pytest.raises(ValueError, match="kind: expected one of define, traverse, got 'other'"):
        grid.parse_axes(["a=1"], "other")
    frame = grid.build_frames(grid.parse_axes(["a=1"], grid.DEFINE) + grid.parse_axes(["b.c=2"], grid.TRAVERSE))[0]
    assert (frame.defines, frame.traverse) == ((("a", "1"),), (("b.c", "2"),))


def test_frames_are_named_and_grouped_by_scene_load():
    axes = (grid.parse_axes({"material": "Au,Ag", "spp": 4}, "define")
            + grid.parse_axes({THICKNESS: "100:300:100"}, "traverse"))
    frames = grid.build_frames(axes)
    assert [f.index for f in frames] == list(range(6))
    assert frames[1].params == {"material": "Au", "spp": "4", THICKNESS: "200"}
    # named after the axes that vary; -P keys by their last three parts
    assert frames[1].exr == "frames/material=Au_layers.0.thickness=200.exr"
    assert len({f.exr for f in frames}) == 6
    for per_task, sizes in [(None, [2, 1, 2, 1]), (3, [3, 3]), (1, [1] * 6)]:
        tasks = grid.plan_tasks(frames, 2, per_task)
        assert [len(t) for t in tasks] == sizes
        assert all(len({f.defines for f in t}) == 1 for t in tasks)  # one scene load per task
        assert [f.index for t in tasks for f in t] == list(range(6))
    # values that differ only in characters a file name cannot hold
    odd = grid.build_frames(grid.parse_axes({"name": ["a b", "a/b"]}, "define"))
    assert odd[0].exr != odd[1].exr and odd[0].exr.startswith("frames/frame-")


def test_gpu_workers_get_one_device_each():
    assert sweeps.visible_gpus({"CUDA_VISIBLE_DEVICES": "2,3"}) == ["2", "3"]
    assert sweeps.visible_gpus({"CUDA_VISIBLE_DEVICES": "1,-1,0"}) == ["1"]  # -1 hides the rest
    assert sweeps.visible_gpus({"CUDA_VISIBLE_DEVICES": ""}) == []
    listing = "GPU 0: NVIDIA H100 (UUID: GPU-a)\nGPU 1: NVIDIA H100 (UUID: GPU-b)\n"
    assert sweeps.visible_gpus({}, lambda: listing) == ["0", "1"]

    def no_driver():
        raise FileNotFoundError("nvidia-smi")

    assert sweeps.visible_gpus({}, no_driver) == []
    assert sweeps.gpu_worker_envs(["2", "3"]) == [{"CUDA_VISIBLE_DEVICES": "2"},
                                                  {"CUDA_VISIBLE_DEVICES": "3"}]
    assert [e["CUDA_VISIBLE_DEVICES"] for e in sweeps.gpu_worker_envs(["0", "1"], 3)] == ["0", "1", "0"]
    with pytest.raises(UsageError, match="GPU"):
        sweeps.gpu_worker_envs([])


def test_importing_the_package_does_not_import_dask():
    code = ("import sys, thinfilm_mi; assert 'distributed' not in sys.modules "
            "and 'dask' not in sys.modules; from thinfilm_mi import sweep; "
            "assert callable(sweep) and 'distributed' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_traverse_values_are_checked_on_the_scene(scene):
    mi.set_variant(tf_scene.DEFAULT_VARIANT)
    loaded = tf_scene.load_scene(scene)
    with pytest.raises(UsageError, match="did you mean sphere.bsdf.layers.0.thickness"):
        worker.set_parameters(loaded, None, [("sphere.bsdf.layers.0.thicknes", "3")])
    with pytest.raises(UsageError, match="single numbers"):
        worker.set_parameters(loaded, None, [("sphere.bsdf.layers.0.eta.values", "1.5")])


def test_sweep_arguments_are_checked(scene, tmp_path):
    with pytest.raises(UsageError, match="scene file not found"):
        sweeps.sweep(tmp_path / "none.xml", {"thickness": "1,2"}, out_dir=tmp_path)
    with pytest.raises(UsageError, match="at most one"):
        sweeps.sweep(scene, {"thickness": "1,2"}, out_dir=tmp_path, workers=2, scheduler="tcp://x:1")
    with pytest.raises(UsageError, match="workers"):
        sweeps.sweep(scene, {"thickness": "1,2"}, out_dir=tmp_path, workers=0)
    with pytest.raises(UsageError, match="spp"):
        sweeps.sweep(scene, {"thickness": "1,2"}, out_dir=tmp_path, spp=0)


def test_cli_usage_errors(scene, capsys):
    assert cli.render_main(["sweep", str(scene)]) == 2
    assert "no grid" in capsys.readouterr().err
    assert cli.render_main(["sweep", str(scene), "-D", "thickness=1:2"]) == 2
    assert "START:STOP:STEP" in capsys.readouterr().err
    assert cli.render_main(["sweep", str(scene), "-D", "a=1", "--workers", "2",
                            "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "not allowed with" in capsys.readouterr().err


# --------------------------------------------------------------------------------------
# on a LocalCluster of 2 worker processes


def test_every_frame_has_outputs_and_a_manifest_row(scene, tmp_path, client):
    out = tmp_path / "grid"
    result = _run(scene, out, client, {"material": "Au,Ag"}, {THICKNESS: "150:450:150"})
    assert [r["status"] for r in result] == ["ok"] * 6, result.failed
    assert (result.rendered, result.skipped) == (6, 0)
    rows = _manifest(out)
    assert list(rows[0]) == ["material", THICKNESS, "exr", "png", "seconds", "status", "error"]
    expected = [(m, t) for m in ("Au", "Ag") for t in ("150", "300", "450")]
    assert [(r["material"], r[THICKNESS]) for r in rows] == expected
    means = {}
    for row in rows:
        assert row["status"] == "ok" and row["error"] == "" and float(row["seconds"]) > 0
        channels, header = exr.read_exr(out / row["exr"])
        assert channels["R"].shape == (16, 16)
        assert header["parameters"] == f"material={row['material']} {THICKNESS}={row[THICKNESS]}"
        assert tuple(mi.Bitmap(str(out / row["png"])).size()) == (16, 16)
        means[row["material"], row[THICKNESS]] = np.mean([channels[c] for c in "RGB"], axis=(1, 2))
    assert len({tuple(np.round(v, 6)) for v in means.values()}) == 6  # six different images
    assert mi.Bitmap(str(result.contact_sheet)).size()[0] > 3 * 16
    assert _parts(out) == []
    # frames that reused their task's scene (-P edits only) compiled no kernel
    reused = [r for r in result if not r["scene_loaded"]]
    assert len(reused) >= 2 and all(r["kernels"] == 0 for r in reused), result.rows
    assert sum(r["scene_loaded"] for r in result) <= 4  # at most one load per task
    # a -P frame is the frame thinfilm-render makes with the value in the XML
    # (same seed and sample count: the same samples; float32 sums in another order)
    direct = tf_scene.render_file(scene, tmp_path / "direct.exr", params={"material": "Ag",
                             "thickness": "450"}, spp=4, size=(16, 16))
    swept, _ = exr.read_exr(out / rows[5]["exr"])
    np.testing.assert_allclose(np.dstack([swept[c] for c in direct.channels]), direct.image,
                               rtol=1e-5, atol=1e-6)


def test_a_failed_frame_is_recorded_and_retried_on_rerun(scene, tmp_path, client):
    out = tmp_path / "failing"
    result = _run(scene, out, client, {"material": "Au,Ag"}, {THICKNESS: "150,-5,300"})
    bad = [r for r in result if r[THICKNESS] == "-5"]
    assert len(result.ok) == 4 and result.failed == bad
    for row in bad:
        assert "thickness" in row["error"] and "-5" in row["error"] and row["exr"] == ""
    rows = _manifest(out)
    assert [r["status"] for r in rows] == ["ok", "failed", "ok"] * 2
    assert not list((out / "frames").glob("*thickness=-5*"))
    before = _mtimes(out, result.ok)
    again = _run(scene, out, client, {"material": "Au,Ag"}, {THICKNESS: "150,-5,300"})
    assert (again.rendered, again.skipped, len(again.failed)) == (2, 4, 2)
    assert _mtimes(out, again.ok) == before  # the finished frames were not rendered again


def test_a_killed_worker_does_not_stop_the_sweep(scene, tmp_path, client):
    out = tmp_path / "killed"
    killed = []

    def kill_a_busy_worker(row):
        if killed:
            return
        busy = {w: keys for w, keys in client.processing().items() if keys}
        assert busy, "no frame left to interrupt"  # 5 frames of >= one scene load each remain
        worker = max(busy, key=lambda w: len(busy[w]))
        pid = client.run(os.getpid, workers=[worker])[worker]
        os.kill(pid, signal.SIGKILL)
        killed.append((pid, len(busy[worker])))

    result = _run(scene, out, client, {"thickness": "100,200,300", "material": "Au,Ag"},
                  on_frame=kill_a_busy_worker, size=(32, 32), spp=16)
    assert killed and killed[0][1] >= 1
    assert [r["status"] for r in result] == ["ok"] * 6, result.failed
    assert all((out / r["exr"]).is_file() and (out / r["png"]).is_file() for r in _manifest(out))
    assert _parts(out) == []


def test_an_interrupted_sweep_resumes_with_the_missing_frames(scene, tmp_path, client):
    out = tmp_path / "interrupted"
    grid = {"thickness": "100,200,300", "material": "Au,Ag"}

    def interrupt(row):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _run(scene, out, client, grid, on_frame=interrupt, size=(32, 32), spp=16)
    assert _parts(out) == []  # no partial file, even from frames that were still running
    done = _manifest(out)
    assert 1 <= len(done) < 6 and all(r["status"] == "ok" for r in done)
    before = _mtimes(out, done)
    result = _run(scene, out, client, grid, size=(32, 32), spp=16)
    assert (result.rendered, result.skipped) == (6 - len(done), len(done))
    assert [r["status"] for r in result] == ["ok"] * 6
    assert _mtimes(out, done) == before
    assert [r["rendered"] for r in result].count(False) == len(done)


def test_cli_sweep_on_a_running_cluster(scene, tmp_path, client, capfd):
    out = tmp_path / "cli"
    rc = cli.render_main(["sweep", str(scene), "-D", "thickness=100:300:100", "--spp", "2",
                          "--size", "16x16", "--scheduler", client.scheduler.address,
                          "--out-dir", str(out), "--timeout", str(TIMEOUT)])
    err = capfd.readouterr().err
    assert rc == 0, err
    assert "3 frames (3 rendered, 0 already done)" in err and "3 ok, 0 failed" in err
    assert [r["thickness"] for r in _manifest(out)] == ["100", "200", "300"]
    # the same command again: everything is there, no cluster is needed
    rc = cli.render_main(["sweep", str(scene), "-D", "thickness=100:300:100", "--spp", "2",
                          "--size", "16x16", "--scheduler", "tcp://127.0.0.1:1", "--out-dir", str(out)])
    assert rc == 0 and "0 rendered, 3 already done" in capfd.readouterr().err
    # other settings (here the sample count): the frames on disk do not count
    rc = cli.render_main(["sweep", str(scene), "-D", "thickness=100:300:100", "--spp", "3",
                          "--size", "16x16", "--scheduler", client.scheduler.address,
                          "--out-dir", str(out), "--timeout", str(TIMEOUT)])
    assert rc == 0 and "3 rendered, 0 already done" in capfd.readouterr().err
    assert exr.read_exr(out / _manifest(out)[0]["exr"])[1]["spp"] == 3


def test_grid_that_needs_a_polarized_variant_gets_one(tmp_path):
    # issue 30: as thinfilm-render, for any -D combination of the grid (a worker
    # process holds one variant, and a polarized variant renders the others too)
    path = tmp_path / "pol.xml"
    path.write_text(SCENE.replace('<integrator type="path">', '<integrator type="$integ">')
                    .replace('<default name="material"', '<default name="integ" value="path"/>'
                             '<default name="material"'))
    frames = grid.build_frames(grid.parse_axes({"integ": "path,stokes"}, "define"))
    variant, notice = sweeps.grid_variant(path, frames, "llvm_ad_spectral")
    assert variant == "llvm_ad_spectral_polarized" and "'stokes' integrator" in notice
    plain = grid.build_frames(grid.parse_axes({"integ": "path"}, "define"))
    assert sweeps.grid_variant(path, plain, "llvm_ad_spectral") == ("llvm_ad_spectral", None)
