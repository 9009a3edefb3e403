"""``thinfilm-render sweep`` (thinfilm_mi/cli/sweep.py): usage errors, and a sweep on a
running cluster."""
from __future__ import annotations

import pytest

pytest.importorskip("distributed")


from tests.support.sweep import TIMEOUT, read_manifest
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
