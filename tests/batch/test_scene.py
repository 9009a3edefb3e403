"""Scenes as files (thinfilm_mi/batch/scene.py): render passes and their seeds, and the
parsers of ``-D`` defines and ``--size``."""
from __future__ import annotations

import pytest

from thinfilm_mi.batch import scene as tf_scene
from thinfilm_mi.errors import UsageError


@pytest.mark.parametrize("spp,pixels,cap", [(1, 100, 1 << 22), (7, 100, 1 << 22),
                                            (1000, 1000, 10_000), (64, 1 << 22, 1 << 22)])


def test_plan_passes(spp, pixels, cap):
    plan = tf_scene.plan_passes(spp, pixels, cap)
    assert sum(plan) == spp
    assert max(plan) - min(plan) <= 1
    assert len(plan) >= min(spp, tf_scene.MIN_PASSES)
    assert max(plan) * pixels <= max(cap, pixels)
    seeds = {tf_scene.pass_seed(0, i) for i in range(len(plan))} | {tf_scene.pass_seed(1, i) for i in range(len(plan))}
    assert len(seeds) == 2 * len(plan)


def test_parse_helpers():
    assert tf_scene.parse_defines(["a=1", "b_2= x=y"]) == {"a": "1", "b_2": " x=y"}
    assert tf_scene.parse_size("640x480") == (640, 480)
    for bad in ("640", "0x4", "axb"):
        with pytest.raises(UsageError):
            tf_scene.parse_size(bad)
    with pytest.raises(UsageError):
        tf_scene.parse_defines(["1a=3"])
