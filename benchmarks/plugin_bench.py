"""Every thin-film plugin against its Mitsuba counterpart, in spectral, RGB and
polarized variants, and the demo scene against its native twin.

    python benchmarks/plugin_bench.py [--repeats 5] [--res 256] [--spp 16]
                                      [--variants llvm_ad_spectral,llvm_ad_rgb,llvm_ad_spectral_polarized]
                                      [--demo-repeats 5] [--demo-size 512x341] [--demo-spp 32]
                                      [--first-repeats 3] [--skip-plugins] [--skip-demo]
                                      [--write-docs]

1. Per plugin: the sphere scene of ``render_bench.py`` (a sphere on a diffuse floor
   under a constant emitter, ``path`` with max depth 8, --res x --res, --spp spp,
   box filter) with the sphere's BSDF one of :data:`PAIRS`: a thin-film plugin at
   default settings, and its Mitsuba counterpart. Each variant runs in a process of
   its own; every scene is loaded and rendered once (warm-up: compiles, builds the
   tables), then --repeats rounds in which each pair renders back to back (native first in even
   rounds, the thin film first in odd ones), different seeds. The ratio of a pair is
   the median over the rounds of the round's ratio of the process's CPU time (all
   of Dr.Jit's threads; steadier than the wall clock on a shared machine, where a
   slow spell also hits both renders of a pair alike); the wall-clock ratio is in
   the JSON on stderr. A scene holding a thin-film plugin is loaded for each of its
   timed renders (after one untimed render) and freed after it (:func:`alone`): a live
   Python BSDF is traced into every render of the process, the native scenes' included.
2. The demo (``scenes/demo.xml``) against its twin, in which each thin-film plugin is
   its Mitsuba counterpart (:func:`twin_xml`), ``llvm_ad_spectral``: steady (as
   above, --demo-repeats rounds) and the first image: a fresh process with the
   kernel cache warm (one untimed run of each first) and an empty table store
   (every table is built), timing ``mi.load_string`` + the first ``mi.render``;
   --first-repeats runs alternating, the median of each.

``--write-docs`` writes the tables to docs/_generated/plugin_bench.md, which docs/benchmarks.md
includes (``docs_output.py``: under a line naming the machine, date and commit; generated,
never copied by hand); ``--from-json FILE`` takes a run's figures, and that line, from the JSON
line it wrote to stderr instead of measuring.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
import warnings

import numpy as np

os.environ.setdefault("THINFILM_MI_TABLE_CACHE", "off")

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import docs_output  # noqa: E402
from render_bench import render_sync, scene_dict  # noqa: E402

VARIANTS = ("llvm_ad_spectral", "llvm_ad_rgb", "llvm_ad_spectral_polarized")
STACK = "SiO2 500"
METALS = "SiO2 500; Au 20; Al 10"

#: (label, Mitsuba's BSDF, the thin-film BSDF): issue 44's scenes.
PAIRS = [
    (f'`thinfilm_conductor` "{STACK}" on Au', {"type": "conductor", "material": "Au"},
     {"type": "thinfilm_conductor", "material": "Au", "layers": STACK}),
    (f'`thinfilm_roughconductor` "{STACK}" on Au, α 0.2',
     {"type": "roughconductor", "material": "Au", "alpha": 0.2},
     {"type": "thinfilm_roughconductor", "material": "Au", "alpha": 0.2, "layers": STACK}),
    (f'`thinfilm_dielectric` "{STACK}" on 1.6', {"type": "dielectric", "int_ior": 1.6},
     {"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": STACK}),
    (f'`thinfilm_dielectric` "{METALS}" on 1.6', {"type": "dielectric", "int_ior": 1.6},
     {"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": METALS}),
    (f'`thinfilm_roughdielectric` "{STACK}" on 1.6, α 0.2',
     {"type": "roughdielectric", "int_ior": 1.6, "alpha": 0.2},
     {"type": "thinfilm_roughdielectric", "int_ior": 1.6, "alpha": 0.2, "layers": STACK}),
    ('`thinfilm_diffuse` "SiO2 500; Au 5", model `exact`', {"type": "diffuse"},
     {"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"}),
    ('`thinfilm_diffuse` "SiO2 500; Au 5", model `single`', {"type": "diffuse"},
     {"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5", "model": "single"}),
]


def mode_of(scene) -> str:
    for shape in scene.shapes():
        b = shape.bsdf()
        stack = getattr(b, "stack", None) or getattr(b, "coating", None)
        if stack is not None:
            return stack.mode()
    return "–"


def timed_render(scene, seed: int) -> tuple[float, float]:
    """``(wall, cpu)`` seconds of one render of ``scene`` (the process's CPU time: all of
    Dr.Jit's threads)."""
    t, c = time.perf_counter(), time.process_time()
    render_sync(scene, seed=seed)
    return time.perf_counter() - t, time.process_time() - c


def alone(load, seed: int) -> tuple[float, float, str]:
    """Load a scene holding our (Python) BSDFs, render it and free it: ``(wall, cpu, mode)``
    of the render alone. While a Python BSDF is alive, Dr.Jit traces it into every render
    of its variant (a symbolic call records every registered instance), that of a scene
    which does not use it included: with every scene alive at once, each render paid for
    tracing every other plugin, and the ratios were pulled towards 1. Loads after the
    first find their tables in the process's own store and their kernels cached."""
    import gc
    scene = load()
    mode = mode_of(scene)
    render_sync(scene, seed=seed + 1000)   # untimed: what a load leaves for the first render
    wall, cpu = timed_render(scene, seed)
    del scene
    gc.collect()
    return wall, cpu, mode


def own_table_store() -> None:
    """A fresh table store for this process, so that a scene loaded again (:func:`alone`)
    reads its tables instead of building them (the builds are not what is timed)."""
    import tempfile
    os.environ["THINFILM_MI_TABLE_CACHE"] = tempfile.mkdtemp(prefix="plugin_bench_tables_")


def plugins_child(variant: str, repeats: int, res: int, spp: int) -> None:
    import mitsuba as mi
    mi.set_variant(variant)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    own_table_store()
    # Mitsuba's scenes stay loaded; the instances alive during each render are then the
    # same in the untimed first round (which compiles every kernel and builds the tables)
    # as in the timed ones
    natives = [mi.load_dict(scene_dict("", res, spp, bsdf=native)) for _, native, _ in PAIRS]
    loaders = [lambda ours=ours: mi.load_dict(scene_dict("", res, spp, bsdf=ours))
               for _, _, ours in PAIRS]
    modes = []
    for i, (label, _, _) in enumerate(PAIRS):
        render_sync(natives[i], seed=0)
        modes.append(alone(loaders[i], 0)[2])
        print(f"  {variant}: {label} loaded, mode {modes[-1]}", file=sys.stderr, flush=True)
    times = [[[], []] for _ in PAIRS]
    cpu = [[[], []] for _ in PAIRS]
    for r in range(repeats):
        for i in range(len(PAIRS)):
            for j in ((0, 1) if r % 2 == 0 else (1, 0)):
                if j == 0:
                    wall, used = timed_render(natives[i], r + 1)
                else:
                    wall, used, _ = alone(loaders[i], r + 1)
                times[i][j].append(wall)
                cpu[i][j].append(used)
    out = []
    for i, (label, _, _) in enumerate(PAIRS):
        native, ours = (np.array(x) for x in times[i])
        native_cpu, ours_cpu = (np.array(x) for x in cpu[i])
        out.append({"label": label, "mode": modes[i],
                    "native": float(np.median(native)), "ours": float(np.median(ours)),
                    "wall_ratio": float(np.median(ours / native)),
                    "ratio": float(np.median(ours_cpu / native_cpu))})
    print(json.dumps(out))


def twin_xml(xml: str) -> str:
    """The demo with Mitsuba's plugins: ``conductor`` of silicon's index at 550 nm
    (Mitsuba has no Si), ``dielectric`` on 1.6, ``diffuse`` of the same albedo."""
    subs = [
        (r'<bsdf type="thinfilm_conductor">.*?</bsdf>',
         '<bsdf type="conductor"><spectrum name="eta" value="4.08"/>'
         '<spectrum name="k" value="0.028"/></bsdf>'),
        (r'<bsdf type="thinfilm_dielectric">.*?</bsdf>',
         '<bsdf type="dielectric"><float name="int_ior" value="1.6"/></bsdf>'),
        (r'<bsdf type="thinfilm_diffuse">.*?</bsdf>',
         '<bsdf type="diffuse"><rgb name="reflectance" value="0.9, 0.9, 0.9"/></bsdf>'),
    ]
    for pattern, repl in subs:
        xml, n = re.subn(pattern, repl, xml, flags=re.S)
        assert n == 1, pattern
    return xml


def load_demo(which: str, size: str, spp: int):
    import mitsuba as mi
    with open(os.path.join(REPO, "scenes", "demo.xml"), encoding="utf-8") as f:
        xml = f.read()
    if which == "twin":
        xml = twin_xml(xml)
    mi.Thread.thread().file_resolver().prepend(os.path.join(REPO, "scenes"))
    w, h = size.split("x")
    return mi.load_string(xml, resx=w, resy=h, spp=str(spp))


def demo_first_child(which: str, size: str, spp: int) -> None:
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    scene = load_demo(which, size, spp)
    t1 = time.perf_counter()
    render_sync(scene, seed=0)
    print(json.dumps({"load": t1 - t0, "render": time.perf_counter() - t1}))


def demo_steady_child(repeats: int, size: str, spp: int) -> None:
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    own_table_store()
    twin = load_demo("twin", size, spp)          # Mitsuba's plugins only: stays loaded
    render_sync(twin, seed=0)
    alone(lambda: load_demo("ours", size, spp), 0)
    ts, cpu = [[], []], [[], []]
    for r in range(repeats):
        for j in ((0, 1) if r % 2 == 0 else (1, 0)):
            if j == 0:
                wall, used = timed_render(twin, r + 1)
            else:
                wall, used, _ = alone(lambda: load_demo("ours", size, spp), r + 1)
            ts[j].append(wall)
            cpu[j].append(used)
    twin, ours = (np.array(x) for x in ts)
    twin_cpu, ours_cpu = (np.array(x) for x in cpu)
    print(json.dumps({"twin": float(np.median(twin)), "ours": float(np.median(ours)),
                      "wall_ratio": float(np.median(ours / twin)),
                      "ratio": float(np.median(ours_cpu / twin_cpu))}))


def child(*args: str, script: str = __file__) -> dict | list:
    """``script`` (this file) run with ``args`` in a fresh process, the table store off: the
    JSON of its last line of output (its stderr passed on)."""
    env = dict(os.environ, THINFILM_MI_TABLE_CACHE="off")
    res = subprocess.run([sys.executable, os.path.abspath(script), *args], env=env,
                         capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(res.stderr[-3000:])
    sys.stderr.write(res.stderr)
    return json.loads(res.stdout.strip().splitlines()[-1])


def demo_first(repeats: int, size: str, spp: int) -> dict:
    for which in ("twin", "ours"):   # the kernel cache warm; tables are rebuilt per process
        child("--demo-first-child", which, "--demo-size", size, "--demo-spp", str(spp))
    runs = {"twin": [], "ours": []}
    for r in range(repeats):
        for which in (("twin", "ours") if r % 2 == 0 else ("ours", "twin")):
            runs[which].append(child("--demo-first-child", which, "--demo-size", size,
                                     "--demo-spp", str(spp)))
    total = {w: [x["load"] + x["render"] for x in v] for w, v in runs.items()}
    return {"twin": float(np.median(total["twin"])), "ours": float(np.median(total["ours"])),
            "ours_load": float(np.median([x["load"] for x in runs["ours"]])),
            "ratio": float(np.median(np.array(total["ours"]) / np.array(total["twin"])))}


def markdown(plugins: dict, demo: dict | None, args) -> str:
    import drjit as dr
    import mitsuba as mi
    lines = []
    if plugins:
        variants = list(plugins)
        lines += [f"Steady render time of each plugin against its Mitsuba counterpart "
                  f"(`benchmarks/plugin_bench.py`: the sphere scene of `render_bench.py`, "
                  f"{args.res}×{args.res}, {args.spp} spp, default settings; median over "
                  f"{args.repeats} rounds of the CPU-time ratio of back-to-back renders; Mitsuba "
                  f"{mi.__version__}, Dr.Jit {dr.__version__}, {dr.thread_count()} threads, a "
                  f"shared machine):", "",
                  "| plugin and stack | " + " | ".join(f"`{v}`" for v in variants)
                  + " | mode (spectral) |",
                  "|---|" + "---:|" * len(variants) + "---|"]
        for i, (label, _, _) in enumerate(PAIRS):
            cells = [f"{plugins[v][i]['ratio']:.2f}×" for v in variants]
            lines.append(f"| {label} | " + " | ".join(cells) + f" | {plugins[variants[0]][i]['mode']} |")
        lines.append("")
    if demo:
        s, f = demo.get("steady"), demo.get("first")
        text = f"`scenes/demo.xml` against its twin of Mitsuba plugins ({args.demo_size}, " \
               f"{args.demo_spp} spp, `llvm_ad_spectral`):"
        if s:
            text += (f" steady {s['ratio']:.2f}× in CPU time ({s['wall_ratio']:.2f}× wall clock: "
                     f"{s['ours']:.2f} s against {s['twin']:.2f} s; medians of "
                     f"{args.demo_repeats});")
        if f:
            text += (f" first image (fresh process, warm kernel cache, empty table store) "
                     f"{f['ratio']:.2f}× ({f['ours']:.2f} s, of which load {f['ours_load']:.2f} s, "
                     f"against {f['twin']:.2f} s, median of {args.first_repeats}).")
        lines += [text, ""]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--demo-repeats", type=int, default=5)
    ap.add_argument("--demo-size", default="512x341")
    ap.add_argument("--demo-spp", type=int, default=32)
    ap.add_argument("--first-repeats", type=int, default=3)
    ap.add_argument("--skip-plugins", action="store_true")
    ap.add_argument("--skip-demo", action="store_true")
    ap.add_argument("--skip-first", action="store_true")
    ap.add_argument("--write-docs", action="store_true")
    ap.add_argument("--from-json", help="the JSON line a run wrote to stderr: print (and with "
                    "--write-docs write) its tables without measuring again; the other "
                    "options must be the run's")
    ap.add_argument("--plugins-child")
    ap.add_argument("--demo-first-child")
    ap.add_argument("--demo-steady-child", action="store_true")
    args = ap.parse_args()
    if args.plugins_child:
        return plugins_child(args.plugins_child, args.repeats, args.res, args.spp)
    if args.demo_first_child:
        return demo_first_child(args.demo_first_child, args.demo_size, args.demo_spp)
    if args.demo_steady_child:
        return demo_steady_child(args.demo_repeats, args.demo_size, args.demo_spp)
    plugins, demo = {}, {}
    header = docs_output.provenance()   # the machine and its load at the start
    if args.from_json:
        with open(args.from_json, encoding="utf-8") as f:
            data = json.loads(f.read().strip().splitlines()[-1])
        plugins, demo = data["plugins"], data["demo"]
        header = data.get("provenance", f"From {args.from_json}, a run that did not record its machine.")
        args.skip_plugins = args.skip_demo = True
    if not args.skip_plugins:
        for v in args.variants.split(","):
            plugins[v] = child("--plugins-child", v, "--repeats", str(args.repeats),
                               "--res", str(args.res), "--spp", str(args.spp))
    if not args.skip_demo:
        demo["steady"] = child("--demo-steady-child", "--demo-repeats", str(args.demo_repeats),
                               "--demo-size", args.demo_size, "--demo-spp", str(args.demo_spp))
        if not args.skip_first:
            demo["first"] = demo_first(args.first_repeats, args.demo_size, args.demo_spp)
    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    text = markdown(plugins, demo, args)
    print(text)
    print(json.dumps({"plugins": plugins, "demo": demo, "provenance": header}), file=sys.stderr)
    if args.write_docs:
        docs_output.write("plugin_bench", text, header)


if __name__ == "__main__":
    main()
