"""``thinfilm-render sweep`` (thinfilm_mi/cli/sweep.py): usage errors, a sweep on a running
cluster, and -P keys as a user types them."""
from __future__ import annotations

import re

import numpy as np
import pytest

pytest.importorskip("distributed")


from tests.support import ROOT
from tests.support.sweep import SCENE, TIMEOUT, read_manifest
from thinfilm_mi.batch import exr  # noqa: E402
from thinfilm_mi.cli import render as cli  # noqa: E402


def test_cli_usage_errors(scene, capsys):
    assert cli.render_main(["sweep", str(scene)]) == 2
    assert "no grid" in capsys.readouterr().err
    assert cli.render_main(["sweep", str(scene), "-D", "thickness=1:2"]) == 2
    assert "START:STOP:STEP" in capsys.readouterr().err
    assert cli.render_main(["sweep", str(scene), "-D", "a=1", "--workers", "2",
                            "--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "not allowed with" in capsys.readouterr().err


def test_cli_sweep_on_a_running_cluster(scene, tmp_path, client, capfd):
    out = tmp_path / "cli"
    rc = cli.render_main(["sweep", str(scene), "-D", "thickness=100:300:100", "--spp", "2",
                          "--size", "16x16", "--scheduler", client.scheduler.address,
                          "--out-dir", str(out), "--timeout", str(TIMEOUT)])
    err = capfd.readouterr().err
    assert rc == 0, err
    assert "3 frames (3 rendered, 0 already done)" in err and "3 ok, 0 failed" in err
    assert [r["thickness"] for r in read_manifest(out)] == ["100", "200", "300"]
    # the same command again: everything is there, no cluster is needed
    rc = cli.render_main(["sweep", str(scene), "-D", "thickness=100:300:100", "--spp", "2",
                          "--size", "16x16", "--scheduler", "tcp://127.0.0.1:1", "--out-dir", str(out)])
    assert rc == 0 and "0 rendered, 3 already done" in capfd.readouterr().err
    # other settings (here the sample count): the frames on disk do not count
    rc = cli.render_main(["sweep", str(scene), "-D", "thickness=100:300:100", "--spp", "3",
                          "--size", "16x16", "--scheduler", client.scheduler.address,
                          "--out-dir", str(out), "--timeout", str(TIMEOUT)])
    assert rc == 0 and "3 rendered, 0 already done" in capfd.readouterr().err
    assert exr.read_exr(out / read_manifest(out)[0]["exr"])[1]["spp"] == 3


def test_cli_P_by_the_end_of_a_key_on_a_shipped_scene(tmp_path, client, capfd):
    """The issue's scene, whose teapot now has an id: -P by the end of its key, as a user types it."""
    out = tmp_path / "fig8a"
    rc = cli.render_main(["sweep", str(ROOT / "scenes" / "fig8a_si_sio2.xml"), "-P", "bsdf.layers.0.thickness=100,400",
                          "--spp", "1", "--size", "16x16", "--scheduler", client.scheduler.address,
                          "--out-dir", str(out), "--no-contact-sheet", "--timeout", str(TIMEOUT)])
    err = capfd.readouterr().err
    assert rc == 0, err
    assert err.count("-P bsdf.layers.0.thickness: taken as teapot.bsdf.layers.0.thickness, the only parameter "
                     "ending so\n") == 1, err
    rows = read_manifest(out)
    assert [r["bsdf.layers.0.thickness"] for r in rows] == ["100", "400"]
    thin, thick = (np.stack(list(exr.read_exr(out / r["exr"])[0].values())) for r in rows)
    assert not np.array_equal(thin, thick)   # the film's thickness was set


def test_cli_P_on_a_shape_without_an_id_says_so(tmp_path, client, capfd):
    """A shape without an id: the made-up key fails saying the shape has none and how to give it
    one; the end of its key is taken, naming the key chosen."""
    path = tmp_path / "no_id.xml"
    path.write_text(SCENE.replace(' id="sphere"', ""))
    common = ["--spp", "1", "--size", "16x16", "--scheduler", client.scheduler.address, "--no-contact-sheet",
              "--timeout", str(TIMEOUT)]
    rc = cli.render_main(["sweep", str(path), "-P", "shape_0.bsdf.layers.0.thickness=100,200",
                          "--out-dir", str(tmp_path / "a"), *common])
    err = capfd.readouterr().err
    assert rc == 1 and "0 ok, 2 failed" in err, err
    assert re.search(r"-P shape_0\.bsdf\.layers\.0\.thickness: not a parameter of the scene \(see mi\.traverse\): "
                     r"no object has the id 'shape_0'; did you mean bsdf\.layers\.0\.thickness\? \(object_\d+ is a "
                     r"Sphere without an id, named anew at every load: give it one in the scene's XML, "
                     r"<shape \.\.\. id=\"NAME\">, and name the parameter NAME\.bsdf\.layers\.0\.thickness\)", err), err
    rc = cli.render_main(["sweep", str(path), "-P", "bsdf.layers.0.thickness=100,200",
                          "--out-dir", str(tmp_path / "b"), *common])
    err = capfd.readouterr().err
    assert rc == 0, err
    assert re.search(r"-P bsdf\.layers\.0\.thickness: taken as object_\d+\.bsdf\.layers\.0\.thickness, the only "
                     r"parameter ending so \(object_\d+ is a Sphere without an id", err), err
