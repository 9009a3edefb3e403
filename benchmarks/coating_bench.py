"""``thinfilm_coating`` (issue 42): its render cost over the nested BSDF alone, its image
noise at equal time against the explicit-geometry reference, its first image, and film
edits without recompilation.

    python benchmarks/coating_bench.py [--repeats 5] [--res 256] [--spp 16]
                                       [--variants llvm_ad_spectral,llvm_ad_rgb]
                                       [--noise-res 128] [--noise-spp 16] [--ref-factor 16]
                                       [--noise-variants llvm_ad_spectral,llvm_ad_rgb]
                                       [--first-repeats 3] [--edits 4]
                                       [--skip-steady] [--skip-noise] [--skip-first]
                                       [--write-docs]

The scene is the sphere of ``timing.py`` (radius 1 on a diffuse floor under a
constant emitter, ``path``, box filter). The sphere's BSDF is one of :data:`BASES`
(``diffuse``, ``roughconductor`` α 0.3 on Al, ``principled``), alone or under the coating
:data:`COAT` (``int_ior`` 1.5, the films ``"SiO2 500; TiO2 80"``, default settings) with
each top of :data:`TOPS` (the smooth one, and a rough one of α 0.2: the films on Beckmann
microfacets): a row per top and base. The
coating's Mitsuba counterpart is its base alone (Mitsuba has no coating of films), which
is what part 1 times; against ``plastic`` (no films over ``diffuse``), in the polarized
variant and at other depths: ``plugin_bench.py`` and ``render_bench.py``. This bench adds
what only the coating has: its noise against the geometry it stands for, and its edits.

1. **Steady cost** per base and variant (each variant in a process of its own), timed by
   ``timing.pair_rounds``: an untimed round (compiles), then --repeats rounds in which the
   base alone and the coated base render back to back (the base first in even rounds, the
   coating first in odd ones), --res², --spp, max depth 8. The coated scene is loaded for
   its render, rendered once untimed and freed after it (the kernel cache and the process's
   table store make the reload cheap): while a Python BSDF lives, Dr.Jit traces its code
   into every render, the base's too, which would bill part of the coating's cost to the
   base (at 48×48 the base's renders took 5× longer with a coated scene alive). The ratio
   is the median over rounds of the round's ratio of the process's CPU time (all of
   Dr.Jit's threads; a slow spell of the shared machine hits both renders of a pair
   alike); wall-clock seconds are in the JSON on stderr.
2. **Edits**, in the same processes: with ``dr.JitFlag.KernelHistory`` on, --edits edits of
   the outer film's thickness through ``mi.traverse(scene)`` and ``params.update()`` (which
   rebuilds a table where the stack has one), each followed by a render; the JIT kernels
   compiled (neither an in-memory nor a disk-cache hit) in the updates and in the renders.
3. **Noise at equal time** (each of --noise-variants, --noise-res², max depth 64 in both
   scenes, lit by the sky and by the area light of ``scenes/include/stage.xml``, which the
   geometry reaches only by chance: next-event estimation cannot cross its smooth top):
   the coated sphere against the coating as geometry, as in
   ``tests/cross/test_coating_geometry.py``: a ``thinfilm_dielectric`` sphere (the films,
   ``ext_ior`` -> ``int_ior``; a ``thinfilm_roughdielectric`` of the same α under a rough
   top) around a sphere :data:`GAP` smaller that carries the base
   (max depth 64 leaves the walk between the two its bounces). The coating renders
   --noise-spp samples in T seconds (median of 3); the geometry gets the spp that fill the
   same T by its own median time per render (CPU seconds, after a render at that sample
   count: the count is compiled into the kernel). Each image's RMSE, over the sphere's
   pixels and relative to their mean, is taken against a render of the same scene at
   --ref-factor times its samples (whose own noise adds 1/ref-factor to the variance);
   three images each, the median time and the root mean square of the three RMSEs.
   Efficiency ratio: ``(RMSE_geometry² t_geometry) / (RMSE_coating² t_coating)`` with the
   measured times; above 1 the coating is the more efficient. The two high-spp images'
   relative RMSE to each other is reported too, beside what their own noise alone puts
   between them (estimated from the three images, so fireflies make it an underestimate),
   and the relative difference of their mean radiance over the sphere (robust to fireflies):
   an excess is the gap's offset, and in RGB the plugin's product of channel integrals
   against the geometry's per-channel crossings. In spectral variants four
   wavelengths per path make most of the RMSE (colour noise) on both sides.
4. **First image** (``llvm_ad_spectral``, --res², --spp): a fresh process, the kernel cache
   warm (one untimed run of each first) and the table store off (every table is built),
   times ``mi.load_dict`` (which builds the stack's table) and the first ``mi.render``;
   --first-repeats runs per configuration, alternating, medians.

``--write-docs`` writes the tables to ``docs/_generated/coating_bench.md`` under the line
that says where, when and at which commit they were measured (``benchmarks/docs_output.py``);
docs/benchmarks.md shows it.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import time
import warnings

import numpy as np

os.environ.setdefault("THINFILM_MI_TABLE_CACHE", "off")

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from timing import child, own_table_store, pair_rounds, render_sync, sphere_scene  # noqa: E402

VARIANTS = ("llvm_ad_spectral", "llvm_ad_rgb")
#: the coating of every measurement: a TiO2 film under SiO2 on a clear 1.5 coat
COAT = {"layers": "SiO2 500; TiO2 80", "int_ior": 1.5}
#: (label, the nested BSDF)
BASES = [
    ("`diffuse`", {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.25, 0.1]}}),
    ("`roughconductor` Al, α 0.3", {"type": "roughconductor", "material": "Al", "alpha": 0.3}),
    ("`principled`", {"type": "principled", "roughness": 0.4,
                      "base_color": {"type": "rgb", "value": [0.6, 0.05, 0.05]}}),
]
#: (label, the coating's properties that make its top, the interface plugin of the explicit
#: geometry's outer sphere): every table has a row per top and base (:func:`cases`)
TOPS = [
    ("smooth", {}, {"type": "thinfilm_dielectric"}),
    ("rough α 0.2", {"alpha": 0.2}, {"type": "thinfilm_roughdielectric", "alpha": 0.2}),
]
#: the sphere's radius less the base sphere's in the explicit geometry (the sphere's is 1)
GAP = 0.01
CENTER = (0.0, 0.2, 0.0)
NOISE_DEPTH = 64


def cases() -> list:
    """``(label, base, top)`` of every row: each top of :data:`TOPS` over each base of
    :data:`BASES` (the label names the top where it is not smooth)."""
    return [(label if name == "smooth" else f"{label}, {name} top", base, (own, geometry))
            for name, own, geometry in TOPS for label, base in BASES]


SMOOTH = TOPS[0][1:]


def coated(base: dict, top: tuple = SMOOTH) -> dict:
    """``thinfilm_coating`` of :data:`COAT` with the top ``top`` (a :data:`TOPS` entry's
    properties) over ``base``."""
    return {"type": "thinfilm_coating", **COAT, **top[0], "bsdf": base}


def lit_scene(bsdf: dict, res: int, spp: int) -> dict:
    """The sphere scene at max depth NOISE_DEPTH with the area light of
    ``scenes/include/stage.xml`` (2.4 wide, ~5 away, above and to the left) besides the sky."""
    import mitsuba as mi
    d = sphere_scene(bsdf, res, spp, NOISE_DEPTH)
    d["light"] = {"type": "rectangle", "emitter": {"type": "area", "radiance": {
                  "type": "rgb", "value": [9.0, 8.6, 8.0]}},
                  "to_world": mi.ScalarTransform4f().translate([-2.0, 4.0, 2.5])
                  .rotate([1, 0, 0], 70).scale(1.2)}
    return d


def geometry_scene(base: dict, res: int, spp: int, top: tuple = SMOOTH) -> dict:
    """The coating as geometry: the films on a sphere of the top's interface plugin (a
    ``thinfilm_dielectric`` for the smooth top) around the base."""
    d = lit_scene({**top[1], "layers": COAT["layers"], "int_ior": COAT["int_ior"]}, res, spp)
    d["base"] = {"type": "sphere", "center": list(CENTER), "radius": 1.0 - GAP, "bsdf": base}
    return d


def cpu_timed(fn, *args, **kwargs) -> tuple[float, float, object]:
    """(wall seconds, process CPU seconds, result) of ``fn(*args, **kwargs)``."""
    t, c = time.perf_counter(), time.process_time()
    result = fn(*args, **kwargs)
    return time.perf_counter() - t, time.process_time() - c, result


# -- 1 and 2: steady cost and edits, one process per variant -------------------------------

def compiled(history: list) -> int:
    import drjit as dr
    return sum(1 for k in history if k["type"] == dr.KernelType.JIT
               and not k.get("cache_hit", False) and not k.get("cache_disk", False))


def edits(scene, n: int) -> dict:
    """Kernels compiled by ``n`` edits of the outer film's thickness and the renders after them."""
    import drjit as dr
    import mitsuba as mi
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("layers.0.thickness"))
    render_sync(scene, seed=0)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()   # clear
        update = render = 0
        for i, d in enumerate(np.linspace(500.0, 420.0, n)):
            params[key] = float(d)
            params.update()
            update += compiled(dr.kernel_history())
            render_sync(scene, seed=i + 1)
            render += compiled(dr.kernel_history())
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    return {"key": key, "edits": n, "update": update, "render": render}


