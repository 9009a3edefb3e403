"""Render-time cost of the thin-film BSDFs (exact and table modes), image error of
the tables, and kernel compilations in a thickness sweep.

    python benchmarks/render_bench.py [--repeats 5] [--first-repeats 3] [--skip-first]
                                      [--skip-de] [--skip-sweep]

Variant llvm_ad_spectral, one process (first-image runs in subprocesses):

1. Steady render time: a sphere (radius 1) on a diffuse floor under a constant
   emitter, path integrator (max_depth 8), 256x256, 16 spp. The sphere is
   Mitsuba's ``conductor`` (Al) or ``thinfilm_conductor`` on Al with 1, 3, 10, 30
   films (alternating n = 2.3 / 1.46, thicknesses 50-200 nm from
   ``numpy.random.default_rng(6)``, as in speed_vs_error.py), with ``tabulate``
   false (exact) and true (table; the mode actually obtained is printed: a stack
   that cannot be tabulated within ``table_error`` is rendered exactly). One
   warm-up render each, then --repeats rounds in which every configuration
   renders once (round-robin, so a slow spell of the shared machine hits all
   alike); the median per configuration (``dr.eval`` + ``dr.sync_thread``),
   different seeds.
2. First image with an empty kernel cache: for each configuration a subprocess
   with ``DRJIT_CACHE_DIR`` set to a fresh temporary folder times ``mi.load_dict``
   + the first ``mi.render`` (imports not timed); --first-repeats rounds,
   round-robin, the run with the median total is reported; ratio to
   ``conductor`` measured the same way.
3. Image error of table mode against exact mode on the paper's Fig. 8 scenes
   (scenes/fig8*.xml, which do not expose ``tabulate`` as a $parameter: the
   BSDF gets ``<string name="tabulate" value="..."/>`` in a modified copy of the
   XML string, loaded with ``mi.load_string``; the scene files are not changed),
   rendered with the same seed (so the sample paths match) at --de-res and
   --de-spp. CIE ΔE2000 per pixel (colour-science, linear sRGB clipped to [0, 1]
   -> XYZ -> Lab, D65), mean and 99th percentile. The noise floor is the ΔE
   between two exact renders with different seeds.
4. A 20-frame sweep of the SiO2 thickness (400 -> 600 nm) on fig8a (one film;
   ``tabulate`` true and false) at 128x85, 4 spp, counting JIT kernel
   compilations (``dr.JitFlag.KernelHistory``: entries of type
   ``dr.KernelType.JIT`` that are neither an in-memory nor a disk cache hit)
   separately in ``params.update()`` (table builds) and in ``mi.render``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
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
FILMS = (1, 3, 10, 30)
VARIANT = "llvm_ad_spectral"


def thicknesses(seed=6, n=max(FILMS)):
    return np.random.default_rng(seed).uniform(50.0, 200.0, n)


def bsdf_dict(config: str) -> dict:
    """``"conductor"`` or ``"L:exact"`` / ``"L:table"``."""
    if config == "conductor":
        return {"type": "conductor", "material": "Al"}
    L, mode = config.split(":")
    d = thicknesses()
    layers = "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(int(L)))
    return {"type": "thinfilm_conductor", "material": "Al", "layers": layers,
            "tabulate": mode == "table"}


def scene_dict(config: str, res=256, spp=16, bsdf: dict | None = None) -> dict:
    """The sphere scene with the BSDF of ``config`` (:func:`bsdf_dict`), or ``bsdf``."""
    import mitsuba as mi
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 8},
        "sensor": {"type": "perspective", "fov": 35,
                   "to_world": mi.ScalarTransform4f().look_at(
                       origin=[0, 1.5, 5], target=[0, 0.2, 0], up=[0, 1, 0]),
                   "sampler": {"type": "independent", "sample_count": spp},
                   "film": {"type": "hdrfilm", "width": res, "height": res,
                            "rfilter": {"type": "box"}}},
        "emitter": {"type": "constant", "radiance": {"type": "rgb", "value": [0.8, 0.85, 1.0]}},
        "sphere": {"type": "sphere", "center": [0, 0.2, 0], "radius": 1.0,
                   "bsdf": bsdf if bsdf is not None else bsdf_dict(config)},
        "floor": {"type": "rectangle",
                  "to_world": mi.ScalarTransform4f().translate([0, -0.8, 0])
                  .rotate([1, 0, 0], -90).scale(6),
                  "bsdf": {"type": "diffuse",
                           "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.45]}}},
    }


def render_sync(scene, **kw):
    import drjit as dr
    import mitsuba as mi
    img = mi.render(scene, **kw)
    dr.eval(img)
    dr.sync_thread()
    return img


def mode_of(scene) -> str:
    for shape in scene.shapes():
        stack = getattr(shape.bsdf(), "stack", None)
        if stack is not None:
            return stack.mode()
    return "–"


# -- 1. steady render time ------------------------------------------------------
def steady(repeats: int):
    import mitsuba as mi
    configs = ["conductor"] + [f"{L}:{m}" for L in FILMS for m in ("exact", "table")]
    scenes, loads = {}, {}
    for c in configs:
        t0 = time.perf_counter()
        scenes[c] = mi.load_dict(scene_dict(c))
        loads[c] = time.perf_counter() - t0
        render_sync(scenes[c], seed=0)   # warm-up: compiles
    # Round-robin: every configuration once per round, so that a slow spell of the
    # (shared) machine hits all of them alike instead of one configuration.
    ts = {c: [] for c in configs}
    for i in range(repeats):
        for c in configs:
            t = time.perf_counter()
            render_sync(scenes[c], seed=i + 1)
            ts[c].append(time.perf_counter() - t)
    out = {}
    for c in configs:
        out[c] = (float(np.median(ts[c])), float(np.min(ts[c])), mode_of(scenes[c]), loads[c])
        print(f"  {c}: median {out[c][0]:.3f} s, mode {out[c][2]}, load {loads[c]:.2f} s",
              file=sys.stderr, flush=True)
    base = out["conductor"][0]
    print("\n### Steady render time (256x256, 16 spp, median of "
          f"{repeats}; load time includes any table build)\n")
    print("| BSDF | films | mode asked | mode obtained | load (s) | render median (s) "
          "| min (s) | ratio to conductor |")
    print("|---|---:|---|---|---:|---:|---:|---:|")
    print(f"| conductor (Al) | – | – | – | {out['conductor'][3]:.2f} | {base:.3f} | "
          f"{out['conductor'][1]:.3f} | 1.00 |")
    for c in configs[1:]:
        L, m = c.split(":")
        med, mn, mode, tl = out[c]
        print(f"| thinfilm_conductor | {L} | {m} | {mode} | {tl:.2f} | {med:.3f} | {mn:.3f} | "
              f"{med / base:.2f} |")
    return out


# -- 2. first image, empty kernel cache ------------------------------------------
def first_image_child(config: str):
    """Runs in the subprocess: time mi.load_dict + first mi.render."""
    import mitsuba as mi
    mi.set_variant(VARIANT)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    scene = mi.load_dict(scene_dict(config))
    t1 = time.perf_counter()
    render_sync(scene, seed=0)
    t2 = time.perf_counter()
    print(json.dumps({"load": t1 - t0, "render": t2 - t1, "mode": mode_of(scene)}))


def first_images(script: str, configs, repeats: int, store: str = "off") -> dict:
    """Per configuration, the run (``{"load", "render", "mode"}``) with the median
    total of ``repeats``: each a new process running ``script
    --first-image-child CONFIG`` with a fresh ``DRJIT_CACHE_DIR``, the
    configurations round-robin (as in steady()). ``store``: the table store on
    disk is ``"off"`` (every process builds its tables), or ``"warm"``: a store
    filled by one untimed run per configuration (a script run again)."""
    runs = {c: [] for c in configs}
    with tempfile.TemporaryDirectory(prefix="tables_") as tables:
        setting = tables if store == "warm" else "off"

        def child(c: str) -> dict:
            with tempfile.TemporaryDirectory(prefix="drjit_cache_") as cache:
                env = dict(os.environ, DRJIT_CACHE_DIR=cache, THINFILM_MI_TABLE_CACHE=setting)
                res = subprocess.run([sys.executable, os.path.abspath(script),
                                      "--first-image-child", c], env=env, capture_output=True,
                                     text=True, check=True)
                return json.loads(res.stdout.strip().splitlines()[-1])

        if store == "warm":
            for c in configs:
                child(c)
        for _ in range(repeats):
            for c in configs:
                runs[c].append(child(c))
                print(f"  first image {c} (table store {store}): {runs[c][-1]}", file=sys.stderr,
                      flush=True)
    return {c: sorted(runs[c], key=lambda r: r["load"] + r["render"])[len(runs[c]) // 2]
            for c in configs}


def first_image_table(out: dict, configs, asked: str = "mode asked") -> None:
    """Print :func:`first_images`' runs (``configs``: ``"conductor"`` first, then
    ``"L:mode"``) as a table with their ratios to ``conductor``'s total."""
    r = out["conductor"]
    base = r["load"] + r["render"]
    print(f"| BSDF | films | {asked} | mode obtained | mi.load (s) | first mi.render (s) "
          "| total (s) | ratio to conductor |")
    print("|---|---:|---|---|---:|---:|---:|---:|")
    print(f"| conductor (Al) | – | – | – | {r['load']:.2f} | {r['render']:.2f} | {base:.2f} "
          f"| 1.00 |")
    for c in configs[1:]:
        L, m = c.split(":")
        r = out[c]
        tot = r["load"] + r["render"]
        print(f"| thinfilm_conductor | {L} | {m} | {r['mode']} | {r['load']:.2f} | "
              f"{r['render']:.2f} | {tot:.2f} | {tot / base:.2f} |")


