"""Frames per minute of a 24-frame parameter sweep: ``thinfilm-render sweep`` on a
local Dask cluster of 1 and 2 worker processes against sequential
``thinfilm-render`` runs (one process per frame, as a shell loop does).

    python benchmarks/sweep_bench.py [--size 160x106] [--spp 16] [--frames 24]

Cases (each into a fresh temporary folder, wall-clock time from the command's
start to its end, cluster start-up and worker imports included):

1. sequential: ``thinfilm-render scenes/demo.xml -D sio2=V`` once per frame
   (every frame pays Python + Mitsuba imports, scene load and the kernel
   compile, the latter from Dr.Jit's disk cache after the first process);
2. ``sweep -D sio2=...`` on scenes/demo.xml with ``--workers 1`` and ``2``
   (each frame loads its scene: ``-D`` values are XML parameters);
3. fig8a (one film on a teapot) swept over the film thickness as a ``-D``
   (scene loaded per frame) and as a ``-P`` ``mi.traverse`` key (scene loaded
   once per task, no kernel compiled after a task's first frame), 2 workers.
   fig8a's shape has no id, so a copy of the scene with ``id="teapot"`` is made
   in the temporary folder (its include/ and meshes/ linked to scenes/).

Then the cost of one demo frame in this process: scene load, first render
(kernel compile or disk-cache load), a second render of the loaded scene, and
the EXR + PNG write; and the imports a fresh process pays.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SCENES = REPO / "scenes"
_SCRIPT = Path(sys.executable).parent / "thinfilm-render"  # the console script of this environment
RENDER = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "thinfilm_mi.cli.render"]


def values(frames: int, start: int = 100, step: int = 30) -> str:
    return f"{start}:{start + step * (frames - 1)}:{step}"


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def sequential(tmp: Path, frames: int, size: str, spp: int) -> float:
    def run():
        for i in range(frames):
            v = 100 + 30 * i
            subprocess.run([*RENDER, str(SCENES / "demo.xml"), "-D", f"sio2={v}", "--size", size,
                            "--spp", str(spp), "-o", str(tmp / "seq" / f"sio2={v}.exr")],
                           check=True, capture_output=True, timeout=600)
    return timed(run)[0]


def swept(scene: Path, out: Path, workers: int, size: str, spp: int, defines=None, parameters=None):
    from thinfilm_mi.batch import sweeps

    seconds, result = timed(lambda: sweeps.sweep(scene, defines, parameters, out, workers=workers,
                                                 size=size, spp=spp, contact_sheet=False,
                                                 timeout=1200))
    assert not result.failed, result.failed
    return seconds, result


def fig8a_with_id(tmp: Path) -> Path:
    folder = tmp / "fig8a"
    folder.mkdir()
    for name in ("include", "meshes"):
        (folder / name).symlink_to(SCENES / name)
    text = (SCENES / "fig8a_si_sio2.xml").read_text()
    text = text.replace('<shape type="ply">', '<shape type="ply" id="teapot">', 1)
    path = folder / "fig8a_teapot.xml"
    path.write_text(text)
    return path


def frame_costs(tmp: Path, size: str, spp: int) -> dict[str, float]:
    import mitsuba as mi

    from thinfilm_mi.batch import exr
    from thinfilm_mi.batch import scene as tf_scene

    imports = timed(lambda: subprocess.run(
        [sys.executable, "-c", "import mitsuba as mi; mi.set_variant('llvm_ad_spectral'); "
                               "import thinfilm_mi"], check=True, timeout=600))[0]
    tf_scene.setup_variant(tf_scene.DEFAULT_VARIANT)
    mi.set_log_level(mi.LogLevel.Error)
    w, h = tf_scene.parse_size(size)
    load, scene = timed(lambda: tf_scene.load_scene(SCENES / "demo.xml", {"sio2": "437"}, size=(w, h), spp=spp))
    first, (image, channels, _, _) = timed(lambda: tf_scene.render_scene(scene, spp, seed=1))
    second = timed(lambda: tf_scene.render_scene(scene, spp, seed=2))[0]
    write = timed(lambda: (exr.write_exr(tmp / "one.exr", image, channels, {}),
                           exr.write_png(tmp / "one.png", image, channels)))[0]
    return {"imports (new process)": imports, "scene load": load, "first render": first,
            "render, scene loaded": second, "EXR + PNG write": write}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="160x106")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--skip-sequential", action="store_true")
    args = parser.parse_args(argv)
    n = args.frames
    import drjit as dr
    import mitsuba as mi

    print(f"{n} frames, {args.size}, {args.spp} spp, llvm_ad_spectral; Mitsuba {mi.__version__}, "
          f"Dr.Jit {dr.__version__}, {os.cpu_count()} cores")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if not args.skip_sequential:
            rows.append(("sequential thinfilm-render (demo, -D)", 1, sequential(tmp, n, args.size, args.spp)))
        for workers in (1, 2):
            s, _ = swept(SCENES / "demo.xml", tmp / f"demo{workers}", workers, args.size, args.spp,
                         defines={"sio2": values(n)})
            rows.append((f"sweep -D (demo), {workers} worker(s)", workers, s))
        fig8a = fig8a_with_id(tmp)
        s, _ = swept(fig8a, tmp / "fig8a_D", 2, args.size, args.spp, defines={"thickness": values(n)})
        rows.append(("sweep -D (fig8a), 2 workers", 2, s))
        s, res = swept(fig8a, tmp / "fig8a_P", 2, args.size, args.spp,
                       parameters={"teapot.bsdf.layers.0.thickness": values(n)})
        loads = sum(r["scene_loaded"] for r in res)
        compiled = sum(r["kernels"] for r in res if not r["scene_loaded"])
        rows.append((f"sweep -P (fig8a), 2 workers [{loads} scene loads, {compiled} kernels "
                     "after a task's first frame]", 2, s))
        costs = frame_costs(tmp, args.size, args.spp)
    base = rows[0][2] if not args.skip_sequential else None
    print(f"\n{'case':<72} {'seconds':>8} {'frames/min':>11} {'speed-up':>9}")
    for name, _, s in rows:
        speed = f"{base / s:.2f}x" if base and "demo" in name else "-"  # same scene only
        print(f"{name:<72} {s:8.1f} {n / s * 60:11.1f} {speed:>9}")
    print("\none demo frame, in one process:")
    for name, s in costs.items():
        print(f"  {name:<24} {s:6.2f} s")
    return 0


if __name__ == "__main__":
    from docs_output import write_docs_option

    with write_docs_option("sweep_bench"):   # --write-docs: docs/_generated/sweep_bench.md
        code = main()
    sys.exit(code)
