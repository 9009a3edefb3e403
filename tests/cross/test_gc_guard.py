"""No segfault whatever the garbage collector does, on any thread (:mod:`thinfilm_mi.render.gc_guard`).

Each check runs ``tests/support/gc_guard_child.py`` in a fresh process: the loop users run
(load, render, a refused edit whose exception is kept in a local, render, return), so
that every later render traces the BSDFs of scenes that only reference cycles keep,
while Python code that allocates runs inside the trace or on another thread.

* The defect is Mitsuba's, and the test can fail: a plain Python BSDF, in a process
  that does not import ``thinfilm_mi``, crashes (SIGSEGV) within a few iterations, on
  the main thread and on a worker thread while the main thread runs Python; so do our
  plugins, most runs, with the guard taken out of ``gc.callbacks``. A use-after-free
  crashes only when the freed memory was reused, so the child also counts the BSDFs
  freed while a symbolic call is traced (or, from another thread, while a render runs):
  the defect's precondition, which a run without the guard shows even when it
  survives, and a guarded run never.
* With the guard, the same plain BSDF survives the loop with the default collector and
  with a pass at every allocation (``gc.set_threshold(1, 1, 1)``), on the main thread
  and on a worker, and the dropped BSDFs are collected as the loop goes (at most a few
  alive at any iteration, none after a final collection): memory stays bounded.
* Every thin-film plugin, bare, inside ``blendbsdf`` and (those that do not transmit)
  inside ``twosided``, rendered on a worker thread while the main thread runs Python,
  in an RGB and a spectral variant, with both collector settings; two worker threads
  rendering different scenes at once; and a sweep whose frames, rendered on Dask worker
  threads of the same process, alternate between refused and good ``-P`` values.

* Loads and renders take turns (the second defect: a render traces what a load on
  another thread registered before it was built, ``tests/support/load_race_child.py``,
  too rare in a short run to be a test): checked on the guard's own blocks, in threads.

Each plugin iteration compiles a new kernel (the set of BSDF instances to trace
changes): 0.5-3 s. ``benchmarks/gc_guard_bench.py`` runs the longer matrix and
measures the guard's cost.
"""
from __future__ import annotations

import re
import signal
import subprocess
import sys

import mitsuba as mi
import pytest

from tests.support import ROOT

CHILD = ROOT / "tests" / "support" / "gc_guard_child.py"
SWEEP_CHILD = ROOT / "tests" / "support" / "gc_sweep_child.py"
#: Dropped BSDFs alive at the start of an iteration, at most. The loop drops one scene
#: per iteration. After a trace in which a pass was deferred, the guard collects them
#: all; when no pass was deferred, they wait in the oldest generation for Python's own
#: rule (a full pass once a quarter more objects have survived the young ones), as any
#: long-lived garbage does. Measured: at most 1-8 in the plugin loops, 13 in 200 plain
#: iterations; a guard that did not collect keeps them all (199 of 200, measured on a
#: first version that only unfroze).
MAX_ALIVE = 25


def _run(variant, iterations, threshold, kind, where="main", timeout=600):
    out = subprocess.run([sys.executable, str(CHILD), variant, str(iterations), threshold, kind, where],
                         capture_output=True, text=True, timeout=timeout)
    return out.returncode, out.stdout.strip(), out.stderr.strip()[-1500:]


RESULT = re.compile(r"ok (\d+) alive=(\d+) max_alive=(\d+) freed_in_trace=(\d+)")


def _survived(result, iterations):
    rc, out, err = result
    assert rc == 0, f"the child died with status {rc}: {out[-500:]} {err}"
    m = RESULT.fullmatch(out.splitlines()[-1])
    assert m and int(m[1]) == iterations, out
    alive, most, freed_in_trace = int(m[2]), int(m[3]), int(m[4])
    assert freed_in_trace == 0, f"{freed_in_trace} BSDFs were freed inside a trace"
    assert alive == 0, f"{alive} dropped BSDFs survive a final gc.collect()"
    assert most <= MAX_ALIVE, f"{most} dropped BSDFs alive at once: the guard does not free them"


def _shows_the_defect(result):
    """A use-after-free crashes only when the freed memory has been reused: the defect
    shows as a segfault, or, in a run that survived, as BSDFs freed inside a trace."""
    rc, out, err = result
    if rc == -signal.SIGSEGV:
        return
    m = RESULT.fullmatch(out.splitlines()[-1]) if rc == 0 and out else None
    assert m and int(m[4]) > 0, f"expected the defect (a segfault, or BSDFs freed inside a trace), got " \
                                f"status {rc}: {out[-300:]} {err[-1500:]}"


