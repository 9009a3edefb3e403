"""What a sweep renders (:mod:`thinfilm_mi.batch.sweeps`): the axes of its grid,
one :class:`Frame` per combination of their values, the frames grouped into
Dask tasks, and the :class:`Job` settings every task carries.

``VALUES`` of an axis is a range ``START:STOP:STEP`` (``STOP`` included when it
lies on the grid), a comma-separated list ``a,b,c`` or a single value (from
Python also a number or an iterable): :func:`parse_values`. An axis is a
``-D`` scene parameter (the scene is loaded per value) or a ``-P``
``mi.traverse`` key (set on the loaded scene): :func:`parse_axes`.
"""
from __future__ import annotations

import hashlib
import itertools
import math
import re
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from thinfilm_mi.batch.scene import parse_defines
from thinfilm_mi.errors import UsageError
from thinfilm_mi.optics.choices import choose

__all__ = [
    "Axis", "AxisKind", "AXIS_KINDS", "DEFINE", "TRAVERSE", "Frame", "Job", "parse_values", "parse_axes",
    "parse_scalar", "axis_label", "build_frames", "plan_tasks", "FRAMES_DIR", "MAX_FRAMES", "COLUMNS",
]

#: the frames' folder in the output folder
FRAMES_DIR = "frames"
#: more frames than this is most likely a mistyped range
MAX_FRAMES = 100_000
#: columns of the manifest after the parameters (no axis may take these names)
COLUMNS = ("exr", "png", "seconds", "status", "error")


class AxisKind(ABC):
    """What an axis of the grid sets: its option (``flag``), an example of it, and
    the checks of its names and values."""

    name: str
    flag: str
    example: str

    @abstractmethod
    def check_name(self, name: str) -> None:
        """:class:`UsageError` unless ``name`` can name an axis of this kind."""

    def check_values(self, name: str, values: tuple[str, ...]) -> None:
        """:class:`UsageError` unless every value can be set."""


class _Define(AxisKind):
    """``-D``: an XML ``$name`` parameter; the scene is loaded per value."""

    name, flag, example = "define", "-D", "thickness=100:800:25"

    def check_name(self, name):
        parse_defines([f"{name}=x"])  # the name check of thinfilm-render -D


class _Traverse(AxisKind):
    """``-P``: a ``mi.traverse`` key (a number or true/false), set on the loaded scene."""

    name, flag, example = "traverse", "-P", "teapot.bsdf.layers.0.thickness=100:800:25"

    def check_name(self, name):
        if not re.fullmatch(r"[^\s=,]+", name):
            raise UsageError(f"-P {name!r}: not a mi.traverse key (e.g. teapot.bsdf.layers.0.thickness)")

    def check_values(self, name, values):
        for v in values:
            parse_scalar(name, v)


DEFINE, TRAVERSE = _Define(), _Traverse()
#: The axis kinds by name.
AXIS_KINDS: dict[str, AxisKind] = {k.name: k for k in (DEFINE, TRAVERSE)}


@dataclass(frozen=True)
class Axis:
    """One axis of the grid: ``kind`` is :data:`DEFINE` (``-D``: an XML ``$name``
    parameter, the scene is loaded per value) or :data:`TRAVERSE` (``-P``: a
    ``mi.traverse`` key, set on the loaded scene)."""

    name: str
    values: tuple[str, ...]
    kind: AxisKind = DEFINE


@dataclass(frozen=True)
class Frame:
    """One frame: its values of the ``-D`` and ``-P`` axes and its outputs
    (paths relative to the output folder)."""

    index: int
    defines: tuple[tuple[str, str], ...]
    traverse: tuple[tuple[str, str], ...]
    exr: str
    png: str

    @property
    def params(self) -> dict[str, str]:
        return dict(self.defines + self.traverse)


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RANGE = re.compile(rf"\s*({_NUMBER})\s*:\s*({_NUMBER})\s*:\s*({_NUMBER})\s*")
_INTEGER = re.compile(r"\s*[-+]?\d+\s*")


def _format_number(value: float) -> str:
    """A grid value as text: no float noise (``0.1 + 2 * 0.1`` -> ``0.3``), no ``-0``."""
    text = f"{round(float(value), 9):.12g}"
    return "0" if text == "-0" else text


