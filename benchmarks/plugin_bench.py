"""Every thin-film plugin against its Mitsuba counterpart, in spectral, RGB and
polarized variants, and the demo scene against its native twin.

    python benchmarks/plugin_bench.py [--repeats 5] [--res 256] [--spp 16]
                                      [--variants llvm_ad_spectral,llvm_ad_rgb,llvm_ad_spectral_polarized]
                                      [--demo-repeats 5] [--demo-size 512x341] [--demo-spp 32]
                                      [--first-repeats 3] [--skip-plugins] [--skip-demo]
                                      [--write-docs]

1. Per plugin: the sphere scene of ``timing.py`` (a sphere on a diffuse floor under a
   constant emitter, ``path`` with max depth 8, --res x --res, --spp spp, box filter)
   with the sphere's BSDF (or the sky's spectrum) one of :data:`PAIRS`: a thin-film plugin
   at default settings, and its Mitsuba counterpart; ``thinfilm_coating`` against
   ``plastic`` (no films over ``diffuse``) and against its rough base alone (Mitsuba has no
   coating of films); ``thinfilm_blackbody`` against ``blackbody`` in spectral variants
   only (Mitsuba's refuses the others). Each variant runs in a process of its own, timed
   by ``timing.pair_rounds``: every scene of ours loaded alone for its render (after one
   untimed render) and freed, Mitsuba's scenes loaded throughout (a live Python BSDF is
   traced into every render of the process, the native scenes' included); an untimed
   round (compiles, builds the tables), then --repeats rounds in which each pair renders
   back to back (native first in even rounds, ours first in odd ones), different seeds.
   The ratio of a pair is the median over the rounds of the round's ratio of the
   process's CPU time (all of Dr.Jit's threads; steadier than the wall clock on a shared
   machine, where a slow spell also hits both renders of a pair alike); the wall-clock
   ratio is in the JSON on stderr. Stacks at other depths and ``tabulate`` settings:
   ``render_bench.py``.
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
import sys
import time
import warnings
from dataclasses import dataclass

import numpy as np

os.environ.setdefault("THINFILM_MI_TABLE_CACHE", "off")

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
sys.path.insert(0, HERE)
import docs_output  # noqa: E402
from timing import child, own_table_store, pair_rounds, render_sync, sphere_scene  # noqa: E402

VARIANTS = ("llvm_ad_spectral", "llvm_ad_rgb", "llvm_ad_spectral_polarized")
STACK = "SiO2 500"
METALS = "SiO2 500; Au 20; Al 10"


@dataclass(frozen=True)
class Pair:
    """A scene of ours and its twin of Mitsuba's plugins: the sphere's BSDFs (``native``,
    ``ours``), or the sky's spectra (``native_radiance``, ``ours_radiance``; the sphere
    ``native`` in both); ``spectral_only``: Mitsuba's plugin refuses the other variants."""

    label: str
    native: dict
    ours: dict
    native_radiance: dict | None = None
    ours_radiance: dict | None = None
    spectral_only: bool = False

    def applies(self) -> bool:
        import mitsuba as mi
        return mi.is_spectral or not self.spectral_only

    @staticmethod
    def scene(bsdf: dict, radiance: dict | None, res: int, spp: int) -> dict:
        return sphere_scene(bsdf, res, spp, radiance=radiance)


_ROUGH_AU = {"type": "roughconductor", "material": "Au", "alpha": 0.2}
_WHITE = {"type": "diffuse", "reflectance": 0.5}

