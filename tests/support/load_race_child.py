"""The second upstream defect of :mod:`thinfilm_mi.render.gc_guard`, without thinfilm-mi:
a scene loaded on one thread while another thread renders can crash the render.

    python tests/support/load_race_child.py VARIANT SECONDS [guard]

One thread loads small scenes of C++ wrapper BSDFs (``blendbsdf`` over ``twosided``
``roughconductor`` and ``plastic``) and keeps every one (nothing is freed: no
collection, no reference count reaching zero), up to 1500; another renders a scene
of its own in a loop, each render tracing a symbolic call over every registered BSDF.
Mitsuba registers an instance in its base class's constructor, before it is built, so
a trace may call into a half-built wrapper. Measured with Mitsuba 3.9.1: SIGSEGV in
1 of 6 runs of 60 s on 2 cores. With ``guard`` the process imports ``thinfilm_mi``
first, which makes loads and renders take turns. On success it prints ``ok LOADS
RENDERS``.
"""
from __future__ import annotations

import sys
import threading
import time

import mitsuba as mi

MAX_LOADS = 1500


def scene(n_shapes: int) -> dict:
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
         "sensor": {"type": "perspective", "fov": 30,
                    "to_world": mi.ScalarTransform4f().look_at([0, 0, 5], [0, 0, 0], [0, 1, 0]),
                    "sampler": {"type": "independent", "sample_count": 1},
                    "film": {"type": "hdrfilm", "width": 8, "height": 8,
                             "rfilter": {"type": "box"}}},
         "emitter": {"type": "constant"}}
    for i in range(n_shapes):
        d[f"s{i}"] = {"type": "sphere", "center": [i * 0.01, 0, 0], "radius": 0.1,
                      "bsdf": {"type": "blendbsdf", "weight": 0.5,
                               "a": {"type": "twosided", "bsdf": {"type": "roughconductor"}},
                               "b": {"type": "plastic"}}}
    return d


def main(variant: str, seconds: float, guard: bool) -> None:
    if guard:
        import thinfilm_mi  # noqa: F401  (wraps mi.load_* and mi.render: they take turns)
    mi.set_variant(variant)
    stop = time.time() + seconds
    kept, renders = [], [0]

    def loader():
        while time.time() < stop and len(kept) < MAX_LOADS:
            kept.append(mi.load_dict(scene(3)))

    def renderer():
        own = mi.load_dict(scene(2))
        while time.time() < stop:
            mi.render(own, seed=renders[0])
            renders[0] += 1

    threads = [threading.Thread(target=loader), threading.Thread(target=renderer)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    print("ok", len(kept), renders[0])


if __name__ == "__main__":
    main(sys.argv[1], float(sys.argv[2]), len(sys.argv) > 3 and sys.argv[3] == "guard")
