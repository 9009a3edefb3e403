"""Parameter sweeps on Dask: ``thinfilm-render sweep`` and :func:`thinfilm_mi.sweep`.

A sweep renders one scene over the product of parameter values (a grid), one
frame per combination, on a Dask ``distributed`` cluster: by default a
:class:`~distributed.LocalCluster` of worker processes on this machine
(127.0.0.1 only, no dashboard), or any running cluster given by its scheduler
address (started by hand, by dask-jobqueue on SLURM, by dask-kubernetes)::

    thinfilm-render sweep SCENE.xml -D thickness=100:800:25 -D spp=64 --out-dir out/sweep
                    [-P key=VALUES ...] [--workers N | --scheduler ADDRESS]
                    [--size WxH] [--spp N] [--variant V] [--seed S] [--threads T]

Axes of the grid:

- ``-D name=VALUES`` sets the scene's ``$name`` parameter, as in
  ``thinfilm-render``; the scene is loaded once per combination of ``-D`` values.
- ``-P key=VALUES`` sets a ``mi.traverse(scene)`` parameter (a number) on the
  loaded scene, e.g. ``-P sphere.bsdf.layers.0.thickness=100:800:25``. Frames
  that differ only in ``-P`` values share one loaded scene: they are rendered
  one after the other by one worker task (a chunk), and film thicknesses being
  opaque Dr.Jit values, no kernel is compiled again.

``VALUES`` is a range ``START:STOP:STEP`` (``STOP`` included when it lies on
the grid), a comma-separated list ``a,b,c`` or a single value (on the command
line a value cannot hold a comma; from Python, pass a list).

Work is split into tasks of up to ``frames_per_task`` frames of the same ``-D``
combination (by default about two tasks per worker, never mixing scenes). Each
worker process is set up once by :class:`SweepWorkerPlugin` (a Dask worker
plugin): Mitsuba variant, thin-film plugin registration (registration is per
process), Dr.Jit thread count. A worker renders one frame at a time and keeps the
last loaded scene, so consecutive tasks of one combination load it once.

Outputs in ``OUT_DIR``:

- ``frames/<name>.exr`` and ``frames/<name>.png`` per frame (the EXR header
  holds the frame's parameters), each written to a hidden temporary name
  (``.<name>.part-*``) and renamed when complete;
- ``manifest.csv``: one row per finished frame, in grid order: the parameters,
  ``exr`` and ``png`` (relative to ``OUT_DIR``), ``seconds``, ``status``
  (``ok`` or ``failed``), ``error``; rewritten atomically while the sweep runs;
- ``contact_sheet.png``: every frame, labelled with the parameters that vary;
- ``sweep.json``: the settings that are not grid axes (scene, variant, size,
  spp, seed, sensor).

Failures: a frame that fails (bad parameter value, render or write error) is
recorded with its error and the others go on. A worker process that dies is
replaced by its nanny and Dask runs its tasks again elsewhere; a task whose
workers died more than :data:`ALLOWED_FAILURES` times is recorded as failed.
Running the same command again resumes: a frame is rendered again unless the
manifest has an ``ok`` row with the same parameters and settings whose files
exist. After Ctrl-C (or a ``timeout``) the manifest holds the frames finished so
far, the worker processes are stopped (an external cluster is waited for until
its running frames end) and temporary files are removed.

A scene that needs a polarized variant (a ``stokes`` integrator, a ``polarizer``:
:func:`thinfilm_mi.cli.render.scene_variant`, for any of the grid's ``-D`` combinations)
is rendered in the polarized variant of the requested one's family, as
``thinfilm-render`` does; it is said on the progress stream and ``sweep.json``
records it.

``cuda_*`` variants: the local cluster starts one worker per visible GPU, each
with its own ``CUDA_VISIBLE_DEVICES`` (:func:`gpu_worker_envs`); on an external
cluster start one worker per GPU the same way (or with dask-cuda).
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import io
import itertools
import json
import logging
import math
import os
import re
import secrets
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence, TextIO

from distributed import WorkerPlugin

from thinfilm_mi.cli import render as cli
from thinfilm_mi.cli.render import DEFAULT_MAX_PASS_SAMPLES, DEFAULT_VARIANT, CLIError, RenderFailure, UsageError, one_line

__all__ = [
    "sweep", "sweep_main", "SweepResult", "SweepWorkerPlugin", "Axis", "Frame", "parse_values",
    "build_frames", "plan_tasks", "local_cluster", "visible_gpus", "gpu_worker_envs",
    "render_frames", "read_manifest", "ALLOWED_FAILURES",
]

PROG = f"{cli.PROG} sweep"
DEFAULT_OUT_DIR = "out/sweep"
MANIFEST = "manifest.csv"
SETTINGS = "sweep.json"
CONTACT_SHEET = "contact_sheet.png"
FRAMES_DIR = "frames"
#: temporary outputs are named ``.<name>.part-<pid>-<random><suffix>``
PART_MARK = ".part-"
#: a task is run again after its worker died, up to this many times (Dask's
#: ``allowed_failures``); then its frames are recorded as failed
ALLOWED_FAILURES = 2
#: more frames than this is most likely a mistyped range
MAX_FRAMES = 100_000
#: columns of the manifest after the parameters
COLUMNS = ("exr", "png", "seconds", "status", "error")
#: seconds between two rewrites of the manifest while frames come in
MANIFEST_INTERVAL = 1.0
#: seconds to wait, after Ctrl-C, for frames still running on an external cluster
DRAIN_TIMEOUT = 120.0


# --------------------------------------------------------------------------------------
# the grid


@dataclass(frozen=True)
class Axis:
    """One axis of the grid: ``kind`` is ``"define"`` (``-D``: an XML ``$name``
    parameter, the scene is loaded per value) or ``"traverse"`` (``-P``: a
    ``mi.traverse`` key, set on the loaded scene)."""

    name: str
    values: tuple[str, ...]
    kind: str = "define"


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


def parse_axes(items: Mapping[str, Any] | Sequence[str] | None, kind: str) -> list[Axis]:
    """``-D``/``-P`` items (``["name=VALUES", ...]`` or a mapping) -> axes."""
    flag = "-D" if kind == "define" else "-P"
    if items is None:
        return []
    if isinstance(items, Mapping):
        pairs = [(str(k).strip(), v) for k, v in items.items()]
    else:
        pairs = []
        for item in items:
            name, sep, value = str(item).partition("=")
            if not sep:
                example = "thickness=100:800:25" if kind == "define" else \
                    "sphere.bsdf.layers.0.thickness=100:800:25"
                raise UsageError(f"{flag} {item!r}: expected name=VALUES, e.g. {flag} {example}")
            pairs.append((name.strip(), value))
    axes, seen = [], set()
    for name, value in pairs:
        if kind == "define":
            cli.parse_defines([f"{name}=x"])  # the name check of thinfilm-render -D
        elif not re.fullmatch(r"[^\s=,]+", name):
            raise UsageError(f"-P {name!r}: not a mi.traverse key (e.g. sphere.bsdf.layers.0.thickness)")
        if name in seen:
            raise UsageError(f"{flag} {name}: given twice")
        seen.add(name)
        values = parse_values(value, f"{flag} {name}=")
        if kind == "traverse":
            for v in values:
                _parse_scalar(name, v)
        axes.append(Axis(name, values, kind))
    return axes


def _parse_scalar(key: str, text: str) -> float | bool:
    """A ``-P`` value: a number, or ``true``/``false``."""
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    try:
        return float(text)
    except ValueError:
        raise UsageError(f"-P {key}={text!r}: mi.traverse values must be numbers") from None


def _stem(frame_params: Mapping[str, str], varying: Sequence[str]) -> str:
    if not varying:
        return "frame"
    text = "_".join(f"{_label(k)}={frame_params[k]}" for k in varying)
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
            defines=tuple((a.name, v) for a, v in pairs if a.kind == "define"),
            traverse=tuple((a.name, v) for a, v in pairs if a.kind == "traverse"),
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


# --------------------------------------------------------------------------------------
# GPUs


def visible_gpus(environ: Mapping[str, str] | None = None,
                 list_gpus: Callable[[], str] | None = None) -> list[str]:
    """The GPUs workers may use: the entries of ``CUDA_VISIBLE_DEVICES`` when it
    is set (up to a ``-1``, which hides the rest, as in CUDA), else one per line
    ``GPU i: ...`` of ``nvidia-smi -L`` (none when it is missing)."""
    environ = os.environ if environ is None else environ
    text = environ.get("CUDA_VISIBLE_DEVICES")
    if text is not None:
        gpus = []
        for token in (t.strip() for t in text.split(",")):
            if not token or token == "-1":
                break
            gpus.append(token)
        return gpus
    if list_gpus is None:
        def list_gpus() -> str:
            return subprocess.run(["nvidia-smi", "-L"], capture_output=True, text=True,
                                  timeout=30, check=True).stdout
    try:
        listing = list_gpus()
    except (OSError, subprocess.SubprocessError):
        return []
    return [m.group(1) for m in re.finditer(r"^GPU (\d+):", listing, re.MULTILINE)]


def gpu_worker_envs(gpus: Sequence[str], n_workers: int | None = None) -> list[dict[str, str]]:
    """Environment of each local worker of a ``cuda_*`` sweep: worker ``i`` sees
    only GPU ``gpus[i % len(gpus)]`` (default: one worker per GPU)."""
    gpus = list(gpus)
    if not gpus:
        raise UsageError("a cuda_* variant needs a GPU, and none is visible "
                         "(CUDA_VISIBLE_DEVICES, nvidia-smi -L)")
    n = len(gpus) if n_workers is None else int(n_workers)
    if n < 1:
        raise UsageError(f"--workers must be >= 1, got {n}")
    return [{"CUDA_VISIBLE_DEVICES": str(gpus[i % len(gpus)])} for i in range(n)]


# --------------------------------------------------------------------------------------
# worker side


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


_SETUP_LOCK = threading.Lock()
_RENDER_LOCK = threading.Lock()
_PROCESS: dict[str, Any] = {}


def setup_process(variant: str, threads: int | None = None, verbose: bool = False) -> None:
    """Prepare this (worker) process once: Mitsuba variant, thin-film plugins,
    Dr.Jit thread count (``dr.set_thread_count``; None keeps it), Mitsuba's log
    level and Dr.Jit's kernel history (each frame counts the kernels it compiled)."""
    with _SETUP_LOCK:
        if _PROCESS.get("variant") != variant:
            cli.setup_variant(variant)
            _PROCESS["variant"] = variant
        import drjit as dr
        import mitsuba as mi

        if threads and _PROCESS.get("threads") != threads:
            dr.set_thread_count(int(threads))
            _PROCESS["threads"] = threads
        mi.set_log_level(mi.LogLevel.Warn if verbose else mi.LogLevel.Error)
        dr.set_flag(dr.JitFlag.KernelHistory, True)