def steady_child(variant: str, repeats: int, res: int, spp: int, n_edits: int) -> None:
    import mitsuba as mi
    mi.set_variant(variant)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    own_table_store()
    bases = [mi.load_dict(sphere_scene(base, res, spp)) for _, base, _ in cases()]
    coated_loaders = [lambda base=base, top=top: mi.load_dict(sphere_scene(coated(base, top),
                                                                           res, spp))
                      for _, base, top in cases()]
    rows = pair_rounds(bases, coated_loaders, repeats, progress=variant)
    out = {"steady": [{"label": label, "base": row["native"], "coated": row["ours"],
                       "wall_ratio": row["wall_ratio"], "ratio": row["ratio"]}
                      for (label, _, _), row in zip(cases(), rows)],
           "edits": edits(mi.load_dict(sphere_scene(coated(BASES[-1][1]), res, spp)), n_edits)}
    print(json.dumps(out))


# -- 3: noise at equal time against the explicit geometry ----------------------------------

def sphere_mask(scene) -> np.ndarray:
    """Pixels (row-major, as ``mi.render`` returns them) whose centre sees the sphere."""
    import drjit as dr
    import mitsuba as mi
    sensor = scene.sensors()[0]
    w, h = sensor.film().crop_size()
    x, y = np.meshgrid((np.arange(w) + 0.5) / w, (np.arange(h) + 0.5) / h)
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(x.ravel(), y.ravel()), mi.Point2f(0.5))
    si = scene.ray_intersect(ray)
    near = dr.norm(si.p - mi.Point3f(*CENTER)) < 1.0 + 1e-3
    return np.array(si.is_valid() & near).reshape(h, w)


