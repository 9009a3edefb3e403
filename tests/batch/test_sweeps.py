"""Parameter sweeps on Dask (thinfilm_mi/batch/sweeps.py): frames named and grouped by
scene load, one GPU a worker, no Dask on import, arguments checked, outputs
and manifest, failures retried, killed workers, resumed sweeps, polarized grids."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")

import mitsuba as mi  # noqa: E402

from tests.support.sweep import SCENE, THICKNESS, TIMEOUT, read_manifest
from thinfilm_mi.batch import exr, grid, outputs, sweeps  # noqa: E402
from thinfilm_mi.batch import scene as tf_scene  # noqa: E402
from thinfilm_mi.errors import UsageError  # noqa: E402


def _run(scene, out, client, defines, parameters=None, **kw):
    return sweeps.sweep(scene, defines, parameters, out, client=client, timeout=TIMEOUT,
                        size=kw.pop("size", (16, 16)), spp=kw.pop("spp", 4), **kw)


def _parts(out: Path) -> list[Path]:
    return sorted(p for p in out.rglob("*") if outputs.PART_MARK in p.name)


def _mtimes(out: Path, rows) -> dict[str, int]:
    return {r["exr"]: (out / r["exr"]).stat().st_mtime_ns for r in rows}


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


def test_sweep_arguments_are_checked(scene, tmp_path):
    with pytest.raises(UsageError, match="scene file not found"):
        sweeps.sweep(tmp_path / "none.xml", {"thickness": "1,2"}, out_dir=tmp_path)
    with pytest.raises(UsageError, match="at most one"):
        sweeps.sweep(scene, {"thickness": "1,2"}, out_dir=tmp_path, workers=2, scheduler="tcp://x:1")
    with pytest.raises(UsageError, match="workers"):
        sweeps.sweep(scene, {"thickness": "1,2"}, out_dir=tmp_path, workers=0)
    with pytest.raises(UsageError, match="spp"):
        sweeps.sweep(scene, {"thickness": "1,2"}, out_dir=tmp_path, spp=0)


# --------------------------------------------------------------------------------------
# on a LocalCluster of 2 worker processes


def test_every_frame_has_outputs_and_a_manifest_row(scene, tmp_path, client, llvm):
    out = tmp_path / "grid"
    result = _run(scene, out, client, {"material": "Au,Ag"}, {THICKNESS: "150:450:150"})
    assert [r["status"] for r in result] == ["ok"] * 6, result.failed
    assert (result.rendered, result.skipped) == (6, 0)
    rows = read_manifest(out)
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
    rows = read_manifest(out)
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
    assert all((out / r["exr"]).is_file() and (out / r["png"]).is_file() for r in read_manifest(out))
    assert _parts(out) == []


def test_an_interrupted_sweep_resumes_with_the_missing_frames(scene, tmp_path, client):
    out = tmp_path / "interrupted"
    grid = {"thickness": "100,200,300", "material": "Au,Ag"}

    def interrupt(row):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        _run(scene, out, client, grid, on_frame=interrupt, size=(32, 32), spp=16)
    assert _parts(out) == []  # no partial file, even from frames that were still running
    done = read_manifest(out)
    assert 1 <= len(done) < 6 and all(r["status"] == "ok" for r in done)
    before = _mtimes(out, done)
    result = _run(scene, out, client, grid, size=(32, 32), spp=16)
    assert (result.rendered, result.skipped) == (6 - len(done), len(done))
    assert [r["status"] for r in result] == ["ok"] * 6
    assert _mtimes(out, done) == before
    assert [r["rendered"] for r in result].count(False) == len(done)


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