def first_image(repeats: int):
    configs = ["conductor"] + [f"{L}:{m}" for L in FILMS for m in ("exact", "table")]
    out = first_images(__file__, configs, repeats)
    print("\n### First image, empty kernel cache (fresh DRJIT_CACHE_DIR per "
          f"configuration and run; the run with the median total of {repeats})\n")
    first_image_table(out, configs)
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


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--first-repeats", type=int, default=3)
    ap.add_argument("--de-res", type=int, default=200)
    ap.add_argument("--de-spp", type=int, default=64)
    ap.add_argument("--skip-steady", action="store_true")
    ap.add_argument("--skip-first", action="store_true")
    ap.add_argument("--skip-de", action="store_true")
    ap.add_argument("--skip-sweep", action="store_true")
    ap.add_argument("--first-image-child")
    args = ap.parse_args()
    if args.first_image_child:
        first_image_child(args.first_image_child)
        return
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(VARIANT)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    print(f"mitsuba {mi.__version__}, drjit {dr.__version__}, {VARIANT}, "
          f"{dr.thread_count()} threads")
    if not args.skip_steady:
        steady(args.repeats)
    if not args.skip_first:
        first_image(args.first_repeats)
    if not args.skip_de:
        image_error(args.de_res, args.de_spp)
    if not args.skip_sweep:
        sweep()
    print(f"\ntotal run time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("render_bench"):   # --write-docs: docs/_generated/render_bench.md
        main()