class SweepWorkerPlugin(WorkerPlugin):
    """Dask worker plugin: runs :func:`setup_process` when a worker starts (and
    on every worker that joins later, e.g. one restarted after a crash).
    ``threads`` is the Dr.Jit thread count; None uses the worker's own thread
    count (``dask worker --nthreads``). ``ignore_sigint`` (local clusters):
    the workers leave Ctrl-C to the client, which stops them."""

    def __init__(self, variant: str = DEFAULT_VARIANT, threads: int | None = None,
                 verbose: bool = False, ignore_sigint: bool = False):
        self.variant = variant
        self.threads = threads
        self.verbose = verbose
        self.ignore_sigint = ignore_sigint
        self.name = f"thinfilm-sweep-{variant}"

    def setup(self, worker) -> None:
        if self.ignore_sigint:
            # Local workers share the terminal's process group: Ctrl-C is the
            # client's to handle (it stops them), not a traceback from each.
            try:
                signal.signal(signal.SIGINT, signal.SIG_IGN)
            except ValueError:  # not the main thread
                pass
        setup_process(self.variant, self.threads or max(1, int(worker.state.nthreads)), self.verbose)


class _SceneCache:
    """The last scene this process loaded, keyed by everything that went into loading it."""

    def __init__(self):
        self.key = None
        self.scene = None
        self.params = None

    def get(self, job: Job, defines: tuple[tuple[str, str], ...]):
        scene_file = Path(job.scene)
        key = (job.scene, scene_file.stat().st_mtime_ns if scene_file.exists() else None,
               job.variant, job.size, job.spp, defines)
        if key == self.key:
            return self.scene, self.params, False
        self.drop()
        scene = cli.load_scene(scene_file, dict(defines), size=job.size, spp=job.spp,
                               variant=job.variant)
        self.key, self.scene, self.params = key, scene, None
        return scene, None, True

    def drop(self) -> None:
        self.key = self.scene = self.params = None


