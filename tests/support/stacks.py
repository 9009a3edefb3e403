"""The benchmark stacks and the small scene the table tests share.

The stacks are those of ``benchmarks/render_bench.py``: films alternating n = 2.3 and
1.46, thicknesses 50-200 nm from ``numpy.random.default_rng(6)`` (the first ``films``
of them: a deeper stack extends a shallower one).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np


def benchmark_thicknesses(films: int) -> np.ndarray:
    """The thicknesses (nm) of the first ``films`` films."""
    return np.random.default_rng(6).uniform(50.0, 200.0, films)


def benchmark_layers(films: int) -> str:
    """The ``layers`` string of the benchmark stack of ``films`` films."""
    d = benchmark_thicknesses(films)
    return "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(films))


def sphere_scene(bsdf: dict) -> dict:
    """A unit sphere named ``ball`` with ``bsdf`` under a constant emitter, 24x24, 1 spp,
    box filter: renders with the same seed compare bit for bit."""
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": 1},
                   "film": {"type": "hdrfilm", "width": 24, "height": 24, "rfilter": {"type": "box"}}},
        "emitter": {"type": "constant"},
        "ball": {"type": "sphere", "bsdf": bsdf},
    }