def relative_rmse(image, reference, mask) -> float:
    a, b = np.asarray(image)[mask], np.asarray(reference)[mask]
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(b))


def noise_child(variant: str, res: int, spp: int, ref_factor: int) -> None:
    import mitsuba as mi
    mi.set_variant(variant)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    out = []
    for label, base, top in cases():
        # each scene is loaded alone (see steady_child: a live Python BSDF is traced by every
        # render); loads after the first hit the kernel cache
        dicts = {"coating": lit_scene(coated(base, top), res, spp),
                 "geometry": geometry_scene(base, res, spp, top)}
        per_render, mask = {}, None
        for name, d in dicts.items():
            scene = mi.load_dict(d)
            mask = sphere_mask(scene) if mask is None else mask
            render_sync(scene, seed=0)   # compiles
            per_render[name] = float(np.median([cpu_timed(render_sync, scene, seed=s)[1]
                                                for s in (1, 2, 3)]))
            del scene
            gc.collect()
        spp_of = {"coating": spp,
                  "geometry": max(1, round(spp * per_render["coating"] / per_render["geometry"]))}
        row = {"label": label, "mask_pixels": int(mask.sum())}
        refs = {}
        for ref_seed, (name, d) in enumerate(dicts.items(), 1000):
            scene = mi.load_dict(d)
            render_sync(scene, seed=0, spp=spp_of[name])   # compiles for this sample count
            # seeds of their own: the two references' noise independent of each other's
            refs[name] = np.asarray(render_sync(scene, seed=ref_seed, spp=ref_factor * spp_of[name]))
            seconds, rmse = [], []
            for seed in (7, 8, 9):
                _, cpu, image = cpu_timed(render_sync, scene, seed=seed, spp=spp_of[name])
                seconds.append(cpu)
                rmse.append(relative_rmse(image, refs[name], mask))
            row[name] = {"spp": spp_of[name], "seconds": float(np.median(seconds)),
                         "rmse": float(np.sqrt(np.mean(np.square(rmse))))}
            del scene
            gc.collect()
        g, c = row["geometry"], row["coating"]
        row["efficiency"] = (g["rmse"] ** 2 * g["seconds"]) / (c["rmse"] ** 2 * c["seconds"])
        row["references_rmse"] = relative_rmse(refs["geometry"], refs["coating"], mask)
        # what the two high-spp images' own noise alone puts between them
        row["references_noise"] = float(np.hypot(c["rmse"], g["rmse"]) / np.sqrt(ref_factor))
        # their mean radiance over the sphere: a bias shows here, fireflies average out
        mean_c, mean_g = (float(np.mean(refs[k][mask])) for k in ("coating", "geometry"))
        row["references_means"] = (mean_c - mean_g) / mean_g
        out.append(row)
        print(f"  noise, {variant}: {label}: coating {c}, geometry {g}", file=sys.stderr, flush=True)
    print(json.dumps(out))