_SCENES = _SceneCache()


def set_parameters(scene, params, values: Sequence[tuple[str, str]]):
    """Set ``-P`` values on a loaded scene (``params``: its ``mi.traverse``, or
    None to make it) and apply them; returns the parameters object."""
    import drjit as dr
    import mitsuba as mi

    if params is None:
        params = mi.traverse(scene)
    for key, text in values:
        if key not in params:
            import difflib

            close = difflib.get_close_matches(key, list(params.keys()), n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise UsageError(f"-P {key}: not a parameter of the scene (see mi.traverse){hint}")
        current = params[key]
        value = _parse_scalar(key, text)
        if isinstance(current, (bool, int, float)):
            params[key] = type(current)(value)
        else:
            if dr.is_array_v(current) and dr.depth_v(current) == 1 and dr.width(current) != 1:
                raise UsageError(f"-P {key}: holds {dr.width(current)} values; "
                                 "-P sets single numbers only")
            params[key] = type(current)(value)
    params.update()
    return params


def _part_path(path: Path) -> Path:
    """A hidden temporary name beside ``path``, same suffix (image writers go by it)."""
    return path.with_name(f".{path.stem}{PART_MARK}{os.getpid()}-{secrets.token_hex(4)}{path.suffix}")


def _write_frame(job: Job, frame: Frame, image, channels, attributes) -> str:
    """Write the frame's EXR and PNG through temporary names; returns the PNG's
    relative path ('' when the film has no colour to preview)."""
    from thinfilm_mi.batch import exr

    out = Path(job.out_dir)
    final_exr, final_png = out / frame.exr, out / frame.png
    parts = [_part_path(final_exr), _part_path(final_png)]
    try:
        exr.write_exr(parts[0], image, channels, attributes)
        wrote_png = exr.write_png(parts[1], image, channels) is not None
        if wrote_png:
            os.replace(parts[1], final_png)
        os.replace(parts[0], final_exr)
    finally:
        for p in parts:
            p.unlink(missing_ok=True)
    return frame.png if wrote_png else ""


def _fresh_kernels() -> int:
    """JIT kernels launched since the last call that were not in this process's
    kernel cache (compiled, or loaded from Dr.Jit's disk cache); clears the history."""
    import drjit as dr

    return sum(1 for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT
               and (k.get("cache_disk", False) or not k.get("cache_hit", False)))


def _render_one(job: Job, frame: Frame) -> dict[str, Any]:
    row: dict[str, Any] = {"index": frame.index, "status": "failed", "error": "", "png": "",
                           "scene_loaded": False, "kernels": 0,
                           "worker": f"{socket.gethostname()}:{os.getpid()}"}
    t0 = time.perf_counter()
    _fresh_kernels()  # clear
    try:
        scene, params, row["scene_loaded"] = _SCENES.get(job, frame.defines)
        if frame.traverse:
            _SCENES.params = set_parameters(scene, params, frame.traverse)
        sensors = scene.sensors()
        if not 0 <= job.sensor < len(sensors):
            raise UsageError(f"--sensor {job.sensor}: the scene has {len(sensors)} sensor(s)")
        spp = job.spp if job.spp is not None else int(sensors[job.sensor].sampler().sample_count())
        image, channels, passes, seconds = cli.render_scene(
            scene, spp, seed=job.seed, sensor=job.sensor, max_pass_samples=job.max_pass_samples)
        attributes = cli.output_attributes(job.scene, job.variant, spp, seconds, job.seed, passes,
                                           frame.params)
        row["png"] = _write_frame(job, frame, image, channels, attributes)
        row["status"] = "ok"
    except Exception as e:  # recorded in the manifest; the other frames go on
        _SCENES.drop()  # it may hold half-applied -P values
        row["error"] = one_line(e) if isinstance(e, CLIError) else f"{type(e).__name__}: {one_line(e)}"
    row["seconds"] = time.perf_counter() - t0
    row["kernels"] = _fresh_kernels()
    return row


def render_frames(job: Job, frames: Sequence[Frame]) -> list[dict[str, Any]]:
    """The task run on a worker: render ``frames`` (one ``-D`` combination) one
    after the other on one loaded scene; one result row per frame, failures included."""
    setup_process(job.variant, job.threads, job.verbose)
    with _RENDER_LOCK:  # one frame at a time per process, whatever --nthreads says
        return [_render_one(job, f) for f in frames]


def _running_keys(prefix: str, dask_worker=None) -> list[str]:
    """Keys of this sweep's tasks still running on a worker (cancelled ones too)."""
    state = dask_worker.state
    return [str(ts.key) for ts in (state.executing | state.long_running) if str(ts.key).startswith(prefix)]


# --------------------------------------------------------------------------------------
# client side: outputs


def read_manifest(path: str | os.PathLike) -> list[dict[str, str]]:
    """The rows of a manifest (empty when missing or unreadable)."""
    try:
        with open(path, newline="") as f:
            return [dict(r) for r in csv.DictReader(f)]
    except (OSError, csv.Error, UnicodeDecodeError):
        return []


def _write_atomic(path: Path, data: bytes) -> None:
    part = _part_path(path)
    try:
        part.write_bytes(data)
        os.replace(part, path)
    finally:
        part.unlink(missing_ok=True)


def _write_manifest(path: Path, names: Sequence[str], rows: Iterable[Mapping[str, Any]]) -> None:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=[*names, *COLUMNS], extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({**row, "seconds": f"{float(row.get('seconds') or 0.0):.3f}"})
    _write_atomic(path, buf.getvalue().encode())


def _remove_parts(folder: Path) -> None:
    """Remove temporary outputs (``.<name>.part-*``) left by killed workers."""
    for p in folder.glob(f".*{PART_MARK}*"):
        p.unlink(missing_ok=True)


def _label(name: str) -> str:
    parts = name.split(".")
    return ".".join(parts[-3:]) if len(parts) > 3 else name


def write_contact_sheet(path: Path, out_dir: Path, axes: Sequence[Axis],
                        rows: Sequence[Mapping[str, Any]], thumb_px: int = 160) -> Path:
    """A PNG of every frame, labelled with the values of the axes that vary;
    failed frames as grey tiles saying so. Uses matplotlib's Agg canvas (no pyplot)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    import matplotlib.image as mpimg

    varying = [a for a in axes if len(a.values) > 1]
    n = len(rows)
    previews = [out_dir / r["png"] for r in rows
                if r.get("status") == "ok" and r.get("png") and (out_dir / r["png"]).is_file()]
    images = {p: mpimg.imread(str(p)) for p in previews}
    aspect = (lambda im: im.shape[0] / im.shape[1])(next(iter(images.values()))) if images else 0.75
    if len(varying) >= 2 and len(varying[-1].values) <= 12:
        cols = len(varying[-1].values)
    else:
        cols = min(n, max(1, math.ceil(math.sqrt(n))), 12) if n else 1
    rows_n = max(1, math.ceil(n / cols))
    dpi = 100
    w_in = thumb_px / dpi
    fig = Figure(figsize=(cols * w_in, rows_n * (w_in * aspect + 0.1 + 0.1 * max(1, len(varying)))),
                 dpi=dpi)
    FigureCanvasAgg(fig)
    for i, row in enumerate(rows):
        ax = fig.add_subplot(rows_n, cols, i + 1)
        ax.set_xticks([])
        ax.set_yticks([])
        label = "\n".join(f"{_label(a.name)}={row.get(a.name, '')}" for a in varying) or "frame"
        png = out_dir / row["png"] if row.get("png") else None
        if png in images:
            ax.imshow(images[png])
        else:
            ax.set_facecolor("0.8")
            ax.text(0.5, 0.5, "failed" if row.get("status") == "failed" else "no preview",
                    ha="center", va="center", transform=ax.transAxes, fontsize=8)
        ax.set_title(label, fontsize=6)
    fig.tight_layout(pad=0.3)
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    _write_atomic(path, buf.getvalue())
    return path


class _Progress:
    """A one-line progress bar over frames (redrawn in place on a terminal)."""

    def __init__(self, total: int, stream: TextIO, width: int = 30):
        self.total, self.stream, self.width = total, stream, width
        self.start = time.perf_counter()
        self.first: int | None = None  # frames already done at the first update
        self.interactive = bool(getattr(stream, "isatty", lambda: False)())
        self.last = ""

    def update(self, done: int, failed: int) -> None:
        if self.first is None:
            self.first = done
        filled = int(round(self.width * done / max(1, self.total)))
        elapsed = time.perf_counter() - self.start
        rate = (done - self.first) / elapsed * 60.0 if elapsed > 0 else 0.0
        self.last = (f"\r{PROG}: [{'#' * filled}{'.' * (self.width - filled)}] {done}/{self.total} "
                     f"frames, {failed} failed, {elapsed:.1f} s, {rate:.1f} frames/min")
        if self.interactive:
            self.stream.write(self.last)
            self.stream.flush()

    def close(self) -> None:
        if self.last:
            self.stream.write(("" if self.interactive else self.last.lstrip("\r")) + "\n")
            self.stream.flush()


# --------------------------------------------------------------------------------------
# client side: the sweep


@dataclass
class SweepResult:
    """The table a sweep returns: one row per frame in grid order (the manifest's
    columns, plus for frames rendered by this call ``scene_loaded``, ``kernels``
    (JIT kernels compiled or read from disk for it) and ``worker``)."""

    out_dir: Path
    columns: list[str]
    rows: list[dict[str, Any]]
    rendered: int
    skipped: int
    seconds: float
    workers: int
    manifest: Path
    contact_sheet: Path | None = None

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self):
        return iter(self.rows)

    def __getitem__(self, i: int) -> dict[str, Any]:
        return self.rows[i]

    @property
    def ok(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r["status"] == "ok"]

    @property
    def failed(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r["status"] == "failed"]

    def to_pandas(self):
        """The rows as a ``pandas.DataFrame`` (pandas is not a dependency)."""
        import pandas as pd

        return pd.DataFrame(self.rows)


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def local_cluster(n_workers: int, variant: str = DEFAULT_VARIANT, gpus: Sequence[str] | None = None,
                  silence_logs: int = logging.ERROR):
    """The embedded cluster: ``n_workers`` worker processes (one Dask thread
    each) under nannies on 127.0.0.1, no dashboard. For a ``cuda_*`` variant
    worker ``i`` gets ``CUDA_VISIBLE_DEVICES`` from :func:`gpu_worker_envs`."""
    from distributed import LocalCluster

    options = dict(threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None,
                   scheduler_kwargs={"allowed_failures": ALLOWED_FAILURES}, silence_logs=silence_logs)
    if not variant.startswith("cuda_"):
        return LocalCluster(n_workers=n_workers, **options)
    envs = gpu_worker_envs(visible_gpus() if gpus is None else gpus, n_workers)
    cluster = LocalCluster(n_workers=0, **options)
    try:
        for i, env in enumerate(envs):  # LocalCluster gives all workers one spec: one each here
            template = cluster.new_spec
            opts = dict(template["options"])
            opts["env"] = {**(opts.get("env") or {}), **env}
            cluster.worker_spec[i] = {"cls": template["cls"], "options": opts}
        cluster.scale(len(envs))
    except BaseException:
        cluster.close()
        raise
    return cluster


def _settings(job: Job) -> dict[str, Any]:
    return {"scene": job.scene, "variant": job.variant, "size": list(job.size) if job.size else None,
            "spp": job.spp, "seed": job.seed, "sensor": job.sensor,
            "max_pass_samples": job.max_pass_samples}


def _previous_rows(out: Path, job: Job, frames: Sequence[Frame], names: Sequence[str],
                   log: Callable[[str], None]) -> dict[int, dict[str, Any]]:
    """Frames complete from an earlier run: an ``ok`` manifest row with the same
    parameters (and settings) whose files exist."""
    manifest = out / MANIFEST
    if not manifest.exists():
        return {}
    try:
        previous = json.loads((out / SETTINGS).read_text())
    except (OSError, ValueError):
        previous = None
    if previous != _settings(job):
        log(f"{out} holds a sweep with other settings (or none recorded): rendering every frame")
        return {}
    by_params: dict[tuple, dict[str, str]] = {}
    for row in read_manifest(manifest):
        if row.get("status") == "ok" and all(row.get(n) is not None for n in names):
            by_params[tuple(row[n] for n in names)] = row
    done = {}
    for f in frames:
        row = by_params.get(tuple(f.params[n] for n in names))
        if row is None or not row.get("exr") or not (out / row["exr"]).is_file():
            continue
        if row.get("png") and not (out / row["png"]).is_file():
            continue
        try:
            seconds = float(row.get("seconds") or 0.0)
        except ValueError:
            seconds = 0.0
        done[f.index] = {**f.params, "exr": row["exr"], "png": row.get("png") or "",
                         "seconds": seconds, "status": "ok", "error": "", "rendered": False}
    return done


def _connect(workers: int | None, scheduler: str | None, client, variant: str):
    """(client, cluster we own or None, client we own?, worker count for planning)."""
    from distributed import Client

    if client is not None:
        return client, None, False
    if scheduler is not None:
        try:
            return Client(scheduler, timeout="30s"), None, True
        except (OSError, TimeoutError) as e:
            raise UsageError(f"--scheduler {scheduler}: cannot connect: {one_line(e)}") from e
    cluster = local_cluster(workers, variant)
    try:
        return Client(cluster), cluster, True
    except BaseException:
        cluster.close()
        raise


def grid_variant(scene: Path, frames: Sequence[Frame], variant: str) -> tuple[str, str | None]:
    """:func:`~thinfilm_mi.cli.render.scene_variant` over the grid's ``-D`` combinations: the
    first that needs a polarized variant sets it for every frame (a polarized variant
    renders the others too; a worker process holds one variant)."""
    seen: set = set()
    for frame in frames:
        if frame.defines not in seen:
            seen.add(frame.defines)
            chosen, notice = cli.scene_variant(scene, dict(frame.defines), variant)
            if notice:
                return chosen, notice
    return variant, None


def sweep(scene: str | os.PathLike, defines: Mapping[str, Any] | Sequence[str] | None = None,
          parameters: Mapping[str, Any] | Sequence[str] | None = None,
          out_dir: str | os.PathLike = DEFAULT_OUT_DIR, *,
          workers: int | None = None, scheduler: str | None = None, client=None,
          spp: int | None = None, size: tuple[int, int] | str | None = None,
          variant: str = DEFAULT_VARIANT, seed: int = 0, sensor: int = 0,
          max_pass_samples: int = DEFAULT_MAX_PASS_SAMPLES, threads: int | None = None,
          frames_per_task: int | None = None, contact_sheet: bool = True,
          progress: TextIO | bool | None = None,
          on_frame: Callable[[dict[str, Any]], None] | None = None,
          timeout: float | None = None, verbose: bool = False) -> SweepResult:
    """Render ``scene`` over a grid of parameters on Dask (see the module docstring).

    ``defines``: ``{name: VALUES}`` of the scene's ``$name`` parameters (or
    ``["name=VALUES", ...]``), ``parameters`` the same for ``mi.traverse``
    keys; VALUES is ``"START:STOP:STEP"``, ``"a,b,c"``, a number or an iterable.
    The cluster: ``client`` (a ``distributed.Client``, left open), else
    ``scheduler`` (an address), else a local cluster of ``workers`` processes
    (default: one per core, at most one per task; one per GPU for ``cuda_*``),
    closed at the end. ``threads``: Dr.Jit threads per worker (default: the
    cores divided among the local workers; on an external cluster, each worker's
    ``--nthreads``). ``on_frame(row)`` is called as each frame ends. ``timeout``
    (seconds) bounds the whole sweep: TimeoutError, handled like Ctrl-C.

    Returns a :class:`SweepResult`. Raises :class:`~thinfilm_mi.cli.render.UsageError`
    for bad arguments, KeyboardInterrupt / TimeoutError after cleaning up.
    """
    t_start = time.perf_counter()
    stream = sys.stderr if progress is True else (progress or None)

    def log(msg: str) -> None:
        if stream is not None or verbose:
            print(f"{PROG}: {msg}", file=stream or sys.stderr)

    # ---- arguments
    scene_file = Path(scene)
    if not scene_file.is_file():
        raise UsageError(f"scene file not found: {scene_file}")
    if sum(x is not None for x in (client, scheduler, workers)) > 1:
        raise UsageError("give at most one of workers, scheduler and client")
    if workers is not None and (isinstance(workers, bool) or int(workers) != workers or workers < 1):
        raise UsageError(f"--workers must be an integer >= 1, got {workers!r}")
    for name, value, low in (("spp", spp, 1), ("threads", threads, 1),
                             ("frames_per_task", frames_per_task, 1), ("sensor", sensor, 0),
                             ("max_pass_samples", max_pass_samples, 1)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < low):
            raise UsageError(f"{name} must be an integer >= {low}, got {value!r}")
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise UsageError(f"seed must be an integer, got {seed!r}")
    if timeout is not None and not (isinstance(timeout, (int, float)) and timeout > 0):
        raise UsageError(f"timeout must be a number of seconds > 0, got {timeout!r}")
    if isinstance(size, str):
        size = cli.parse_size(size)
    elif size is not None:
        try:
            size = cli.parse_size("x".join(str(int(v)) for v in size))
        except (TypeError, ValueError):
            raise UsageError(f"size {size!r}: expected (width, height)") from None
    if not isinstance(variant, str) or not re.fullmatch(r"[a-z]+(_[a-z0-9]+)+", variant):
        raise UsageError(f"--variant {variant!r}: not a Mitsuba variant name (e.g. {DEFAULT_VARIANT})")
    axes = parse_axes(defines, "define") + parse_axes(parameters, "traverse")
    frames = build_frames(axes)
    variant, notice = grid_variant(scene_file, frames, variant)
    if notice:
        log(notice)
    names = [a.name for a in axes]
    out = Path(out_dir).resolve()
    (out / FRAMES_DIR).mkdir(parents=True, exist_ok=True)

    if variant.startswith("cuda_") and workers is None and client is None and scheduler is None:
        workers = len(gpu_worker_envs(visible_gpus()))
    local_workers = workers or min(_cpu_count(), len(frames))
    if threads is None and client is None and scheduler is None:
        threads = max(1, _cpu_count() // local_workers)
    job = Job(scene=str(scene_file.resolve()), out_dir=str(out), variant=variant, spp=spp,
              size=size, seed=seed, sensor=sensor, max_pass_samples=max_pass_samples,
              threads=threads, verbose=verbose)

    # ---- what is left to do
    _remove_parts(out / FRAMES_DIR)
    rows: dict[int, dict[str, Any]] = _previous_rows(out, job, frames, names, log)
    skipped = len(rows)
    todo = [f for f in frames if f.index not in rows]
    manifest = out / MANIFEST

    def flush() -> None:
        # manifest first: a crash in between leaves old settings, which make
        # the next run render everything again rather than trust rows wrongly
        _write_manifest(manifest, names, (rows[f.index] for f in frames if f.index in rows))
        _write_atomic(out / SETTINGS, (json.dumps(_settings(job), indent=1) + "\n").encode())

    n_workers = 0
    if todo:
        n_workers = _run(job, todo, rows, total=len(frames),
                         workers=local_workers if client is None and scheduler is None else None,
                         scheduler=scheduler, client=client, frames_per_task=frames_per_task,
                         stream=stream, on_frame=on_frame, timeout=timeout, flush=flush)
    flush()
    ordered = [rows[f.index] for f in frames]
    sheet = write_contact_sheet(out / CONTACT_SHEET, out, axes, ordered) if contact_sheet else None
    return SweepResult(out_dir=out, columns=[*names, *COLUMNS], rows=ordered,
                       rendered=len(todo), skipped=skipped,
                       seconds=time.perf_counter() - t_start, workers=n_workers,
                       manifest=manifest, contact_sheet=sheet)


def _results(fut, chunk: Sequence[Frame]) -> list[tuple[int, dict[str, Any]]]:
    """``(frame index, row)`` of each frame of a finished task; a task that raised (its worker died
    ``ALLOWED_FAILURES + 1`` times, or it could not run) fails all its frames."""
    from distributed.scheduler import KilledWorker

    if fut.status == "finished":
        results = fut.result()
    else:
        exc = fut.exception()
        if isinstance(exc, KilledWorker):
            error = f"the worker process died {ALLOWED_FAILURES + 1} times while rendering this frame's task"
        else:
            error = f"{type(exc).__name__}: {one_line(exc)}"
        results = [{"index": f.index, "status": "failed", "error": error, "png": "", "seconds": 0.0}
                   for f in chunk]
    by_index = {f.index: f for f in chunk}
    rows = []
    for res in results:
        frame = by_index[res["index"]]
        rows.append((frame.index, {**frame.params, "exr": frame.exr if res["status"] == "ok" else "",
                                   **{k: v for k, v in res.items() if k != "index"},
                                   "rendered": True}))
    return rows


def _run(job: Job, todo: Sequence[Frame], rows: dict[int, dict[str, Any]], *, total: int,
         workers, scheduler, client, frames_per_task, stream, on_frame, timeout,
         flush) -> int:
    """Render ``todo`` on the cluster, adding to ``rows``; returns the number of
    workers. On any exit: stops the work, removes temporary files, and on an
    early exit (Ctrl-C, timeout, an error) records the frames that finished."""
    from distributed import as_completed

    client, cluster, own_client = _connect(workers, scheduler, client, job.variant)
    prefix = f"thinfilm-sweep-{secrets.token_hex(6)}-"
    futures: dict[Any, list[Frame]] = {}
    consumed: set = set()
    bar = _Progress(total, stream) if stream is not None else None
    failed = sum(r["status"] == "failed" for r in rows.values())
    finished = False
    try:
        client.register_plugin(SweepWorkerPlugin(job.variant, job.threads, job.verbose,
                                                 ignore_sigint=cluster is not None))
        n_workers = workers or len(client.nthreads())
        for i, chunk in enumerate(plan_tasks(todo, n_workers or 8, frames_per_task)):
            futures[client.submit(render_frames, job, chunk, key=f"{prefix}{i}", pure=False)] = chunk
        if bar:
            bar.update(len(rows), failed)
        last_flush = time.monotonic()
        for fut in as_completed(list(futures), timeout=timeout):
            consumed.add(fut)
            for index, row in _results(fut, futures[fut]):
                rows[index] = row
                failed += row["status"] == "failed"
                if bar:
                    bar.update(len(rows), failed)
                if on_frame is not None:
                    on_frame(row)
            if time.monotonic() - last_flush >= MANIFEST_INTERVAL:
                flush()
                last_flush = time.monotonic()
        finished = True
        return n_workers
    finally:
        if bar:
            bar.close()
        if not finished:  # Ctrl-C, timeout, an error in on_frame: keep what is done, stop the rest
            for fut, chunk in futures.items():
                if fut not in consumed and fut.status == "finished":
                    rows.update(_results(fut, chunk))
            pending = [f for f in futures if not f.done()]
            if pending:
                client.cancel(pending)
                if cluster is None:
                    _drain(client, prefix, DRAIN_TIMEOUT)
        if own_client:
            client.close()
        if cluster is not None:
            cluster.close()  # after the worker processes are gone, nothing writes any more
        _remove_parts(Path(job.out_dir) / FRAMES_DIR)
        if not finished:
            flush()


def _drain(client, prefix: str, timeout: float) -> None:
    """Wait (at most ``timeout`` s) until no task of this sweep still runs on
    the external cluster: a cancelled task finishes its frame regardless."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            running = client.run(_running_keys, prefix)
        except Exception:  # the cluster is going away: nothing more to wait for
            return
        if not any(running.values()):
            return
        time.sleep(0.05)  # polling the workers' state, not a synchronisation by delay
    print(f"{PROG}: frames still running on the cluster after {timeout:.0f} s; not waiting longer",
          file=sys.stderr)


