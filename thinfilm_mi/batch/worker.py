"""The worker side of a sweep (:mod:`thinfilm_mi.batch.sweeps`): what runs in each
Dask worker process.

Each worker process is set up once by :class:`SweepWorkerPlugin` (a Dask worker
plugin, :func:`setup_process`): Mitsuba variant, thin-film plugin registration
(registration is per process), Dr.Jit thread count. A task
(:func:`render_frames`) renders its frames one at a time on one loaded scene,
setting the ``-P`` values of each frame (:func:`set_parameters`), and keeps the
last loaded scene, so consecutive tasks of one ``-D`` combination load it once.
A frame that fails is a row with its error; the others go on.
"""
from __future__ import annotations

import os
import signal
import socket
import threading
import time
from pathlib import Path
from typing import Any, Sequence

from thinfilm_mi.batch.grid import Frame, Job, parse_scalar
from thinfilm_mi.batch.keys import parameter_names, resolve_all
from thinfilm_mi.batch.outputs import write_frame
from thinfilm_mi.batch.scene import (
    DEFAULT_VARIANT,
    load_scene,
    one_line,
    output_attributes,
    render_scene,
    setup_variant,
)
from thinfilm_mi.errors import RenderError, UsageError, require_extra

distributed = require_extra("distributed", "sweep", "a sweep (thinfilm_mi.sweep, thinfilm-render sweep)")

__all__ = ["SweepWorkerPlugin", "setup_process", "render_frames", "set_parameters", "running_keys"]

_SETUP_LOCK = threading.Lock()
_RENDER_LOCK = threading.Lock()
_PROCESS: dict[str, Any] = {}


def setup_process(variant: str, threads: int | None = None, verbose: bool = False) -> None:
    """Prepare this (worker) process once: Mitsuba variant, thin-film plugins,
    Dr.Jit thread count (``dr.set_thread_count``; None keeps it), Mitsuba's log
    level and Dr.Jit's kernel history (each frame counts the kernels it compiled)."""
    with _SETUP_LOCK:
        if _PROCESS.get("variant") != variant:
            setup_variant(variant)
            _PROCESS["variant"] = variant
        import drjit as dr
        import mitsuba as mi

        if threads and _PROCESS.get("threads") != threads:
            dr.set_thread_count(int(threads))
            _PROCESS["threads"] = threads
        mi.set_log_level(mi.LogLevel.Warn if verbose else mi.LogLevel.Error)
        dr.set_flag(dr.JitFlag.KernelHistory, True)


class SweepWorkerPlugin(distributed.WorkerPlugin):
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
        scene = load_scene(scene_file, dict(defines), size=job.size, spp=job.spp,
                           variant=job.variant)
        self.key, self.scene, self.params = key, scene, None
        return scene, None, True

    def drop(self) -> None:
        self.key = self.scene = self.params = None


_SCENES = _SceneCache()


def set_parameters(scene, params, values: Sequence[tuple[str, str]]):
    """Set ``-P`` values on a loaded scene (``params``: its ``mi.traverse``, or
    None to make it) and apply them; returns the parameters object and the lines
    saying which key a ``-P`` name that is not a key stands for (:mod:`.keys`)."""
    import drjit as dr
    import mitsuba as mi

    if params is None:
        params = mi.traverse(scene)
    keys, notes = resolve_all(parameter_names(scene, params), [name for name, _ in values])
    for name, text in values:
        key = keys[name]
        current = params[key]
        value = parse_scalar(name, text)
        if isinstance(current, (bool, int, float)):
            params[key] = type(current)(value)
        else:
            if dr.is_array_v(current) and dr.depth_v(current) == 1 and dr.width(current) != 1:
                held = "holds" if key == name else f"({key}) holds"
                raise UsageError(f"-P {name}: {held} {dr.width(current)} values; "
                                 "-P sets single numbers only")
            params[key] = type(current)(value)
    params.update()
    return params, notes


def _fresh_kernels() -> int:
    """JIT kernels launched since the last call that were not in this process's
    kernel cache (compiled, or loaded from Dr.Jit's disk cache); clears the history."""
    import drjit as dr

    return sum(1 for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT
               and (k.get("cache_disk", False) or not k.get("cache_hit", False)))


def _render_one(job: Job, frame: Frame) -> dict[str, Any]:
    """Render and write one frame; its result row (failures included)."""
    row: dict[str, Any] = {"index": frame.index, "status": "failed", "error": "", "png": "",
                           "scene_loaded": False, "kernels": 0,
                           "worker": f"{socket.gethostname()}:{os.getpid()}"}
    t0 = time.perf_counter()
    _fresh_kernels()  # clear
    try:
        scene, params, row["scene_loaded"] = _SCENES.get(job, frame.defines)
        if frame.traverse:
            _SCENES.params, row["notes"] = set_parameters(scene, params, frame.traverse)
        sensors = scene.sensors()
        if not 0 <= job.sensor < len(sensors):
            raise UsageError(f"--sensor {job.sensor}: the scene has {len(sensors)} sensor(s)")
        spp = job.spp if job.spp is not None else int(sensors[job.sensor].sampler().sample_count())
        image, channels, passes, seconds = render_scene(
            scene, spp, seed=job.seed, sensor=job.sensor, max_pass_samples=job.max_pass_samples)
        attributes = output_attributes(job.scene, job.variant, spp, seconds, job.seed, passes,
                                       frame.params)
        row["png"] = write_frame(job, frame, image, channels, attributes)
        row["status"] = "ok"
    except Exception as e:  # recorded in the manifest; the other frames go on
        _SCENES.drop()  # it may hold half-applied -P values
        row["error"] = one_line(e) if isinstance(e, RenderError) else f"{type(e).__name__}: {one_line(e)}"
    row["seconds"] = time.perf_counter() - t0
    row["kernels"] = _fresh_kernels()
    return row


def render_frames(job: Job, frames: Sequence[Frame]) -> list[dict[str, Any]]:
    """The task run on a worker: render ``frames`` (one ``-D`` combination) one
    after the other on one loaded scene; one result row per frame, failures included."""
    setup_process(job.variant, job.threads, job.verbose)
    with _RENDER_LOCK:  # one frame at a time per process, whatever --nthreads says
        return [_render_one(job, f) for f in frames]


def running_keys(prefix: str, dask_worker=None) -> list[str]:
    """Keys of this sweep's tasks still running on a worker (cancelled ones too);
    run on each worker by ``client.run`` (which passes ``dask_worker``)."""
    state = dask_worker.state
    return [str(ts.key) for ts in (state.executing | state.long_running) if str(ts.key).startswith(prefix)]
