"""Deep stacks (issue 32): load time at every depth, steady render against Mitsuba's
``conductor``, the exact evaluation's cost per film, and the share of a gradient
descent spent in table builds.

    python benchmarks/deep_bench.py [--rounds 3] [--only loads|steady|descent|edits|ratios]

Stacks: the Al stacks of render_bench.py (2.3/1.46 films, 50-200 nm from
``default_rng(6)``), default settings (``tabulate="auto"``, ``spectral_resolution``
1 nm), variant llvm_ad_spectral.

1. Loads: ``mi.load_dict`` of the BSDF in a fresh process per load (empty table
   cache; the build kernels compiled by a first load of a 2-film stack), --rounds
   round-robin rounds over 10, 30, 100, 300, 1000 films, medians; what the build did.
2. Steady: the sphere scene of render_bench.py, 128x128, 16 spp; ``conductor`` against
   100, 300, 1000 films, and 100 films with ``tabulate=true`` (its load printed), timed by
   ``timing.pair_rounds`` (each scene of ours loaded alone for its render and freed:
   a live Python BSDF is traced into every render; an untimed round, then --rounds
   rounds of back-to-back pairs), medians; the exact evaluation's cost per film from the
   slope between 100 and 1000 films. ``thinfilm_conductor`` only: what a deep stack costs
   is its evaluation (the per-film loop or its table), which this bench measures; every
   plugin against its counterpart, up to 30 films, is ``render_bench.py``'s.
3. Descent: 50 steps of gradient descent on the first film's thickness of the
   30-film stack (32x32, 1 spp, ``prb``-free ``path`` integrator, a fixed target
   image); total time and time spent in ``stack_build.build_tables``.
4. Edits: the sphere scene at the issue's 128x128, 8 spp, 1, 10 and 30 films at
   default settings and with ``tabulate`` false; a plain render (median of
   --rounds + 2) against a thickness edit through ``mi.traverse(scene)`` (a new
   value each time, so no table comes from a cache) + ``params.update()`` + the
   render (median of as many; the first edit, which may compile the kernel of another
   route, also alone).
5. Ratios to ``conductor`` at 10 and 30 films (128x128, 8 spp, default settings): the
   first image (``timing.first_images``: a fresh process, an empty kernel cache and no
   table store, ``mi.load_dict`` + the first render; the run with the median total of
   --rounds) in llvm_ad_spectral, and the steady render (``timing.pair_rounds``, --rounds
   rounds) in llvm_ad_spectral and llvm_ad_spectral_polarized, each variant in a process
   of its own.

The table store on disk is off (builds are what is timed) unless the environment
names one.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
# this checkout's package, not an installed one
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
os.environ.setdefault("THINFILM_MI_TABLE_CACHE", "off")

DEPTHS = (10, 30, 100, 300, 1000)


def layers(L: int) -> str:
    d = np.random.default_rng(6).uniform(50.0, 200.0, L)
    return "; ".join(f"{2.3 if i % 2 == 0 else 1.46} {float(d[i])!r}" for i in range(L))


def bsdf(L: int) -> dict:
    return {"type": "thinfilm_conductor", "material": "Al", "layers": layers(L)}


def load_child(L: int) -> dict:
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    import thinfilm_mi  # noqa: F401
    mi.load_dict(bsdf(2))                 # the build kernels
    t = time.perf_counter()
    b = mi.load_dict(bsdf(L))
    dt = time.perf_counter() - t
    rep = b.stack.plan[False].build_report or {}
    return {"load": dt, "result": rep.get("result"), "points": rep.get("points"),
            "exact": (rep.get("exact_attempt") or {}).get("result")}


def loads(rounds: int) -> None:
    res = {L: [] for L in DEPTHS}
    for _ in range(rounds):
        for L in DEPTHS:
            out = subprocess.run([sys.executable, __file__, "--child", str(L)], capture_output=True,
                                 text=True, check=True).stdout
            res[L].append(json.loads(out.strip().splitlines()[-1]))
    print("\n### Loads at default settings (fresh process each)\n")
    print("| films | load (s), median | band-limited build | exact attempt | exact evaluations |")
    print("|---:|---:|---|---|---:|")
    for L in DEPTHS:
        r = res[L]
        print(f"| {L} | {statistics.median(x['load'] for x in r):.2f} | {r[0]['result']} | "
              f"{r[0]['exact']} | {r[0]['points']} |")


def steady(rounds: int) -> None:
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    import render_bench as rb
    from timing import own_table_store, pair_rounds

    import thinfilm_mi  # noqa: F401
    own_table_store()
    configs = {100: bsdf(100), 300: bsdf(300), 1000: bsdf(1000),
               "100 tabulate=true": dict(bsdf(100), tabulate=True)}
    t = time.perf_counter()
    mi.load_dict(configs["100 tabulate=true"])   # its build (into the store), then dropped
    print(f"100 films with tabulate=true: load {time.perf_counter() - t:.2f} s")
    conductor = mi.load_dict(rb.scene_dict("conductor", 128, 16))
    loaders = [lambda d=d: mi.load_dict(rb.scene_dict("", 128, 16, bsdf=d)) for d in configs.values()]
    rows = dict(zip(configs, pair_rounds([conductor] * len(configs), loaders, rounds)))
    print(f"\n### Steady render, 128x128, 16 spp (medians of {rounds} rounds of back-to-back "
          "pairs, our scene loaded alone)\n")
    print("| config | mode | time (s) | conductor (s) | CPU-time ratio to conductor |")
    print("|---|---|---:|---:|---:|")
    for c, row in rows.items():
        print(f"| {c} | {row['mode']} | {row['ours']:.3f} | {row['native']:.3f} | "
              f"{row['ratio']:.2f} |")
    per_film = (rows[1000]["ours"] - rows[100]["ours"]) / 900
    print(f"\nExact evaluation: {1e3 * per_film:.2f} ms per film per render "
          f"({1e9 * per_film / (128 * 128 * 16):.2f} ns per film per sample).")


def descent() -> None:
    import drjit as dr
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    import render_bench as rb

    import thinfilm_mi  # noqa: F401
    from thinfilm_mi.render import stack_build
    spent = [0.0]
    build_tables = stack_build.build_tables

    def timed(*args, **kwargs):   # whatever the builder takes
        t = time.perf_counter()
        out = build_tables(*args, **kwargs)
        spent[0] += time.perf_counter() - t
        return out
    stack_build.build_tables = timed
    s = rb.scene_dict("conductor", 32, 1)
    s["sphere"]["bsdf"] = bsdf(30)
    scene = mi.load_dict(s)
    target = mi.render(scene, seed=0)
    params = mi.traverse(scene)
    key = "sphere.bsdf.layers.0.thickness"
    opt = mi.ad.Adam(lr=2.0)
    opt[key] = mi.Float(params[key][0] + 20.0)
    params.update(opt)
    spent[0] = 0.0
    t = time.perf_counter()
    for i in range(50):
        img = mi.render(scene, params, seed=i + 1)
        loss = dr.mean(dr.square(img - target), axis=None)
        dr.backward(loss)
        opt.step()
        params.update(opt)
    total = time.perf_counter() - t
    print("\n### Gradient descent, 30 films, 50 steps (32x32, 1 spp)\n")
    print(f"total {total:.2f} s, in table planning/builds {spent[0]:.3f} s "
          f"({100 * spent[0] / total:.1f} %)")


def edits(rounds: int) -> None:
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    import render_bench as rb

    import thinfilm_mi  # noqa: F401
    n = rounds + 2
    print("\n### A thickness edit + render against a plain render (128x128, 8 spp, "
          f"medians of {n})\n")
    print("| films | mode | plain render (s) | edit + render (s) | ratio | first edit + render (s) "
          "| mode after edits | the edit's build |")
    print("|---:|---|---:|---:|---:|---:|---|---|")
    for L in (1, 10, 30):
        for exact in (False, True):
            s = rb.scene_dict("conductor", 128, 8)
            s["sphere"]["bsdf"] = dict(bsdf(L), **({"tabulate": False} if exact else {}))
            scene = mi.load_dict(s)
            mode = scene.shapes()[0].bsdf().stack.mode()
            rb.render_sync(scene, seed=0)
            plain = []
            for i in range(n):
                t = time.perf_counter()
                rb.render_sync(scene, seed=i + 1)
                plain.append(time.perf_counter() - t)
            params = mi.traverse(scene)
            key = "sphere.bsdf.layers.0.thickness"
            base = float(params[key][0])
            edit = []
            for i in range(n):
                t = time.perf_counter()
                params[key] = base + 0.25 * (i + 1)
                params.update()
                rb.render_sync(scene, seed=i + 1)
                edit.append(time.perf_counter() - t)
            stack = scene.shapes()[0].bsdf().stack
            report = stack.plan[False].build_report or {}
            a, b = statistics.median(plain), statistics.median(edit)
            print(f"| {L} | {mode} | {a:.3f} | {b:.3f} | {b / a:.2f} | {edit[0]:.3f} | "
                  f"{stack.mode()} | {report.get('result', '-')} |", flush=True)
            del scene, params, stack   # alive, it would be traced into the next scenes' renders
            gc.collect()


RATIO_FILMS = (10, 30)
RATIO_VARIANTS = ("llvm_ad_spectral", "llvm_ad_spectral_polarized")


def ratio_scene(config: str) -> dict:
    """The 128x128, 8 spp sphere scene of ``"conductor"`` or of ``"L"`` films."""
    import render_bench as rb
    return rb.scene_dict("conductor", 128, 8, bsdf=None if config == "conductor"
                         else bsdf(int(config)))


def first_image_child(config: str) -> None:
    """Runs in the subprocess: ``mi.load_dict`` + the first render, timed."""
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    from timing import mode_of, render_sync

    import thinfilm_mi  # noqa: F401
    t0 = time.perf_counter()
    scene = mi.load_dict(ratio_scene(config))
    t1 = time.perf_counter()
    render_sync(scene, seed=0)
    print(json.dumps({"load": t1 - t0, "render": time.perf_counter() - t1,
                      "mode": mode_of(scene)}))


def steady_child(variant: str, rounds: int) -> None:
    """Runs in the subprocess: ``conductor`` against each depth, steady."""
    import mitsuba as mi
    mi.set_variant(variant)
    from timing import own_table_store, pair_rounds

    import thinfilm_mi  # noqa: F401
    own_table_store()
    native = mi.load_dict(ratio_scene("conductor"))
    loaders = [lambda L=L: mi.load_dict(ratio_scene(str(L))) for L in RATIO_FILMS]
    print(json.dumps(pair_rounds([native] * len(RATIO_FILMS), loaders, rounds)))


def ratios(rounds: int) -> None:
    from timing import child, first_images
    configs = ["conductor"] + [str(L) for L in RATIO_FILMS]
    runs = first_images(__file__, configs, rounds)
    base = runs["conductor"]["load"] + runs["conductor"]["render"]
    print("\n### Against `conductor`, 128x128, 8 spp, default settings\n")
    print("| films | measure | variant | mode | ours (s) | conductor (s) | ratio |")
    print("|---:|---|---|---|---:|---:|---:|")
    for L in RATIO_FILMS:
        r = runs[str(L)]
        print(f"| {L} | first image (load {r['load']:.2f} + render {r['render']:.2f} s; "
              f"median of {rounds} fresh processes) | llvm_ad_spectral | {r['mode']} | "
              f"{r['load'] + r['render']:.2f} | {base:.2f} | {(r['load'] + r['render']) / base:.2f} |",
              flush=True)
    for v in RATIO_VARIANTS:
        rows = child(__file__, "--steady-child", v, "--rounds", str(rounds))
        for L, row in zip(RATIO_FILMS, rows):
            print(f"| {L} | steady (CPU time, median of {rounds} pairs) | {v} | {row['mode']} | "
                  f"{row['ours']:.3f} | {row['native']:.3f} | {row['ratio']:.2f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--only", choices=("loads", "steady", "descent", "edits", "ratios"))
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--first-image-child", help=argparse.SUPPRESS)
    ap.add_argument("--steady-child", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(load_child(a.child)))
        return
    if a.first_image_child:
        return first_image_child(a.first_image_child)
    if a.steady_child:
        return steady_child(a.steady_child, a.rounds)
    if a.only in (None, "loads"):
        loads(a.rounds)
    if a.only in (None, "steady"):
        steady(a.rounds)
    if a.only in (None, "descent"):
        descent()
    if a.only in (None, "edits"):
        edits(a.rounds)
    if a.only in (None, "ratios"):
        ratios(a.rounds)


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("deep_bench"):   # --write-docs: docs/_generated/deep_bench.md
        main()