# --------------------------------------------------------------------------------------
# command line


def build_parser() -> argparse.ArgumentParser:
    parser = cli.ArgumentParser(
        prog=PROG,
        description="Render a scene over a grid of parameter values on Dask (a local cluster "
                    "of worker processes, or a running cluster), one EXR + PNG per frame, "
                    "with manifest.csv and contact_sheet.png. Rerunning resumes.")
    parser.add_argument("scene", help="Mitsuba 3 scene file (XML)")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="name=VALUES",
                        help="a grid axis over the scene parameter $name: START:STOP:STEP "
                             "(STOP included), a,b,c or one value (repeatable)")
    parser.add_argument("-P", dest="parameters", action="append", default=[], metavar="key=VALUES",
                        help="a grid axis over a mi.traverse parameter (numbers), set on the "
                             "loaded scene without reloading it (repeatable)")
    parser.add_argument("--out-dir", default=DEFAULT_OUT_DIR,
                        help=f"output folder (default {DEFAULT_OUT_DIR})")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="worker processes of the local cluster (default: one per core, "
                            "one per GPU for cuda_* variants)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use a running Dask cluster, e.g. tcp://10.0.0.5:8786")
    parser.add_argument("--threads", type=int, metavar="T",
                        help="Dr.Jit threads per worker (default: cores / local workers; on "
                             "a cluster, each worker's --nthreads)")
    parser.add_argument("--frames-per-task", type=int, metavar="K",
                        help="frames of one scene load per Dask task (default: about two "
                             "tasks per worker)")
    parser.add_argument("--spp", type=int, metavar="N", help="samples per pixel")
    parser.add_argument("--size", metavar="WxH", help="film size in pixels, e.g. 320x240")
    parser.add_argument("--variant", default=DEFAULT_VARIANT,
                        help=f"Mitsuba variant (default {DEFAULT_VARIANT}); a scene that needs a "
                             "polarized one is rendered in the polarized variant of its family")
    parser.add_argument("--seed", type=int, default=0, help="random seed of every frame (default 0)")
    parser.add_argument("--sensor", type=int, default=0, metavar="INDEX",
                        help="which sensor to render (default 0)")
    parser.add_argument("--max-pass-samples", type=int, default=DEFAULT_MAX_PASS_SAMPLES,
                        metavar="N", help="at most N samples (pixels x spp) per render pass")
    parser.add_argument("--timeout", type=float, metavar="SECONDS",
                        help="give up (like Ctrl-C) after this long")
    parser.add_argument("--no-contact-sheet", action="store_true", help="skip contact_sheet.png")
    parser.add_argument("--verbose", action="store_true", help="tracebacks and Mitsuba warnings")
    return parser