# -- 4: first image ------------------------------------------------------------------------

def first_child(which: str, index: int, res: int, spp: int) -> None:
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    _, base, top = cases()[index]
    t0 = time.perf_counter()
    scene = mi.load_dict(sphere_scene(coated(base, top) if which == "coated" else base, res, spp))
    t1 = time.perf_counter()
    render_sync(scene, seed=0)
    print(json.dumps({"load": t1 - t0, "render": time.perf_counter() - t1}))


def first_images(repeats: int, res: int, spp: int) -> list:
    out = []
    for index, (label, _, _) in enumerate(cases()):
        size = ["--res", str(res), "--spp", str(spp)]
        for which in ("base", "coated"):      # the kernel cache warm; tables built per process
            child(__file__, "--first-child", which, str(index), *size)
        runs = {"base": [], "coated": []}
        for r in range(repeats):
            for which in (("base", "coated") if r % 2 == 0 else ("coated", "base")):
                runs[which].append(child(__file__, "--first-child", which, str(index), *size))
        total = {w: np.array([x["load"] + x["render"] for x in v]) for w, v in runs.items()}
        out.append({"label": label, "base": float(np.median(total["base"])),
                    "coated": float(np.median(total["coated"])),
                    "coated_load": float(np.median([x["load"] for x in runs["coated"]])),
                    "ratio": float(np.median(total["coated"] / total["base"]))})
    return out


# -- the report ----------------------------------------------------------------------------