def _range(option: str, spec: str, start: str, stop: str, step: str) -> list[str]:
    a, b, s = float(start), float(stop), float(step)
    if not all(map(math.isfinite, (a, b, s))) or s == 0 or (b - a) / s < 0:
        raise UsageError(f"{option}{spec!r}: need a finite STEP != 0 going from START towards STOP")
    count = int(math.floor((b - a) / s + 1e-9)) + 1
    if count > MAX_FRAMES:
        raise UsageError(f"{option}{spec!r}: {count} values (more than {MAX_FRAMES})")
    if all(_INTEGER.fullmatch(t) for t in (start, stop, step)):
        return [str(int(start) + i * int(step)) for i in range(count)]
    return [_format_number(a + i * s) for i in range(count)]


def parse_values(spec: Any, option: str = "") -> tuple[str, ...]:
    """The values of one axis, as text.

    ``spec`` is a string ``START:STOP:STEP`` (numbers; ``STOP`` included when on
    the grid), ``a,b,c`` or a single value; or (from Python) a number or an
    iterable of numbers/strings (``range``, list, numpy array). ``option`` (e.g.
    ``"-D thickness="``) prefixes error messages.
    """
    if isinstance(spec, str):
        text = spec.strip()
        if not text:
            raise UsageError(f"{option}{spec!r}: no value given")
        m = _RANGE.fullmatch(text)
        if m:
            values = _range(option, spec, *m.groups())
        elif ":" in text and all(re.fullmatch(rf"\s*{_NUMBER}\s*", t) for t in text.split(":")):
            raise UsageError(f"{option}{spec!r}: a range needs START:STOP:STEP, e.g. 100:800:25")
        else:
            values = [t.strip() for t in text.split(",")]
            if any(not v for v in values):
                raise UsageError(f"{option}{spec!r}: empty value in the list")
    elif isinstance(spec, (bool, int, float)) or type(spec).__module__ == "numpy" and not hasattr(spec, "__len__"):
        values = [_value_text(spec, option)]
    else:
        try:
            items = list(spec)
        except TypeError:
            raise UsageError(f"{option}{spec!r}: expected a string, a number or a list of "
                             f"values, got {type(spec).__name__}") from None
        if not items:
            raise UsageError(f"{option}{spec!r}: no value given")
        values = [_value_text(v, option) for v in items]
    duplicates = sorted({v for v in values if values.count(v) > 1})
    if duplicates:
        raise UsageError(f"{option}{spec!r}: repeated value(s) {', '.join(duplicates)}")
    return tuple(values)


def _value_text(value: Any, option: str) -> str:
    if isinstance(value, str):
        if not value.strip():
            raise UsageError(f"{option}{value!r}: empty value")
        return value.strip()
    if isinstance(value, bool):
        return "true" if value else "false"
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise UsageError(f"{option}{value!r}: not a number or string") from None
    if float(number).is_integer() and abs(number) < 2 ** 53:
        return str(int(number))
    return _format_number(number)


def parse_axes(items: Mapping[str, Any] | Sequence[str] | None, kind: AxisKind | str) -> list[Axis]:
    """``-D`` (``kind="define"``) or ``-P`` (``kind="traverse"``) items,
    ``["name=VALUES", ...]`` or a mapping ``{name: VALUES}``, -> axes; a bad name,
    a name given twice or bad values raise :class:`~thinfilm_mi.errors.UsageError`."""
    kind = kind if isinstance(kind, AxisKind) else choose(AXIS_KINDS, kind, "kind")
    flag = kind.flag
    if items is None:
        return []
    if isinstance(items, Mapping):
        pairs = [(str(k).strip(), v) for k, v in items.items()]
    else:
        pairs = []
        for item in items:
            name, sep, value = str(item).partition("=")
            if not sep:
                raise UsageError(f"{flag} {item!r}: expected name=VALUES, e.g. {flag} {kind.example}")
            pairs.append((name.strip(), value))
    axes, seen = [], set()
    for name, value in pairs:
        kind.check_name(name)
        if name in seen:
            raise UsageError(f"{flag} {name}: given twice")
        seen.add(name)
        values = parse_values(value, f"{flag} {name}=")
        kind.check_values(name, values)
        axes.append(Axis(name, values, kind))
    return axes


