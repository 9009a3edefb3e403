"""Parameter sweeps on Dask: :func:`thinfilm_mi.sweep` (and ``thinfilm-render sweep``,
:mod:`thinfilm_mi.cli.sweep`).

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
  loaded scene, e.g. ``-P teapot.bsdf.layers.0.thickness=100:800:25``; the end
  of one key alone (``bsdf.layers.0.thickness``) or a shape's path to a BSDF with
  its own id names it too, and the key chosen is said on stderr
  (:mod:`~thinfilm_mi.batch.keys`). Frames
  that differ only in ``-P`` values share one loaded scene: they are rendered
  one after the other by one worker task (a chunk), and film thicknesses being
  opaque Dr.Jit values, no kernel is compiled again.

``VALUES`` is a range ``START:STOP:STEP`` (``STOP`` included when it lies on
the grid), a comma-separated list ``a,b,c`` or a single value (on the command
line a value cannot hold a comma; from Python, pass a list).

Work is split into tasks of up to ``frames_per_task`` frames of the same ``-D``
combination (by default about two tasks per worker, never mixing scenes:
:func:`~thinfilm_mi.batch.grid.plan_tasks`). Each worker process is set up once by
:class:`~thinfilm_mi.batch.worker.SweepWorkerPlugin` (a Dask worker plugin):
Mitsuba variant, thin-film plugin registration (registration is per process),
Dr.Jit thread count. A worker renders one frame at a time and keeps the last
loaded scene, so consecutive tasks of one combination load it once.

Outputs in ``OUT_DIR`` (:mod:`thinfilm_mi.batch.outputs`):

- ``frames/<name>.exr`` and ``frames/<name>.png`` per frame (the EXR header
  holds the frame's parameters), each written to a hidden temporary name
  (``.<name>.part-*``) and renamed when complete;
- ``manifest.csv``: one row per finished frame, in grid order: the parameters,
  ``exr`` and ``png`` (relative to ``OUT_DIR``), ``seconds``, ``status``
  (``ok`` or ``failed``), ``error``; rewritten atomically while the sweep runs;
- ``contact_sheet.png``: every frame, labelled with the parameters that vary
  (needs matplotlib, which the ``[sweep]`` extra installs);
- ``sweep.json``: the settings that are not grid axes (scene, variant, size,
  spp, seed, sensor).

The modules of a sweep, one job each: :mod:`~thinfilm_mi.batch.grid` (axes,
frames, tasks), :mod:`~thinfilm_mi.batch.worker` (the worker processes),
:mod:`~thinfilm_mi.batch.outputs` (the files) and this one (the cluster and the
client's loop). Dask ``distributed`` is the ``[sweep]`` extra
(``pip install 'thinfilm-mi[sweep]'``): importing this module without it raises
:class:`~thinfilm_mi.errors.MissingExtra`, which says so.

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
:func:`thinfilm_mi.batch.scene.scene_variant`, for any of the grid's ``-D`` combinations:
:func:`grid_variant`)
is rendered in the polarized variant of the requested one's family, as
``thinfilm-render`` does; it is said on the progress stream and ``sweep.json``
records it.

``cuda_*`` variants: the local cluster starts one worker per visible GPU, each
with its own ``CUDA_VISIBLE_DEVICES`` (:func:`gpu_worker_envs`); on an external
cluster start one worker per GPU the same way (or with dask-cuda).
"""
from __future__ import annotations

import logging
import os
import re
import secrets
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence, TextIO

from tqdm import tqdm

from thinfilm_mi.batch.grid import (
    COLUMNS,
    DEFINE,
    FRAMES_DIR,
    TRAVERSE,
    Frame,
    Job,
    build_frames,
    parse_axes,
    plan_tasks,
)
from thinfilm_mi.batch.outputs import (
    CONTACT_SHEET,
    DEFAULT_OUT_DIR,
    MANIFEST,
    previous_rows,
    remove_parts,
    save_manifest,
    write_contact_sheet,
)
from thinfilm_mi.batch.scene import (
    DEFAULT_MAX_PASS_SAMPLES,
    DEFAULT_VARIANT,
    one_line,
    parse_size,
    progress_bar,
    scene_variant,
)
from thinfilm_mi.batch.scene import PROG as RENDER_PROG
from thinfilm_mi.batch.worker import SweepWorkerPlugin, render_frames, running_keys
from thinfilm_mi.errors import UsageError, require_extra

