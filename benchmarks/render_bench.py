"""Render time against the number of films: every thin-film plugin against its Mitsuba
counterpart in every variant, steady and first image; the image error of the tables, and
the kernels compiled by a thickness sweep.

    python benchmarks/render_bench.py [--repeats 5] [--films 1,3,10,30] [--modes exact,table,default]
                                      [--variants llvm_ad_spectral,llvm_ad_rgb,llvm_ad_mono,llvm_ad_spectral_polarized]
                                      [--res 256] [--spp 16]
                                      [--first-repeats 3] [--first-films 1,30]
                                      [--first-variants llvm_ad_spectral,llvm_ad_spectral_polarized]
                                      [--skip-steady] [--skip-first] [--skip-de] [--skip-sweep]

The stacks: 1, 3, 10, 30 films alternating n = 2.3 / 1.46, thicknesses 50-200 nm from
``numpy.random.default_rng(6)`` (:func:`thicknesses`; the benchmark stacks that
``speed_vs_error.py``, ``band_bench.py``, ``deep_bench.py`` and ``rgb_bench.py`` share). Each
plugin of ``timing.COUNTERPARTS`` carries them against its counterpart: ``thinfilm_conductor``
on Al against ``conductor`` (Al), the rough conductor (α 0.2) against ``roughconductor``, the
dielectrics on 1.6 against ``dielectric`` / ``roughdielectric``, ``thinfilm_diffuse`` on 0.5
against ``diffuse`` 0.5, and ``thinfilm_coating`` (``int_ior`` 1.5) over the rough Al base
against that base alone. The plugins at default settings, with one stack each, in spectral,
RGB and polarized variants: ``plugin_bench.py``.

1. Steady render time, each of --variants in a process of its own, the sphere scene of
   ``timing.py`` (--res², --spp, ``path`` max depth 8): each plugin with each stack, with
   ``tabulate`` at each of --modes in spectral variants (``exact``: false, ``table``: true,
   ``default``: unset; the mode obtained is printed: a stack that cannot be tabulated within
   ``table_error`` is rendered exactly), at default settings in RGB and mono variants (a stack
   of any depth is there a colour table over the angle). ``timing.pair_rounds``: our scene
   loaded alone for each render and freed, Mitsuba's loaded throughout, an untimed round, then
   --repeats rounds of back-to-back pairs; the ratio is the median of the rounds' CPU-time
   ratios.
2. First image with an empty kernel cache (``timing.first_images``: a fresh process and
   ``DRJIT_CACHE_DIR`` per run timing ``mi.load_dict`` + the first ``mi.render``, imports not
   timed, every table built) in each of --first-variants: each plugin at --first-films with
   ``tabulate`` unset and false, and its counterpart; --first-repeats rounds, round-robin, the
   run with the median total is reported, and its ratio to the counterpart's.
3. Image error of table mode against exact mode on the paper's Fig. 8 scenes
   (scenes/fig8*.xml, which do not expose ``tabulate`` as a $parameter: the
   BSDF gets ``<string name="tabulate" value="..."/>`` in a modified copy of the
   XML string, loaded with ``mi.load_string``; the scene files are not changed),
   rendered with the same seed (so the sample paths match) at --de-res and
   --de-spp. CIE ΔE2000 per pixel (colour-science, linear sRGB clipped to [0, 1]
   -> XYZ -> Lab, D65), mean and 99th percentile. The noise floor is the ΔE
   between two exact renders with different seeds. An accuracy figure: nothing timed.
4. A 20-frame sweep of the SiO2 thickness (400 -> 600 nm) on fig8a (one film;
   ``tabulate`` true and false) at 128x85, 4 spp, counting JIT kernel
   compilations (``dr.JitFlag.KernelHistory``: entries of type
   ``dr.KernelType.JIT`` that are neither an in-memory nor a disk cache hit)
   separately in ``params.update()`` (table builds) and in ``mi.render``. It counts
   kernels of our plugin's edits, which Mitsuba's plugins have no counterpart of.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import sys
import tempfile
import time
import warnings

import numpy as np

# Builds are what these benchmarks time: the table store on disk
# (thinfilm_mi.tabulate.store) is off unless the environment names one, and
# first_images(store="warm") measures it on purpose.
os.environ.setdefault("THINFILM_MI_TABLE_CACHE", "off")

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
SCENES = os.path.join(REPO, "scenes")
sys.path.insert(0, HERE)
from timing import (  # noqa: E402
    COUNTERPARTS,
    MODES,
    child,
    first_images,
    mode_of,
    own_table_store,
    pair_rounds,
    render_sync,
    sphere_scene,
)

FILMS = (1, 3, 10, 30)
VARIANT = "llvm_ad_spectral"
VARIANTS = ("llvm_ad_spectral", "llvm_ad_rgb", "llvm_ad_mono", "llvm_ad_spectral_polarized")
FIRST_VARIANTS = ("llvm_ad_spectral", "llvm_ad_spectral_polarized")


def thicknesses(seed=6, n=max(FILMS)):
    return np.random.default_rng(seed).uniform(50.0, 200.0, n)


def layers(n: int) -> str:
    """The benchmark stack of ``n`` films (:func:`thicknesses`)."""
    d = thicknesses()
    return "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(n))


def bsdf_dict(config: str) -> dict:
    """``"conductor"`` or ``"L:exact"`` / ``"L:table"``: ``thinfilm_conductor`` on Al."""
    conductor = COUNTERPARTS["thinfilm_conductor"]
    if config == "conductor":
        return conductor.native
    L, mode = config.split(":")
    return conductor.ours(layers(int(L)), **MODES[mode])


def scene_dict(config: str, res=256, spp=16, bsdf: dict | None = None) -> dict:
    """The sphere scene with the BSDF of ``config`` (:func:`bsdf_dict`), or ``bsdf``."""
    return sphere_scene(bsdf if bsdf is not None else bsdf_dict(config), res, spp)


def config_bsdf(config: str) -> dict:
    """``"PLUGIN"``: the counterpart of ``PLUGIN``; ``"PLUGIN:L:MODE"``: ``PLUGIN`` with the
    stack of ``L`` films at the ``tabulate`` setting ``MODE`` (:data:`timing.MODES`)."""
    plugin, *rest = config.split(":")
    if not rest:
        return COUNTERPARTS[plugin].native
    L, mode = rest
    return COUNTERPARTS[plugin].ours(layers(int(L)), **MODES[mode])


def label(config: str) -> tuple[str, str, str]:
    """(plugin, films, ``tabulate`` setting) of a configuration, for a table row."""
    plugin, *rest = config.split(":")
    if not rest:
        return f"`{COUNTERPARTS[plugin].native['type']}` (`{plugin}`'s counterpart)", "–", "–"
    return f"`{plugin}`", rest[0], rest[1]


# -- 1. steady render time ------------------------------------------------------
def steady_child(variant: str, films, modes, repeats: int, res: int, spp: int) -> None:
    import mitsuba as mi
    mi.set_variant(variant)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    own_table_store()
    modes = modes if mi.is_spectral else ["default"]   # colour variants: one table per stack
    configs = [f"{p}:{L}:{m}" for p in COUNTERPARTS for L in films for m in modes]
    natives = {p: mi.load_dict(sphere_scene(c.native, res, spp)) for p, c in COUNTERPARTS.items()}
    loaders = [lambda c=c: mi.load_dict(sphere_scene(config_bsdf(c), res, spp)) for c in configs]
    rows = pair_rounds([natives[c.split(":")[0]] for c in configs], loaders, repeats,
                       progress=variant)
    print(json.dumps([dict(row, config=c) for c, row in zip(configs, rows)]))


def steady(variants, films, modes, args) -> dict:
    out = {}
    for v in variants:
        out[v] = child(__file__, "--steady-child", v, "--films", ",".join(map(str, films)),
                       "--modes", ",".join(modes), "--repeats", str(args.repeats),
                       "--res", str(args.res), "--spp", str(args.spp))
        print(f"\n### `{v}`: steady render time against each plugin's counterpart ({args.res}x"
              f"{args.res}, {args.spp} spp; median over {args.repeats} rounds of the CPU-time "
              "ratio of back-to-back renders, our scene loaded alone)\n")
        print("| plugin | films | tabulate | mode obtained | ours (s) | counterpart (s) "
              "| wall-clock ratio | CPU-time ratio |")
        print("|---|---:|---|---|---:|---:|---:|---:|")
        for row in out[v]:
            name, L, m = label(row["config"])
            print(f"| {name} | {L} | {m} | {row['mode']} | {row['ours']:.3f} | "
                  f"{row['native']:.3f} | {row['wall_ratio']:.2f} | {row['ratio']:.2f} |",
                  flush=True)
    return out


# -- 2. first image, empty kernel cache ------------------------------------------
def first_image_child(config: str, variant: str, res: int, spp: int):
    """Runs in the subprocess: time mi.load_dict + first mi.render."""
    import mitsuba as mi
    mi.set_variant(variant)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    scene = mi.load_dict(sphere_scene(config_bsdf(config), res, spp))
    t1 = time.perf_counter()
    render_sync(scene, seed=0)
    t2 = time.perf_counter()
    print(json.dumps({"load": t1 - t0, "render": t2 - t1, "mode": mode_of(scene)}))


def first_image(variants, films, repeats: int, res: int, spp: int) -> dict:
    configs = [c for p in COUNTERPARTS
               for c in [p] + [f"{p}:{L}:{m}" for L in films for m in ("default", "exact")]]
    out = {}
    for v in variants:
        out[v] = runs = first_images(__file__, configs, repeats,
                                     child_args=("--variants", v, "--res", str(res),
                                                 "--spp", str(spp)))
        print(f"\n### `{v}`: first image, empty kernel cache ({res}x{res}, {spp} spp; fresh "
              f"process and DRJIT_CACHE_DIR per run; the run with the median total of "
              f"{repeats})\n")
        print("| plugin | films | tabulate | mode obtained | mi.load (s) | first mi.render (s) "
              "| total (s) | ratio to the counterpart |")
        print("|---|---:|---|---|---:|---:|---:|---:|")
        for c in configs:
            r = runs[c]
            tot = r["load"] + r["render"]
            base = runs[c.split(":")[0]]
            name, L, m = label(c)
            print(f"| {name} | {L} | {m} | {r['mode']} | {r['load']:.2f} | {r['render']:.2f} | "
                  f"{tot:.2f} | {tot / (base['load'] + base['render']):.2f} |", flush=True)
    return out


# -- 3. ΔE2000 of table mode against exact mode -------------------------------------
def load_fig8(name: str, tabulate: str, **params):
    import mitsuba as mi
    path = os.path.join(SCENES, name)
    with open(path, encoding="utf-8") as f:
        xml = f.read()
    marker = '<bsdf type="thinfilm_'
    i = xml.index(marker)
    j = xml.index(">", i) + 1
    xml = xml[:j] + f'\n            <string name="tabulate" value="{tabulate}"/>' + xml[j:]
    mi.Thread.thread().file_resolver().prepend(SCENES)
    return mi.load_string(xml, **{k: str(v) for k, v in params.items()})


def to_lab(img):
    import colour
    rgb = np.clip(np.array(img, dtype=np.float64)[..., :3], 0.0, 1.0)
    xyz = colour.RGB_to_XYZ(rgb, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False)
    return colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS[
        "CIE 1931 2 Degree Standard Observer"]["D65"])


def delta_e(a, b):
    import colour
    return colour.delta_E(to_lab(a), to_lab(b), method="CIE 2000")


def image_error(res: int, spp: int):
    import mitsuba as mi
    scenes = ["fig8a_si_sio2.xml", "fig8b_glass_au.xml", "fig8c_glass_dielectric_au_al.xml"]
    resx, resy = res, int(round(res * 266 / 400))
    print(f"\n### Image error of table mode against exact mode ({resx}x{resy}, {spp} spp, "
          "same seed; ΔE2000 per pixel)\n")
    print("| scene | mode obtained (tabulate true) | table nu x nv (side: verified err) "
          "| mean ΔE | p99 ΔE | max ΔE | noise floor: exact seed 0 vs 1, mean ΔE |")
    print("|---|---|---|---:|---:|---:|---:|")
    out = {}
    for name in scenes:
        params = dict(resx=resx, resy=resy, spp=spp)
        exact = load_fig8(name, "false", **params)
        table = load_fig8(name, "true", **params)
        stack = None
        for shape in table.shapes():
            stack = getattr(shape.bsdf(), "stack", None) or stack
        tabs = ", ".join(f"{'inside' if k else 'outside'}: "
                         + (f"{s.table.nu}x{s.table.nv} ({s.table.error:.1e})"
                            if s.table is not None else "none")
                         for k, s in stack.plan.items())
        img_e = render_sync(exact, seed=0)
        img_t = render_sync(table, seed=0)
        img_e1 = render_sync(exact, seed=1)
        de = delta_e(img_t, img_e)
        noise = delta_e(img_e1, img_e)
        mi.util.write_bitmap(os.path.join(tempfile.gettempdir(), f"rb_{name}_table.png"), img_t)
        mi.util.write_bitmap(os.path.join(tempfile.gettempdir(), f"rb_{name}_exact.png"), img_e)
        out[name] = float(de.mean())
        print(f"| {name} | {stack.mode()} | {tabs} | {de.mean():.3f} | "
              f"{np.percentile(de, 99):.3f} | {de.max():.2f} | {noise.mean():.3f} |", flush=True)
        del exact, table, stack   # our BSDFs alive would be traced into the next renders
        gc.collect()
    return out


# -- 4. compilations in a thickness sweep ------------------------------------------
def sweep(frames: int = 20):
    import drjit as dr
    import mitsuba as mi

    def compiles(history):
        n_jit = [h for h in history if h.get("type") == dr.KernelType.JIT]
        new = [h for h in n_jit if not h.get("cache_hit") and not h.get("cache_disk")]
        disk = [h for h in n_jit if h.get("cache_disk")]
        return len(new), len(disk), len(n_jit)

    print(f"\n### Kernel compilations in a {frames}-frame sweep (fig8a, SiO2 400 -> 600 nm, "
          "128x85, 4 spp)\n")
    print("| tabulate | frames | render: compiled (frame 0 / frames 1..) | render: disk-cache "
          "loads | params.update (table build): compiled (frame 0 / frames 1..) "
          "| build launches | table shapes | sweep time (s) |")
    print("|---|---:|---|---:|---|---:|---|---:|")
    for tab in ("false", "true"):
        scene = load_fig8("fig8a_si_sio2.xml", tab, resx=128, resy=85, spp=4, thickness=400)
        params = mi.traverse(scene)
        key = next(k for k in params.keys() if k.endswith("layers.0.thickness"))
        stack = next(s.bsdf().stack for s in scene.shapes() if hasattr(s.bsdf(), "stack"))
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()   # clear
        r_new, b_new, r_disk, b_launch, shapes = [], [], 0, 0, []
        t0 = time.perf_counter()
        for f, d in enumerate(np.linspace(400.0, 600.0, frames)):
            params[key] = float(d)
            params.update()
            h = dr.kernel_history()
            n, _, tot = compiles(h)
            b_new.append(n)
            b_launch += tot
            t = stack.plan[False].table
            shapes.append(None if t is None else (t.nu, t.nv))
            render_sync(scene, seed=f)
            n, disk, _ = compiles(dr.kernel_history())
            r_new.append(n)
            r_disk += disk
        dt = time.perf_counter() - t0
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        uniq = sorted({s for s in shapes if s is not None}) or ["–"]
        print(f"| {tab} | {frames} | {sum(r_new)} ({r_new[0]} / {sum(r_new[1:])}) | {r_disk} | "
              f"{sum(b_new)} ({b_new[0]} / {sum(b_new[1:])}) | {b_launch} | "
              f"{', '.join(f'{s[0]}x{s[1]}' if s != '–' else s for s in uniq)} | {dt:.1f} |",
              flush=True)
        del scene, params, stack   # alive, our BSDF would be traced into the next sweep's renders
        gc.collect()


def names(s: str) -> list[str]:
    return [x for x in s.split(",") if x]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--films", default=",".join(map(str, FILMS)))
    ap.add_argument("--modes", default="exact,table,default",
                    help=f"tabulate settings in spectral variants, of {list(MODES)}")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--first-repeats", type=int, default=3)
    ap.add_argument("--first-films", default="1,30")
    ap.add_argument("--first-variants", default=",".join(FIRST_VARIANTS))
    ap.add_argument("--de-res", type=int, default=200)
    ap.add_argument("--de-spp", type=int, default=64)
    ap.add_argument("--skip-steady", action="store_true")
    ap.add_argument("--skip-first", action="store_true")
    ap.add_argument("--skip-de", action="store_true")
    ap.add_argument("--skip-sweep", action="store_true")
    ap.add_argument("--steady-child", help=argparse.SUPPRESS)
    ap.add_argument("--first-image-child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    films = [int(x) for x in names(args.films)]
    if args.steady_child:
        return steady_child(args.steady_child, films, names(args.modes), args.repeats, args.res,
                            args.spp)
    if args.first_image_child:
        return first_image_child(args.first_image_child, args.variants, args.res, args.spp)
    unknown = [m for m in names(args.modes) if m not in MODES]
    if unknown:
        ap.error(f"--modes: {unknown} not in {list(MODES)}")
    import drjit as dr
    import mitsuba as mi
    t0 = time.perf_counter()
    print(f"Mitsuba {mi.__version__}, Dr.Jit {dr.__version__}, {os.cpu_count()} CPUs")
    if not args.skip_steady:
        steady(names(args.variants), films, names(args.modes), args)
    if not args.skip_first:
        first_image(names(args.first_variants), [int(x) for x in names(args.first_films)],
                    args.first_repeats, args.res, args.spp)
    if not (args.skip_de and args.skip_sweep):
        mi.set_variant(VARIANT)
        import thinfilm_mi  # noqa: F401
        warnings.simplefilter("ignore")
    if not args.skip_de:
        image_error(args.de_res, args.de_spp)
    if not args.skip_sweep:
        sweep()
    print(f"\ntotal run time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("render_bench"):   # --write-docs: docs/_generated/render_bench.md
        main()
