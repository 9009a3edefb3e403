#!/usr/bin/env python3
"""Build scenes/textures/soap_film.exr, the film-thickness scale of the soap
bubble in scenes/rough_films.xml.

Mitsuba 3 has no procedural noise texture, so the swirls of a draining soap
film are baked into a small single-channel float EXR over the sphere's
(u, v) = (azimuth / 2 pi, polar angle / pi):

* drainage: the film thins towards the top (v = 0) as gravity pulls the
  liquid down, ``base(v) = lo + (hi - lo) * v**0.8``;
* swirls: band-limited noise made of random 3-D plane waves evaluated on a
  cylinder (so it is periodic in u, without a seam), with one step of domain
  warping for the marbled look of real bubbles, added with amplitude
  ``swirl`` and clamped to >= 0.02.

The scene multiplies every film thickness by this value (the ``thickness``
parameter of the thin-film plugins). Deterministic (fixed seed).

Usage: python scripts/make_soap_film_texture.py [--size 256x128] [--out scenes/textures/soap_film.exr]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def plane_wave_noise(p: np.ndarray, rng: np.random.Generator, waves: int = 48,
                     freq: tuple[float, float] = (1.5, 6.0)) -> np.ndarray:
    """Sum of ``waves`` random plane waves at points ``p`` (..., 3), normalised to
    unit standard deviation; amplitudes fall as 1/f (a 'pink' spectrum)."""
    dirs = rng.normal(size=(waves, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    f = rng.uniform(*freq, size=waves)
    phase = rng.uniform(0, 2 * np.pi, size=waves)
    arg = np.tensordot(p, (dirs * f[:, None]).T, axes=1) * 2 * np.pi + phase
    out = np.sum(np.cos(arg) / f, axis=-1)
    return out / out.std()


def soap_film(width: int, height: int, lo: float = 0.12, hi: float = 1.0,
              swirl: float = 0.22, seed: int = 7) -> np.ndarray:
    rng = np.random.default_rng(seed)
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    uu, vv = np.meshgrid(u, v)
    # Points on a cylinder of circumference 2 (u periodic) and height 1 (v).
    r = 1.0 / np.pi
    p = np.stack([r * np.cos(2 * np.pi * uu), r * np.sin(2 * np.pi * uu), vv], axis=-1)
    warp = np.stack([plane_wave_noise(p, rng, freq=(0.8, 2.5)) for _ in range(3)], axis=-1)
    noise = plane_wave_noise(p + 0.12 * warp, rng)
    base = lo + (hi - lo) * vv ** 0.8
    return np.maximum(base + swirl * noise * np.sqrt(vv + 0.1), 0.02).astype(np.float32)


def main() -> None:
    here = Path(__file__).resolve().parent.parent
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="256x128", help="WIDTHxHEIGHT (default 256x128)")
    ap.add_argument("--out", default=str(here / "scenes" / "textures" / "soap_film.exr"))
    args = ap.parse_args()
    width, height = (int(x) for x in args.size.lower().split("x"))
    img = soap_film(width, height)

    import mitsuba as mi
    mi.set_variant("scalar_rgb")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    mi.Bitmap(img[:, :, None], pixel_format=mi.Bitmap.PixelFormat.Y).write(str(out))
    print(f"wrote {out} ({width}x{height}, values {img.min():.3f}..{img.max():.3f})")


if __name__ == "__main__":
    main()
