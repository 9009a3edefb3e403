#!/usr/bin/env python3
"""Build the two assets of scenes/fig9d_clay_oxide.xml (a clay teapot under an uneven
oxide film):

* ``scenes/textures/oxide_thickness.png``: the film-thickness scale, an 8-bit grey
  PNG of smooth band-limited noise (the random plane waves of
  ``make_soap_film_texture.plane_wave_noise``, one step of domain warping) mapped to
  ``[LO, HI]`` = [0.35, 1.0] and stored as ``pixel = 255 * value``; the scene reads it
  with ``raw="true"`` (value = pixel / 255) and multiplies every film's thickness by
  it, so the films are 35-100 % of their nominal thickness over the pot.
* ``scenes/meshes/teapot_uv.ply``: ``scenes/meshes/teapot.ply`` (made by
  ``make_teapot.py``, which has no texture coordinates) with per-vertex ``(u, v)``: a
  planar projection along ``z`` of its bounding box, ``u = (x - x_min)/(x_max - x_min)``,
  ``v = (y_max - y)/(y_max - y_min)`` (image rows run downwards). A planar projection
  has no seam; the texture stretches along ``z`` on the pot's sides, where the noise
  is smooth enough for that not to show.

Deterministic (fixed seed). Usage: python scripts/make_clay_oxide.py [--size 256]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from make_soap_film_texture import plane_wave_noise  # noqa: E402

ROOT = HERE.parent
LO, HI = 0.35, 1.0


def oxide_noise(size: int, seed: int = 11) -> np.ndarray:
    """``size`` x ``size`` values in [0, 1]: warped plane-wave noise, its 1st-99th
    percentiles stretched to the full range."""
    rng = np.random.default_rng(seed)
    c = (np.arange(size) + 0.5) / size
    uu, vv = np.meshgrid(c, c)
    p = np.stack([uu, vv, np.zeros_like(uu)], axis=-1)
    warp = np.stack([plane_wave_noise(p, rng, freq=(0.6, 1.8)) for _ in range(3)], axis=-1)
    n = plane_wave_noise(p + 0.15 * warp, rng, freq=(0.8, 4.0))
    lo, hi = np.percentile(n, [1, 99])
    return np.clip((n - lo) / (hi - lo), 0.0, 1.0)


def teapot_with_uv(src: Path, out: Path) -> None:
    import mitsuba as mi

    pot = mi.load_dict({"type": "ply", "filename": str(src)})
    params = mi.traverse(pot)
    pos = np.array(params["vertex_positions"], np.float32).reshape(-1, 3)
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    uv = np.stack([(pos[:, 0] - lo[0]) / (hi[0] - lo[0]), (hi[1] - pos[:, 1]) / (hi[1] - lo[1])], axis=-1)
    mesh = mi.Mesh("teapot_uv", pot.vertex_count(), pot.face_count(), has_vertex_normals=True,
                   has_vertex_texcoords=True)
    new = mi.traverse(mesh)
    new["vertex_positions"] = params["vertex_positions"]
    new["vertex_normals"] = params["vertex_normals"]
    new["faces"] = params["faces"]
    new["vertex_texcoords"] = type(params["vertex_positions"])(uv.astype(np.float32).ravel())
    new.update()
    mesh.write_ply(str(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256, help="texture size in pixels (square; default 256)")
    args = ap.parse_args()

    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    png = ROOT / "scenes" / "textures" / "oxide_thickness.png"
    img = np.round((LO + (HI - LO) * oxide_noise(args.size)) * 255).astype(np.uint8)
    mi.Bitmap(img[:, :, None], pixel_format=mi.Bitmap.PixelFormat.Y).write(str(png))
    print(f"wrote {png} ({args.size}x{args.size}, values {img.min() / 255:.3f}..{img.max() / 255:.3f})")
    ply = ROOT / "scenes" / "meshes" / "teapot_uv.ply"
    teapot_with_uv(ROOT / "scenes" / "meshes" / "teapot.ply", ply)
    print(f"wrote {ply}")


if __name__ == "__main__":
    main()
