"""Load time and steady render cost of ``thinfilm_diffuse``'s ``thickness`` texture.

    .venv/bin/python benchmarks/diffuse_texture_bench.py [variant ...]

Per variant: a sphere under ``SiO2 500; Au 4`` (model "exact") with no texture, a
constant scale 1.2 and the soap-film bitmap (``scenes/textures/soap_film.exr``, scale
0-1.47; RGB/mono variants build a table over (θ_i, θ_o, s), ``tabulate/diffuse.py``).
Load: ``mi.load_dict`` wall time (the tables over the scale are built there). Render: 96x96 at 16 spp, the best of 3
after a warm-up render, relative to the same scene without a texture. Each scene is freed (``gc.collect``) before the
next loads: a live Python BSDF is traced into every render of its variant (``benchmarks/timing.py``).

The counterpart here is the plugin without a texture: Mitsuba has no film-thickness texture, and what the untextured
plugin costs against Mitsuba's ``diffuse`` is measured by ``plugin_bench.py`` and ``render_bench.py``.
"""
from __future__ import annotations

import gc
import sys
import time

import mitsuba as mi

VARIANTS = [a for a in sys.argv[1:] if a != "--write-docs"] or [
    "llvm_ad_spectral", "llvm_ad_spectral_polarized", "llvm_ad_rgb", "llvm_ad_mono"]


def scene(thickness):
    bsdf = {"type": "thinfilm_diffuse", "model": "exact", "layers": "SiO2 500; Au 4",
            "reflectance": 0.7}
    if thickness is not None:
        bsdf["thickness"] = thickness
    return {"type": "scene", "integrator": {"type": "path", "max_depth": 4},
            "sensor": {"type": "perspective", "fov": 40,
                       "to_world": mi.ScalarTransform4f().look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": 96, "height": 96}},
            "env": {"type": "constant"}, "sphere": {"type": "sphere", "bsdf": bsdf}}


def main():
    for variant in VARIANTS:
        mi.set_variant(variant)
        import thinfilm_mi  # noqa: F401
        cases = [("none", None), ("constant 1.2", 1.2),
                 ("soap-film bitmap", {"type": "bitmap", "raw": True,
                                       "filename": "scenes/textures/soap_film.exr"})]
        base = None
        for name, tex in cases:
            t0 = time.perf_counter()
            s = mi.load_dict(scene(tex))
            load = time.perf_counter() - t0
            mi.render(s, spp=16)
            best = float("inf")
            for seed in range(3):
                t0 = time.perf_counter()
                mi.render(s, spp=16, seed=seed).numpy()
                best = min(best, time.perf_counter() - t0)
            base = base or best
            print(f"{variant:28s} {name:17s} load {load:6.2f} s   render {best:6.3f} s "
                  f"({best / base:4.2f}x)", flush=True)
            del s
            gc.collect()


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("diffuse_texture_bench"):   # --write-docs: docs/_generated/diffuse_texture_bench.md
        main()