__all__ = [
    "sweep", "SweepResult", "grid_variant", "local_cluster", "visible_gpus", "gpu_worker_envs",
    "ALLOWED_FAILURES", "PROG",
]

#: the prefix of a sweep's messages on stderr
PROG = f"{RENDER_PROG} sweep"
#: a task is run again after its worker died, up to this many times (Dask's
#: ``allowed_failures``); then its frames are recorded as failed
ALLOWED_FAILURES = 2
#: seconds between two rewrites of the manifest while frames come in
MANIFEST_INTERVAL = 1.0
#: seconds to wait, after Ctrl-C, for frames still running on an external cluster
DRAIN_TIMEOUT = 120.0


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


@dataclass
class SweepResult:
    """The table a sweep returns: one row per frame in grid order (the manifest's
    columns, plus for frames rendered by this call ``scene_loaded``, ``kernels``
    (JIT kernels compiled or read from disk for it), ``worker`` and, with ``-P``
    axes, ``notes``: which key each ``-P`` name that is not a key stands for)."""

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
    """:func:`~thinfilm_mi.batch.scene.scene_variant` over the grid's ``-D`` combinations: the
    first that needs a polarized variant sets it for every frame (a polarized variant
    renders the others too; a worker process holds one variant)."""
    seen: set = set()
    for frame in frames:
        if frame.defines not in seen:
            seen.add(frame.defines)
            chosen, notice = scene_variant(scene, dict(frame.defines), variant)
            if notice:
                return chosen, notice
    return variant, None


def _checked_arguments(scene_file: Path, *, client, scheduler, workers, spp, threads,
                       frames_per_task, sensor, max_pass_samples, seed, timeout, size, variant,
                       contact_sheet) -> tuple[int, int] | None:
    """Raise :class:`~thinfilm_mi.errors.UsageError` for a bad argument of :func:`sweep`
    (before anything is rendered); returns ``size`` as ``(width, height)`` or ``None``."""
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
        size = parse_size(size)
    elif size is not None:
        try:
            size = parse_size("x".join(str(int(v)) for v in size))
        except (TypeError, ValueError):
            raise UsageError(f"size {size!r}: expected (width, height)") from None
    if not isinstance(variant, str) or not re.fullmatch(r"[a-z]+(_[a-z0-9]+)+", variant):
        raise UsageError(f"--variant {variant!r}: not a Mitsuba variant name (e.g. {DEFAULT_VARIANT})")
    if contact_sheet:  # say so now, not after the frames are rendered
        require_extra("matplotlib", "plot",
                      "the contact sheet (skip it: --no-contact-sheet, contact_sheet=False)")
    return size


