"""Table refinement (thinfilm_mi/tabulate/refine.py): a poor first estimate is refined to
the target."""
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from tests.support.kernels import interaction
from tests.support.tables import F32, STACK, random_points, ref_R
from thinfilm_mi.render import media as media_mod
from thinfilm_mi.render import stack_build

pytestmark = pytest.mark.usefixtures("llvm")


def test_a_poor_first_estimate_is_refined_to_the_target(monkeypatch):
    """Whatever the probe says, only a verified table is kept: from a 16 x 16 first
    table the refinement reaches the target, and the lookup meets the float64
    reference within the verified error (tolerance as in the first test)."""
    from thinfilm_mi.tabulate import exact as tables
    monkeypatch.setattr(tables, "_estimate", lambda *a, **k: (16, 16))
    stack_build.TABLE_CACHE.clear()
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "layers": STACK, "material": "Cu",
                         "tabulate": True})
    stack_build.TABLE_CACHE.clear()
    table = bsdf.stack.plan[False].table
    assert table is not None and table.error <= 1e-3
    assert bsdf.stack.plan[False].build_report["rounds"] > 1
    cos, wls = random_points(20000, seed=7)
    R = np.array(bsdf.stack.reflectance(interaction(wls), mi.Float(cos.astype(np.float32))))
    ref = tf.Stack(STACK, substrate="Cu", ambient=media_mod.DEFAULT_EXT_IOR)
    err = max(np.max(np.abs(R[i] - ref_R(ref, cos, wls[i]))) for i in range(4))
    assert err <= 1.5 * table.error + F32, err