@pytest.mark.parametrize("variant", ["llvm_ad_rgb", "llvm_ad_spectral"])
def test_the_defect_crashes_a_plain_python_bsdf_without_the_guard(variant):
    _shows_the_defect(_run(variant, 30, "default", "plain"))


def test_our_plugins_crash_with_the_guard_taken_out():
    """The guard is what protects our plugins: without it the loop over every plugin
    frees BSDFs inside traces, and most runs die of it (SIGSEGV within a few iterations;
    measured: 8 of 11 runs, the others freed 15 BSDFs inside traces and survived)."""
    _shows_the_defect(_run("llvm_ad_rgb", 26, "default", "thinfilm-unguarded"))


@pytest.mark.parametrize("threshold", ["default", "1"])
def test_the_guard_keeps_a_plain_python_bsdf_alive_and_frees_it_after(threshold):
    # 60 iterations (30 with a pass at every allocation): a guard that did not collect
    # would keep them all, over MAX_ALIVE
    iterations = 60 if threshold == "default" else 30
    _survived(_run("llvm_ad_rgb", iterations, threshold, "plain+guard"), iterations)


@pytest.mark.parametrize("threshold", ["default", "1"])
def test_a_plain_python_bsdf_on_a_worker_thread(threshold):
    """The thread probe without our package crashes (the test can fail); with the guard
    (``install`` alone: the plain BSDF's methods are not ours to wrap) it survives."""
    _shows_the_defect(_run("llvm_ad_rgb", 30, threshold, "plain", "worker"))
    _survived(_run("llvm_ad_rgb", 15, threshold, "plain+guard", "worker"), 15)


#: every plugin configuration once (15: six plugins bare and in blendbsdf, four in twosided)
CONFIGURATIONS = 15
#: (variant, collector): 10-50 s each, the spectral pass at every allocation the longest
PLUGIN_RUNS = [(v, t) for v in ("llvm_ad_rgb", "llvm_ad_spectral") for t in ("default", "1")]


@pytest.mark.slow
@pytest.mark.parametrize("variant, threshold", PLUGIN_RUNS, ids=[f"{v}-{t}" for v, t in PLUGIN_RUNS])
def test_every_plugin_and_wrapper_survives_on_a_worker_thread(variant, threshold):
    _survived(_run(variant, CONFIGURATIONS, threshold, "thinfilm", "worker"), CONFIGURATIONS)


@pytest.mark.slow
def test_two_worker_threads_render_different_scenes_at_once():
    # 6 iterations each, a pass at every allocation: ~25 s (each render compiles anew,
    # since each thread's traces see the other's BSDFs)
    _survived(_run("llvm_ad_rgb", 6, "1", "thinfilm", "workers"), 6)


