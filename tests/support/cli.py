"""Helpers of the command-line tests: a PNG's size and an error's lines."""
from __future__ import annotations


def png_size(path):
    import mitsuba as mi

    return tuple(int(v) for v in mi.Bitmap(str(path)).size())


def error_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.strip()]
