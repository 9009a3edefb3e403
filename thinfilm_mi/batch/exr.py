"""Image output of the command-line renderer: a linear EXR with metadata and a
clipped sRGB PNG preview.

The EXR is written with the ``OpenEXR`` Python package (float32 channels, ZIP
compression) so that arbitrary string/int/float header attributes can be stored
next to the pixels; :func:`read_exr` reads one back. The PNG is made with
Mitsuba's :class:`mitsuba.Bitmap` conversion (linear -> sRGB transfer curve,
8 bit, values clipped to [0, 1]).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["write_exr", "read_exr", "write_png", "preview_channels"]


def _attribute(value: Any) -> Any:
    """A header value OpenEXR can store: str, int or float (others as str)."""
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if isinstance(value, (str, os.PathLike)):
        return str(value)
    return repr(value)


def write_exr(path: str | os.PathLike, image: np.ndarray, channels: Sequence[str],
              attributes: Mapping[str, Any] | None = None) -> Path:
    """Write ``image`` (H x W x C, linear) as a float32 EXR with the given
    channel names and extra header ``attributes``; returns the path."""
    import OpenEXR

    image = np.asarray(image)
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3 or image.shape[2] != len(channels):
        raise ValueError(f"image of shape {image.shape} does not match channels {list(channels)}")
    if len(set(channels)) != len(channels):
        raise ValueError(f"duplicate channel names {list(channels)}")
    pixels = {name: np.ascontiguousarray(image[:, :, i], dtype=np.float32)
              for i, name in enumerate(channels)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in (attributes or {}).items():
        header[str(key)] = _attribute(value)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with OpenEXR.File(header, pixels) as f:
        f.write(str(path))
    return path


def read_exr(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """``(channels, header)`` of an EXR: channel name -> H x W float array."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        header = dict(f.header())
        channels = {name: np.array(ch.pixels) for name, ch in f.channels().items()}
    return channels, header


def preview_channels(channels: Sequence[str]) -> list[int] | None:
    """Indices of the channels a preview shows: R, G, B (and A when present),
    else a single Y/L channel; ``None`` if the film has neither (e.g. a
    spectral film)."""
    names = list(channels)
    if all(c in names for c in ("R", "G", "B")):
        idx = [names.index(c) for c in ("R", "G", "B")]
        if "A" in names:
            idx.append(names.index("A"))
        return idx
    for c in ("Y", "L"):
        if c in names:
            return [names.index(c)]
    return None


def write_png(path: str | os.PathLike, image: np.ndarray, channels: Sequence[str]) -> Path | None:
    """Write a clipped 8-bit sRGB preview of a linear image; returns the path,
    or ``None`` when the channels hold no colour or luminance to show."""
    import mitsuba as mi

    idx = preview_channels(channels)
    if idx is None:
        return None
    data = np.ascontiguousarray(np.clip(np.nan_to_num(np.asarray(image)[:, :, idx], nan=0.0,
                                                      posinf=1.0, neginf=0.0), 0.0, 1.0),
                                dtype=np.float32)
    fmt = {1: mi.Bitmap.PixelFormat.Y, 3: mi.Bitmap.PixelFormat.RGB,
           4: mi.Bitmap.PixelFormat.RGBA}[len(idx)]
    bitmap = mi.Bitmap(data, fmt)
    bitmap = bitmap.convert(fmt, mi.Struct.Type.UInt8, srgb_gamma=True)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    bitmap.write(str(path))
    return path
