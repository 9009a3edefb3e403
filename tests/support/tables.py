"""The stack, points and float64 reference that the table tests share."""
from __future__ import annotations

import numpy as np

import thinfilm_mi as tf

# A float32 kernel value against float64: rounding below 3e-5 for these stacks
# (tests/plugins/test_thinfilm_conductor.py). A table lookup adds its interpolation error,
# which the build verified to be below ``table.error`` at the midpoints of its
# cells; the cubic spline's error peaks near those midpoints, so a point
# anywhere may exceed it only marginally: we allow 1.5x plus the float32 term.
F32 = 3e-5



def f32(x):
    """Values the float32 kernel sees exactly, for the float64 reference too: near a
    critical angle R has a square-root kink, where rounding cos to float32 alone
    moves R by ~1e-3."""
    return np.asarray(x, np.float32).astype(np.float64)


def random_points(n, seed=1):
    """Directions outside the grazing sliver the table's verification leaves out
    (tabulate_base.GRAZING_COS; benchmarks/speed_vs_error.py reports the error there)."""
    rng = np.random.default_rng(seed)
    cos = f32(rng.uniform(tf.tabulate.exact.GRAZING_COS, 1.0, n))
    wls = [f32(rng.uniform(360.0, 830.0, n)) for _ in range(4)]
    return cos, wls


def ref_R(stack, cos, wl, T=False):
    r = stack.rt(wl, np.arccos(np.clip(cos, 0, 1)))
    return r.T if T else r.R


STACK = "1.46 420; 2.3 95; 1.38 130"
