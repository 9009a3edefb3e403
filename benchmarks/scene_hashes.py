"""A hash of every shipped scene's image at a fixed seed, in each variant family.

    python benchmarks/scene_hashes.py [--out hashes.json] [--compare OLD.json]
                                      [--size 96x64] [--spp 4]
                                      [--images DIR] [--compare-images OLD_DIR]

Written to check that a change which should not touch the arithmetic (a move of
code between modules) leaves every image bit-identical. Each scene is loaded
through ``thinfilm-render``'s loader at ``--size`` and ``--spp`` and rendered with
seed 0 in ``llvm_ad_spectral``, ``llvm_ad_rgb`` and ``llvm_ad_spectral_polarized``
(a scene a variant cannot render is recorded with its error). Dr.Jit renders on
one thread: with several, the order in which threads add samples into a pixel varies,
and with it the last bit of ~1 pixel in a render of some scenes.

Each scene renders in a fresh process per variant (``--child``), so that kernels
and tables built for one scene are not reused by the next; the children import the
package of this checkout (``PYTHONPATH``), not an installed one.

A change that moves the arithmetic slightly (a material resampled within its stated
bound) is checked with ``--images DIR`` (each image saved as ``DIR/variant/scene.npy``)
against the images of the previous commit (``--compare-images OLD_DIR``): see
:func:`image_difference` for the tolerance.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
VARIANTS = ("llvm_ad_spectral", "llvm_ad_rgb", "llvm_ad_spectral_polarized")


#: Largest mean absolute difference between two renders of a scene, relative to the
#: image's mean, for a change that moves indices by at most 1e-4 (the materials'
#: resampling bound): a reflectance moves by at most about that much per unit of index
#: (|dR/dn|, |dR/dk| stay below ~1 for the shipped stacks, phase included for films of a
#: few hundred nm), so no pixel moves by more than ~1e-4 of its value; a lobe choice that
#: flips on a rare path is an outlier the mean absorbs
IMAGE_RTOL = 1e-4

#: Seconds a variant's child may take (its 15 scenes render in well under a minute on a
#: shared 2-core machine): a child was seen waiting on a lock for good while it loaded a
#: scene with an EXR texture (rough_films.xml) right after a one-thread render, so the
#: run stops with a message instead of blocking its caller
CHILD_TIMEOUT = 600


def image_difference(new, old) -> float:
    """Mean absolute difference of two images relative to the old one's mean."""
    import numpy as np
    return float(np.mean(np.abs(new - old)) / max(float(np.mean(np.abs(old))), 1e-12))


def compare_images(new_dir: Path, old_dir: Path) -> int:
    """Print each scene's :func:`image_difference` to its image in ``old_dir``; the
    number of images over :data:`IMAGE_RTOL` (or missing from either side)."""
    import numpy as np
    bad = 0
    for new in sorted(new_dir.glob("*/*.npy")):
        old = old_dir / new.parent.name / new.name
        if not old.exists():
            print(f"MISSING {new.parent.name}/{new.name} in {old_dir}")
            bad += 1
            continue
        d = image_difference(np.load(new), np.load(old))
        flag = "OVER " if d > IMAGE_RTOL else ""
        bad += d > IMAGE_RTOL
        print(f"{flag}{new.parent.name:28s} {new.stem:34s} {d:.2e}")
    print(f"{bad} images over {IMAGE_RTOL:g} (mean |difference| / mean)")
    return bad


def child(variant: str, size: str, spp: int, images: str | None = None) -> dict:
    import drjit as dr
    import mitsuba as mi
    import numpy as np

    mi.set_variant(variant)
    threads = dr.thread_count()
    import thinfilm_mi  # noqa: F401  (registers the plugins)
    from thinfilm_mi.batch.scene import load_scene

    w, h = (int(x) for x in size.split("x"))
    out = {}
    for path in sorted((REPO / "scenes").glob("*.xml")):
        try:
            # loading runs plugin constructors on the thread pool (one thread
            # there can deadlock it): one thread for the render only
            dr.set_thread_count(threads)
            scene = load_scene(path, size=(w, h), spp=spp)
            dr.set_thread_count(1)
            image = np.ascontiguousarray(np.array(mi.render(scene, seed=0), dtype=np.float32))
            out[path.name] = hashlib.sha256(image.tobytes()).hexdigest()[:16]
            if images:
                folder = Path(images) / variant
                folder.mkdir(parents=True, exist_ok=True)
                np.save(folder / f"{path.stem}.npy", image)
        except Exception as e:  # noqa: BLE001 - recorded, e.g. a stokes scene in RGB
            out[path.name] = "error: " + str(e).splitlines()[0][:120]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", help="write the hashes to this JSON file")
    ap.add_argument("--compare", help="a JSON file written before: list the differences")
    ap.add_argument("--size", default="96x64")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--images", help="save each image as IMAGES/variant/scene.npy")
    ap.add_argument("--compare-images", help="a folder --images wrote before: compare with "
                    "a tolerance (needs --images)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.size, args.spp, args.images)))
        return 0
    hashes = {}
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    extra = ["--images", str(Path(args.images).resolve())] if args.images else []
    for variant in VARIANTS:
        try:
            res = subprocess.run([sys.executable, __file__, "--child", variant, "--size",
                                  args.size, "--spp", str(args.spp)] + extra,
                                 capture_output=True, text=True, cwd=REPO, env=env,
                                 timeout=CHILD_TIMEOUT)
        except subprocess.TimeoutExpired as e:
            done = (e.stdout or b"").decode(errors="replace") if isinstance(e.stdout, bytes) \
                else (e.stdout or "")
            print(f"{variant}: no result within {CHILD_TIMEOUT} s (a child that hangs while it "
                  f"loads a scene; run again){done and ': ' + done[-200:]}", file=sys.stderr)
            return 2
        if res.returncode:
            print(res.stderr, file=sys.stderr)
            return res.returncode
        hashes[variant] = json.loads(res.stdout.strip().splitlines()[-1])
    if args.out:
        Path(args.out).write_text(json.dumps(hashes, indent=1, sort_keys=True) + "\n")
    for variant, scenes in hashes.items():
        for name, h in scenes.items():
            print(f"{variant:28s} {name:34s} {h}")
    if args.compare:
        old = json.loads(Path(args.compare).read_text())
        diff = [(v, n, old.get(v, {}).get(n), h) for v, s in hashes.items() for n, h in s.items()
                if old.get(v, {}).get(n) != h]
        for v, n, a, b in diff:
            print(f"DIFFERS {v} {n}: {a} -> {b}")
        print(f"{len(diff)} of {sum(len(s) for s in hashes.values())} images differ")
        if not args.compare_images:
            return 1 if diff else 0
    if args.compare_images and args.images:
        return 1 if compare_images(Path(args.images), Path(args.compare_images)) else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