def _local_workers(variant: str, n_frames: int, workers: int | None, threads: int | None, *,
                   external: bool) -> tuple[int, int | None]:
    """``(workers, threads)`` of :func:`sweep`: a local cluster's processes (one per GPU for
    ``cuda_*``, else one per core, at most one per frame) and the Dr.Jit threads of each
    (the cores divided among them; an ``external`` cluster's own unless given)."""
    if variant.startswith("cuda_") and workers is None and not external:
        workers = len(gpu_worker_envs(visible_gpus()))
    local_workers = workers or min(_cpu_count(), n_frames)
    if threads is None and not external:
        threads = max(1, _cpu_count() // local_workers)
    return local_workers, threads


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

    Returns a :class:`SweepResult`. Raises :class:`~thinfilm_mi.errors.UsageError`
    for bad arguments (:class:`~thinfilm_mi.errors.MissingExtra` when the contact
    sheet is asked for and matplotlib is missing), KeyboardInterrupt / TimeoutError
    after cleaning up.
    """
    t_start = time.perf_counter()
    stream = sys.stderr if progress is True else (progress or None)

    def log(msg: str) -> None:
        if stream is not None or verbose:
            tqdm.write(f"{PROG}: {msg}", file=stream or sys.stderr)  # above a progress bar

    scene_file = Path(scene)
    size = _checked_arguments(scene_file, client=client, scheduler=scheduler, workers=workers,
                              spp=spp, threads=threads, frames_per_task=frames_per_task,
                              sensor=sensor, max_pass_samples=max_pass_samples, seed=seed,
                              timeout=timeout, size=size, variant=variant,
                              contact_sheet=contact_sheet)
    axes = parse_axes(defines, DEFINE) + parse_axes(parameters, TRAVERSE)
    frames = build_frames(axes)
    variant, notice = grid_variant(scene_file, frames, variant)
    if notice:
        log(notice)
    names = [a.name for a in axes]
    out = Path(out_dir).resolve()
    (out / FRAMES_DIR).mkdir(parents=True, exist_ok=True)

    local_workers, threads = _local_workers(variant, len(frames), workers, threads,
                                            external=client is not None or scheduler is not None)
    job = Job(scene=str(scene_file.resolve()), out_dir=str(out), variant=variant, spp=spp,
              size=size, seed=seed, sensor=sensor, max_pass_samples=max_pass_samples,
              threads=threads, verbose=verbose)

    # ---- what is left to do
    remove_parts(out / FRAMES_DIR)
    rows: dict[int, dict[str, Any]] = previous_rows(out, job, frames, names, log)
    skipped = len(rows)
    todo = [f for f in frames if f.index not in rows]
    manifest = out / MANIFEST

    def flush() -> None:
        save_manifest(out, job, names, (rows[f.index] for f in frames if f.index in rows))

    n_workers = 0
    if todo:
        n_workers = _run(job, todo, rows, total=len(frames),
                         workers=local_workers if client is None and scheduler is None else None,
                         scheduler=scheduler, client=client, frames_per_task=frames_per_task,
                         stream=stream, on_frame=on_frame, timeout=timeout, flush=flush, log=log)
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
         flush, log) -> int:
    """Render ``todo`` on the cluster, adding to ``rows``; returns the number of
    workers. Each line a frame notes (which key a ``-P`` name stands for) is
    logged once. On any exit: stops the work, removes temporary files, and on an
    early exit (Ctrl-C, timeout, an error) records the frames that finished."""
    from distributed import as_completed

    client, cluster, own_client = _connect(workers, scheduler, client, job.variant)
    prefix = f"thinfilm-sweep-{secrets.token_hex(6)}-"
    futures: dict[Any, list[Frame]] = {}
    consumed: set = set()
    noted: set = set()
    bar = progress_bar(stream, total=total, unit="frame", desc=PROG, initial=len(rows))
    failed = sum(r["status"] == "failed" for r in rows.values())
    finished = False
    try:
        client.register_plugin(SweepWorkerPlugin(job.variant, job.threads, job.verbose,
                                                 ignore_sigint=cluster is not None))
        n_workers = workers or len(client.nthreads())
        for i, chunk in enumerate(plan_tasks(todo, n_workers or 8, frames_per_task)):
            futures[client.submit(render_frames, job, chunk, key=f"{prefix}{i}", pure=False)] = chunk
        bar.set_postfix_str(f"{failed} failed")
        last_flush = time.monotonic()
        for fut in as_completed(list(futures), timeout=timeout):
            consumed.add(fut)
            for index, row in _results(fut, futures[fut]):
                rows[index] = row
                for note in row.get("notes", ()):
                    if note not in noted:
                        noted.add(note)
                        log(note)
                failed += row["status"] == "failed"
                bar.set_postfix_str(f"{failed} failed", refresh=False)
                bar.update(1)
                if on_frame is not None:
                    on_frame(row)
            if time.monotonic() - last_flush >= MANIFEST_INTERVAL:
                flush()
                last_flush = time.monotonic()
        finished = True
        return n_workers
    finally:
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
        remove_parts(Path(job.out_dir) / FRAMES_DIR)
        if not finished:
            flush()


def _drain(client, prefix: str, timeout: float) -> None:
    """Wait (at most ``timeout`` s) until no task of this sweep still runs on
    the external cluster: a cancelled task finishes its frame regardless."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            running = client.run(running_keys, prefix)
        except Exception:  # the cluster is going away: nothing more to wait for
            return
        if not any(running.values()):
            return
        time.sleep(0.05)  # polling the workers' state, not a synchronisation by delay
    print(f"{PROG}: frames still running on the cluster after {timeout:.0f} s; not waiting longer",
          file=sys.stderr)