@pytest.mark.slow
@pytest.mark.parametrize("threshold", ["default", "1"])
def test_a_sweep_on_worker_threads_with_refused_frames(tmp_path, threshold):
    """Frames on Dask worker threads of one process, every other one refused: no crash,
    every good frame written, every refused one recorded (~10 s each)."""
    out = subprocess.run([sys.executable, str(SWEEP_CHILD), threshold, str(tmp_path / "sweep")],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, f"the child died with status {out.returncode}: {out.stderr[-1500:]}"
    assert out.stdout.split()[-3:] == ["ok", "3", "3"], out.stdout


def test_the_guard_is_installed_by_importing_the_package():
    import gc

    import thinfilm_mi  # noqa: F401
    from thinfilm_mi.render import gc_guard

    assert gc_guard.installed()
    gc_guard.install()   # idempotent
    assert sum(cb is gc_guard._guard for cb in gc.callbacks) == 1


def test_a_forked_child_forgets_the_other_threads():
    """A child made by fork has only the forking thread: a thread that was rendering in
    the parent must not keep the child deferring every pass."""
    import os

    from thinfilm_mi.render import gc_guard

    guard = gc_guard._guard
    guard.scoped[-1] = 1   # as while another thread renders
    try:
        pid = os.fork()
        if pid == 0:
            os._exit(0 if not guard.busy() and not guard.pass_lock.locked() else 1)
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0
    finally:
        guard.scoped.pop(-1, None)


def test_mi_render_is_covered_and_keeps_its_signature():
    import inspect

    import thinfilm_mi  # noqa: F401
    from thinfilm_mi.render import gc_guard

    assert mi.render.__wrapped_by_gc_guard__
    assert inspect.signature(mi.render) == inspect.signature(mi.render.__wrapped__)
    gc_guard.install()   # idempotent: not wrapped twice
    assert not getattr(mi.render.__wrapped__, "__wrapped_by_gc_guard__", False)


def test_rendering_nests_and_leaves_no_trace_of_the_thread():
    import threading

    from thinfilm_mi.render import gc_guard

    guard, me = gc_guard._guard, threading.get_ident()
    with gc_guard.rendering():
        with gc_guard.rendering():
            assert guard.scoped[me] == 2
        assert guard.scoped[me] == 1 and guard.busy()
    assert me not in guard.scoped


def test_our_traced_methods_are_wrapped_once_per_variant(llvm):
    import importlib

    import thinfilm_mi
    from thinfilm_mi.plugins import PLUGINS

    thinfilm_mi.register()
    thinfilm_mi.register()
    for name, (module, cls_name) in PLUGINS.items():
        cls = getattr(importlib.import_module(f"thinfilm_mi.plugins.{module}"), cls_name)
        for method in ("sample", "eval", "pdf", "eval_pdf"):
            f = getattr(cls, method)
            assert f.__wrapped_by_gc_guard__, (name, method)
            assert not getattr(f.__wrapped__, "__wrapped_by_gc_guard__", False), (name, method)


# -- loads and renders take turns (the second defect: a render traces what a load on
# another thread has registered before it is built; tests/support/load_race_child.py) --

#: seconds a thread that must wait is given to show that it did not (a thread that
#: waits as it should never gets through, however slow the machine)
HOLD = 0.5


def _in_thread(body):
    """``body`` on a new thread; returns ``(thread, done)``: ``done`` is set when it ends."""
    import threading

    done = threading.Event()

    def run():
        try:
            body()
        finally:
            done.set()
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, done


def _holding(block):
    """Hold ``block`` (a context manager) on another thread until the returned
    ``release`` event is set; returns once it is held."""
    import threading

    held, release = threading.Event(), threading.Event()

    def hold():
        with block:
            held.set()
            release.wait(60)
    _in_thread(hold)
    assert held.wait(60)
    return release


def test_mitsubas_loads_are_covered_and_keep_their_names_and_docs():
    import thinfilm_mi  # noqa: F401
    from thinfilm_mi.render import gc_guard

    for name in gc_guard.LOADS:
        load = getattr(mi, name)
        assert load.__wrapped_by_gc_guard__, name
        # (nanobind's functions have no inspect.signature: their docs carry it)
        assert (load.__name__, load.__doc__) == (name, load.__wrapped__.__doc__)
    gc_guard.install()   # idempotent: not wrapped twice
    assert not getattr(mi.load_dict.__wrapped__, "__wrapped_by_gc_guard__", False)


def test_a_load_waits_for_a_render_on_another_thread(llvm):
    from thinfilm_mi.render import gc_guard

    release = _holding(gc_guard.rendering())
    _, loaded = _in_thread(lambda: mi.load_dict({"type": "diffuse"}))
    assert not loaded.wait(HOLD), "a load ran beside a render"
    release.set()
    assert loaded.wait(60)


def test_a_render_waits_for_a_load_and_a_waiting_load_goes_first():
    import threading

    from thinfilm_mi.render import gc_guard

    order, lock = [], threading.Lock()

    def enter(block, name):
        with block:
            with lock:
                order.append(name)
    release_render = _holding(gc_guard.rendering())
    _, loaded = _in_thread(lambda: enter(gc_guard.loading(), "load"))
    while not gc_guard._turns.loads_waiting:    # the load waits for the render
        assert not loaded.wait(0.01)
    _, rendered = _in_thread(lambda: enter(gc_guard.rendering(), "render"))
    assert not rendered.wait(HOLD), "a render started while a load waited"
    release_render.set()
    assert loaded.wait(60) and rendered.wait(60)
    assert order == ["load", "render"]


def test_a_load_inside_a_load_never_waits_for_a_waiting_render():
    """A plugin's constructor that loads (on a loader thread, inside the outer load)
    while a render waits for the outer load: no deadlock."""
    from thinfilm_mi.render import gc_guard

    def render():
        with gc_guard.rendering():
            pass
    release_load = _holding(gc_guard.loading())
    _, rendered = _in_thread(render)
    assert not rendered.wait(HOLD), "a render started beside a load"

    def inner_load():
        with gc_guard.loading():
            pass
    _, inner = _in_thread(inner_load)
    assert inner.wait(60), "a load inside a load waited for the waiting render"
    release_load.set()
    assert rendered.wait(60)
    assert gc_guard._turns.kind is None and not gc_guard._turns.depth