def summary(result: SweepResult) -> str:
    where = f"{result.workers} worker(s)" if result.rendered else "nothing to render"
    text = (f"{PROG}: {len(result)} frames ({result.rendered} rendered, {result.skipped} already "
            f"done) in {result.seconds:.1f} s with {where}: {len(result.ok)} ok, "
            f"{len(result.failed)} failed -> {result.manifest}")
    if result.contact_sheet:
        text += f", {result.contact_sheet}"
    for row in result.failed[:3]:
        params = " ".join(f"{k}={row[k]}" for k in result.columns[:-len(COLUMNS)])
        text += f"\n{PROG}: failed: {params}: {row['error']}"
    if len(result.failed) > 3:
        text += f"\n{PROG}: ... and {len(result.failed) - 3} more (see the manifest)"
    return text


def sweep_main(argv: Sequence[str] | None = None) -> int:
    """``thinfilm-render sweep ...``: 0 all frames ok, 1 some failed, 2 bad
    command line or set-up, 130 interrupted."""
    argv = list(sys.argv[1:] if argv is None else argv)
    verbose = "--verbose" in argv
    try:
        args = build_parser().parse_args(argv)
    except UsageError as e:
        return cli.report_error(_prog_error(e), verbose)
    except SystemExit as e:  # --help
        return int(e.code or 0)
    try:
        if not args.defines and not args.parameters:
            raise UsageError("no grid: give at least one -D name=VALUES or -P key=VALUES")
        result = sweep(args.scene, args.defines, args.parameters, args.out_dir,
                       workers=args.workers, scheduler=args.scheduler, spp=args.spp,
                       size=args.size, variant=args.variant, seed=args.seed, sensor=args.sensor,
                       max_pass_samples=args.max_pass_samples, threads=args.threads,
                       frames_per_task=args.frames_per_task,
                       contact_sheet=not args.no_contact_sheet, progress=sys.stderr,
                       timeout=args.timeout, verbose=args.verbose)
    except CLIError as e:
        return cli.report_error(_prog_error(e), args.verbose)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; finished frames are in the manifest, rerun to resume",
              file=sys.stderr)
        return 130
    except TimeoutError:
        print(f"{PROG}: error: timed out after {args.timeout} s; rerun to resume", file=sys.stderr)
        return 1
    except Exception as e:  # the cluster could not start, etc.: one line, as thinfilm-render
        err = RenderFailure(f"{type(e).__name__}: {one_line(e)}")
        err.__cause__ = e
        return cli.report_error(_prog_error(err), args.verbose)
    print(summary(result), file=sys.stderr)
    return 1 if result.failed else 0


def _prog_error(error: CLIError) -> CLIError:
    """``report_error`` prints ``thinfilm-render: error:``; say ``sweep`` too."""
    out = type(error)(f"sweep: {error}")
    out.__cause__ = error.__cause__
    return out