#: issue 44's scenes, and the coating and black body of the same sphere scene.
PAIRS = [
    Pair(f'`thinfilm_conductor` "{STACK}" on Au', {"type": "conductor", "material": "Au"},
         {"type": "thinfilm_conductor", "material": "Au", "layers": STACK}),
    Pair(f'`thinfilm_roughconductor` "{STACK}" on Au, α 0.2', _ROUGH_AU,
         {"type": "thinfilm_roughconductor", "material": "Au", "alpha": 0.2, "layers": STACK}),
    Pair(f'`thinfilm_dielectric` "{STACK}" on 1.6', {"type": "dielectric", "int_ior": 1.6},
         {"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": STACK}),
    Pair(f'`thinfilm_dielectric` "{METALS}" on 1.6', {"type": "dielectric", "int_ior": 1.6},
         {"type": "thinfilm_dielectric", "int_ior": 1.6, "layers": METALS}),
    Pair(f'`thinfilm_roughdielectric` "{STACK}" on 1.6, α 0.2',
         {"type": "roughdielectric", "int_ior": 1.6, "alpha": 0.2},
         {"type": "thinfilm_roughdielectric", "int_ior": 1.6, "alpha": 0.2, "layers": STACK}),
    Pair('`thinfilm_diffuse` "SiO2 500; Au 5", model `exact`', {"type": "diffuse"},
         {"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"}),
    Pair('`thinfilm_diffuse` "SiO2 500; Au 5", model `single`', {"type": "diffuse"},
         {"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5", "model": "single"}),
    # no films, the clear coat over a Lambertian base: plastic with its nonlinear term
    Pair("`thinfilm_coating`, no films, `int_ior` 1.5 over `diffuse` 0.5 (against `plastic`, "
         "`nonlinear`)",
         {"type": "plastic", "int_ior": 1.5, "nonlinear": True, "diffuse_reflectance": 0.5},
         {"type": "thinfilm_coating", "int_ior": 1.5, "layers": "", "bsdf": _WHITE}),
    # films over a rough base: Mitsuba has no coating of films; the base alone
    Pair(f'`thinfilm_coating` "{STACK}", `int_ior` 1.5 over `roughconductor` Au, α 0.2 (against '
         f"the base alone)", _ROUGH_AU,
         {"type": "thinfilm_coating", "int_ior": 1.5, "layers": STACK, "bsdf": _ROUGH_AU}),
    Pair("`thinfilm_blackbody` 4000 K as the sky's radiance (against `blackbody`; Mitsuba's "
         "refuses RGB)", _WHITE, _WHITE,
         {"type": "blackbody", "temperature": 4000.0},
         {"type": "thinfilm_blackbody", "temperature": 4000.0}, spectral_only=True),
]


def plugins_child(variant: str, repeats: int, res: int, spp: int) -> None:
    import mitsuba as mi
    mi.set_variant(variant)
    import thinfilm_mi  # noqa: F401
    warnings.simplefilter("ignore")
    own_table_store()
    pairs = [p for p in PAIRS if p.applies()]
    natives = [mi.load_dict(p.scene(p.native, p.native_radiance, res, spp)) for p in pairs]
    loaders = [lambda p=p: mi.load_dict(p.scene(p.ours, p.ours_radiance, res, spp)) for p in pairs]
    rows = pair_rounds(natives, loaders, repeats, progress=variant)
    print(json.dumps([dict(row, label=p.label) for p, row in zip(pairs, rows)]))


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
    row = pair_rounds([twin], [lambda: load_demo("ours", size, spp)], repeats)[0]
    print(json.dumps({"twin": row["native"], "ours": row["ours"],
                      "wall_ratio": row["wall_ratio"], "ratio": row["ratio"]}))


def demo_first(repeats: int, size: str, spp: int) -> dict:
    for which in ("twin", "ours"):   # the kernel cache warm; tables are rebuilt per process
        child(__file__, "--demo-first-child", which, "--demo-size", size, "--demo-spp", str(spp))
    runs = {"twin": [], "ours": []}
    for r in range(repeats):
        for which in (("twin", "ours") if r % 2 == 0 else ("ours", "twin")):
            runs[which].append(child(__file__, "--demo-first-child", which, "--demo-size", size,
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
                  f"(`benchmarks/plugin_bench.py`: the sphere scene of `benchmarks/timing.py`, "
                  f"{args.res}×{args.res}, {args.spp} spp, default settings; median over "
                  f"{args.repeats} rounds of the CPU-time ratio of back-to-back renders; Mitsuba "
                  f"{mi.__version__}, Dr.Jit {dr.__version__}, {dr.thread_count()} threads, a "
                  f"shared machine):", "",
                  "| plugin and stack | " + " | ".join(f"`{v}`" for v in variants)
                  + " | mode (first variant) |",
                  "|---|" + "---:|" * len(variants) + "---|"]
        rows = {v: {row["label"]: row for row in plugins[v]} for v in variants}
        for pair in PAIRS:
            cells = [f"{rows[v][pair.label]['ratio']:.2f}×" if pair.label in rows[v] else "–"
                     for v in variants]
            first = next((rows[v][pair.label] for v in variants if pair.label in rows[v]), None)
            if first is not None:
                lines.append(f"| {pair.label} | " + " | ".join(cells) + f" | {first['mode']} |")
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
            plugins[v] = child(__file__, "--plugins-child", v, "--repeats", str(args.repeats),
                               "--res", str(args.res), "--spp", str(args.spp))
    if not args.skip_demo:
        demo["steady"] = child(__file__, "--demo-steady-child", "--demo-repeats", str(args.demo_repeats),
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