def markdown(data: dict, args) -> str:
    import drjit as dr
    coat = f'`thinfilm_coating` "{COAT["layers"]}", `int_ior` {COAT["int_ior"]}'
    lines = [f"{dr.thread_count()} Dr.Jit threads.", ""]
    steady = data.get("steady")
    if steady:
        variants = list(steady)
        lines += [f"**Render cost over the nested BSDF alone.** The sphere scene of "
                  f"`benchmarks/timing.py` ({args.res}×{args.res}, {args.spp} spp, max depth 8), the "
                  f"sphere's BSDF the base alone or under {coat}; median over {args.repeats} "
                  f"rounds of the CPU-time ratio of back-to-back renders:", "",
                  "| base | " + " | ".join(f"`{v}`" for v in variants) + " |",
                  "|---|" + "---:|" * len(variants)]
        for i, (label, _, _) in enumerate(cases()):
            cells = [f"{steady[v]['steady'][i]['ratio']:.2f}× ({steady[v]['steady'][i]['coated']:.2f} s "
                     f"against {steady[v]['steady'][i]['base']:.2f} s wall)" for v in variants]
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
        lines += ["", "**Edits without recompilation** (the `principled` base): "
                  + "; ".join(f"`{v}`: {e['edits']} edits of `{e['key']}` compiled {e['update']} "
                              f"kernels in `params.update()` and {e['render']} in the renders after them"
                              for v, e in ((v, steady[v]["edits"]) for v in variants)) + ".", ""]
    noise = data.get("noise")
    if noise:
        lines += [f"**Noise at equal time against the explicit geometry** ({args.noise_res}×"
                  f"{args.noise_res}, max depth {NOISE_DEPTH}, the sky and an area light as in "
                  f"`scenes/include/stage.xml`): the coated sphere at {args.noise_spp} spp against "
                  f"a `thinfilm_dielectric` sphere (a `thinfilm_roughdielectric` of the same α under a "
                  f"rough top) around the base sphere ({GAP} smaller) given the "
                  f"same CPU seconds; RMSE over the sphere's pixels relative to their mean, each "
                  f"against its own scene at {args.ref_factor}× its samples. Efficiency = RMSE² × "
                  f"time of the geometry over that of the coating (> 1: the coating is the more "
                  f"efficient). The last column is the two high-spp images' RMSE to each other, and "
                  f"in brackets what their own noise alone puts between them as estimated from the "
                  f"three images (fireflies make it an underestimate), then the relative difference "
                  f"of their mean radiance over the sphere, where a bias would show (in RGB the "
                  f"plugin's product of channel integrals differs from the geometry's per-channel "
                  f"crossings too):", "",
                  "| base | variant | coating: spp, s, RMSE | geometry: spp, s, RMSE | efficiency | "
                  "high-spp images apart | their means apart |", "|---|---|---|---|---:|---:|---:|"]
        for i, (label, _, _) in enumerate(cases()):
            for v, rows in noise.items():
                row = rows[i]
                c, g = row["coating"], row["geometry"]
                lines.append(f"| {label} | `{v}` | {c['spp']}, {c['seconds']:.2f} s, {c['rmse']:.3f} | "
                             f"{g['spp']}, {g['seconds']:.2f} s, {g['rmse']:.3f} | "
                             f"{row['efficiency']:.1f}× | {row['references_rmse']:.3f} "
                             f"({row['references_noise']:.3f}) | {row['references_means']:+.2%} |")
        lines.append("")
    first = data.get("first")
    if first:
        lines += [f"**First image** (`llvm_ad_spectral`, {args.res}×{args.res}, {args.spp} spp; a "
                  f"fresh process, the kernel cache warm, the table store off: the stack's table is "
                  f"built in the load): medians of {args.first_repeats}:", "",
                  "| base | coated (load) | base alone | ratio |", "|---|---:|---:|---:|"]
        for row in first:
            lines.append(f"| {row['label']} | {row['coated']:.2f} s ({row['coated_load']:.2f} s) | "
                         f"{row['base']:.2f} s | {row['ratio']:.2f}× |")
        lines.append("")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--edits", type=int, default=4)
    ap.add_argument("--noise-res", type=int, default=128)
    ap.add_argument("--noise-spp", type=int, default=16)
    ap.add_argument("--ref-factor", type=int, default=16)
    ap.add_argument("--first-repeats", type=int, default=3)
    ap.add_argument("--skip-steady", action="store_true")
    ap.add_argument("--skip-noise", action="store_true")
    ap.add_argument("--skip-first", action="store_true")
    ap.add_argument("--steady-child")
    ap.add_argument("--noise-variants", default=",".join(VARIANTS))
    ap.add_argument("--noise-child")
    ap.add_argument("--first-child", nargs=2, metavar=("WHICH", "BASE"))
    args = ap.parse_args()
    if args.steady_child:
        return steady_child(args.steady_child, args.repeats, args.res, args.spp, args.edits)
    if args.noise_child:
        return noise_child(args.noise_child, args.noise_res, args.noise_spp, args.ref_factor)
    if args.first_child:
        return first_child(args.first_child[0], int(args.first_child[1]), args.res, args.spp)
    data = {}
    if not args.skip_steady:
        data["steady"] = {v: child(__file__, "--steady-child", v, "--repeats", str(args.repeats),
                                   "--res", str(args.res), "--spp", str(args.spp),
                                   "--edits", str(args.edits))
                          for v in args.variants.split(",")}
    if not args.skip_noise:
        data["noise"] = {v: child(__file__, "--noise-child", v, "--noise-res", str(args.noise_res),
                                  "--noise-spp", str(args.noise_spp), "--ref-factor",
                                  str(args.ref_factor))
                         for v in args.noise_variants.split(",")}
    if not args.skip_first:
        data["first"] = first_images(args.first_repeats, args.res, args.spp)
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    print(markdown(data, args))
    print(json.dumps(data), file=sys.stderr)


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("coating_bench"):   # --write-docs: docs/_generated/coating_bench.md
        main()
