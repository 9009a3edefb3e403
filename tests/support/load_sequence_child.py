"""Child of ``tests/cross/test_parallel_load.py``: shipped scenes loaded in parallel on two
threads, each followed by a one-thread render, as ``benchmarks/scene_hashes.py`` does;
prints ``ok``.

    python load_sequence_child.py ROOT
"""
import sys

import drjit as dr
import mitsuba as mi

sys.path.insert(0, sys.argv[1])
mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from thinfilm_mi.batch.scene import load_scene  # noqa: E402

# the order a hang needed: a plugin constructor updating a spectrum through
# mi.traverse waited on the pool running the loader, at the second rough_films.xml
for name in ("demo.xml", "rough_films.xml", "fig9d_clay_oxide.xml", "rough_films.xml"):
    dr.set_thread_count(2)
    scene = load_scene(f"{sys.argv[1]}/scenes/{name}", size=(48, 32), spp=1)
    dr.set_thread_count(1)
    mi.render(scene, seed=0)
print("ok", flush=True)