def parse_scalar(key: str, text: str) -> float | bool:
    """A ``-P`` value: a number, or ``true``/``false``."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        return float(text)
    except ValueError:
        raise UsageError(f"-P {key}={text!r}: mi.traverse values must be numbers") from None


def axis_label(name: str) -> str:
    """An axis name shortened for labels and file names: the last three parts of a
    ``mi.traverse`` key (``a.b.c.d.e`` -> ``c.d.e``)."""
    parts = name.split(".")
    return ".".join(parts[-3:]) if len(parts) > 3 else name


def _stem(frame_params: Mapping[str, str], varying: Sequence[str]) -> str:
    if not varying:
        return "frame"
    text = "_".join(f"{axis_label(k)}={frame_params[k]}" for k in varying)
    return re.sub(r"[^A-Za-z0-9._=+-]+", "-", text)


def build_frames(axes: Sequence[Axis]) -> list[Frame]:
    """The frames of the grid, in product order (the last axis varies fastest),
    named after the values of the axes that vary (``frames/<name>.exr``)."""
    names = [a.name for a in axes]
    if len(set(names)) != len(names):
        raise UsageError(f"an axis is given twice: {', '.join(names)}")
    reserved = sorted(set(names) & set(COLUMNS))
    if reserved:
        raise UsageError(f"parameter name(s) {', '.join(reserved)} clash with manifest columns")
    total = math.prod(len(a.values) for a in axes) if axes else 1
    if total > MAX_FRAMES:
        raise UsageError(f"the grid has {total} frames (more than {MAX_FRAMES})")
    varying = [a.name for a in axes if len(a.values) > 1]
    combos = list(itertools.product(*(a.values for a in axes)))
    stems = [_stem(dict(zip(names, c)), varying) for c in combos]
    counts: dict[str, int] = {}
    for s in stems:
        counts[s] = counts.get(s, 0) + 1
    frames = []
    for i, (combo, stem) in enumerate(zip(combos, stems)):
        if len(stem) > 120 or counts[stem] > 1:  # too long, or values that differ only in odd characters
            digest = hashlib.sha1(repr(combo).encode()).hexdigest()[:12]
            stem = f"frame-{digest}"
        pairs = list(zip(axes, combo))
        frames.append(Frame(
            index=i,
            defines=tuple((a.name, v) for a, v in pairs if a.kind is DEFINE),
            traverse=tuple((a.name, v) for a, v in pairs if a.kind is TRAVERSE),
            exr=f"{FRAMES_DIR}/{stem}.exr", png=f"{FRAMES_DIR}/{stem}.png"))
    return frames


def plan_tasks(frames: Sequence[Frame], workers: int, frames_per_task: int | None = None) -> list[list[Frame]]:
    """Chunks of frames, one Dask task each. A chunk holds frames of one ``-D``
    combination (one scene load), consecutive in grid order; groups are split
    into near-equal chunks of at most ``frames_per_task`` frames (default: the
    number that gives about two tasks per worker)."""
    if frames_per_task is None:
        frames_per_task = max(1, math.ceil(len(frames) / (2 * max(1, workers))))
    if frames_per_task < 1:
        raise UsageError(f"frames_per_task must be >= 1, got {frames_per_task}")
    groups: dict[tuple, list[Frame]] = {}
    for f in frames:
        groups.setdefault(f.defines, []).append(f)
    tasks = []
    for group in groups.values():
        n = math.ceil(len(group) / frames_per_task)
        base, extra = divmod(len(group), n)
        start = 0
        for i in range(n):
            size = base + (1 if i < extra else 0)
            tasks.append(group[start:start + size])
            start += size
    return tasks


@dataclass(frozen=True)
class Job:
    """What every task of a sweep needs besides its frames (sent with each task)."""

    scene: str                      # absolute path (the same on every worker)
    out_dir: str                    # absolute path (shared by the workers)
    variant: str
    spp: int | None
    size: tuple[int, int] | None
    seed: int
    sensor: int
    max_pass_samples: int
    threads: int | None             # Dr.Jit threads per worker (None: leave as set up)
    verbose: bool = False
