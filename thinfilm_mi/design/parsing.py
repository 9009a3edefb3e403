"""Parsing of the design's input files (targets, measurements): numbers, grids, choices.

Every error raises :class:`~thinfilm_mi.errors.ThinFilmError` ``"{where}: {message}"``,
``where`` naming the entry (``targets[2] (colour)``).
"""
from __future__ import annotations

import math
import re
from typing import Any, Mapping, TypeVar

import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.choices import choose

__all__ = ["fail", "parse_number", "parse_grid", "per_point", "parse_choice", "MAX_POINTS"]

T = TypeVar("T")
#: Most wavelengths one target may list (a 0.001 nm grid over the visible).
MAX_POINTS = 500_000


def fail(where: str, message: str):
    """Raise :class:`ThinFilmError` ``"{where}: {message}"``."""
    raise ThinFilmError(f"{where}: {message}")


def parse_number(value: Any, where: str, what: str) -> float:
    """``value`` as a finite float, else :func:`fail`."""
    if isinstance(value, bool):
        fail(where, f"{what} must be a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        fail(where, f"{what} must be a number, got {value!r}")
    if not math.isfinite(x):
        fail(where, f"{what} must be finite, got {value!r}")
    return x


def parse_grid(value: Any, where: str, what: str) -> np.ndarray:
    """``"START:STOP:STEP"``, one number, a list, or a string of numbers -> floats."""
    if isinstance(value, str) and ":" in value:
        parts = value.split(":")
        if len(parts) != 3:
            fail(where, f"{what} {value!r}: expected START:STOP:STEP, e.g. 420:680:5")
        start, stop, step = (parse_number(p, where, f"{what} {value!r}") for p in parts)
        if step <= 0 or stop < start:
            fail(where, f"{what} {value!r}: need STOP >= START and STEP > 0")
        count = int(math.floor((stop - start) / step + 1e-9)) + 1
        if count > MAX_POINTS:
            fail(where, f"{what} {value!r}: {count} values; at most {MAX_POINTS}")
        return start + step * np.arange(count)
    if isinstance(value, str):
        value = [t for t in re.split(r"[,\s]+", value.strip()) if t]
    items = value if isinstance(value, (list, tuple)) else [value]
    if not items:
        fail(where, f"{what}: none given")
    return np.array([parse_number(v, where, what) for v in items], dtype=np.float64)


def per_point(value: Any, count: int, where: str, what: str) -> np.ndarray:
    """One number or one per wavelength (``count``) -> ``count`` floats."""
    arr = parse_grid(value, where, what) if isinstance(value, (list, tuple)) else \
        np.array([parse_number(value, where, what)])
    if arr.size not in (1, count):
        fail(where, f"{what}: give one number or one per wavelength ({count}), got {arr.size}")
    return np.broadcast_to(arr, (count,)).copy()


def parse_choice(value: Any, registry: Mapping[str, T], where: str, what: str, aliases=None) -> T:
    """The entry of ``registry`` (a dict name -> object, or a tuple of names) that
    ``value`` names (:func:`thinfilm_mi.optics.choices.choose`), the error
    prefixed with ``where``."""
    if not isinstance(registry, Mapping):
        registry = {name: name for name in registry}
    try:
        return choose(registry, value, what, aliases)
    except ThinFilmError as e:
        fail(where, str(e))
