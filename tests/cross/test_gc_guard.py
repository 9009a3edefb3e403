"""No segfault whatever the garbage collector does (:mod:`thinfilm_mi.render.gc_guard`).

Each check runs ``tests/support/gc_guard_child.py`` in a fresh process: the loop users run
(load, render, a refused edit whose exception is kept in a local, render, return), so
that every later render traces the BSDFs of scenes that only reference cycles keep,
while Python code that allocates runs inside the trace.

* The defect is Mitsuba's, and the test can fail: a plain Python BSDF, in a process
  that does not import ``thinfilm_mi``, crashes (SIGSEGV) within a few iterations; so
  do our plugins, most runs, with the guard taken out of ``gc.callbacks``. A
  use-after-free crashes only when the freed memory was reused, so the child also
  counts the BSDFs freed while a symbolic call is traced: the defect's precondition,
  which a run without the guard shows even when it survives, and a guarded run never.
* With the guard, the same plain BSDF survives the loop with the default collector and
  with a pass at every allocation (``gc.set_threshold(1, 1, 1)``), and the dropped
  BSDFs are collected as the loop goes (at most a few alive at any iteration, none
  after a final collection): memory stays bounded.
* Every thin-film plugin, bare, inside ``blendbsdf`` and (those that do not transmit)
  inside ``twosided``, in a spectral, an RGB and a polarized variant, with a pass at
  every allocation. Before the guard these crashed on the second iteration.

The suite runs each plugin configuration once or twice per variant (each iteration
compiles a new kernel, since the set of BSDF instances to trace changes: 1-4 s in a
spectral variant). ``benchmarks/gc_guard_bench.py`` runs the 200-iteration matrix of
the issue (every variant, both collector settings) and measures the guard's cost.
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
#: Dropped BSDFs alive at the start of an iteration, at most. The loop drops one scene
#: per iteration. After a trace in which a pass was deferred, the guard collects them
#: all; when no pass was deferred, they wait in the oldest generation for Python's own
#: rule (a full pass once a quarter more objects have survived the young ones), as any
#: long-lived garbage does. Measured: at most 1-8 in the plugin loops, 13 in 200 plain
#: iterations; a guard that did not collect keeps them all (199 of 200, measured on a
#: first version that only unfroze).
MAX_ALIVE = 25


def _run(variant, iterations, threshold, kind, timeout=600):
    out = subprocess.run([sys.executable, str(CHILD), variant, str(iterations), threshold, kind],
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
    # 200 iterations: ~5 s (default) and ~25 s (a pass at every allocation)
    _survived(_run("llvm_ad_rgb", 200, threshold, "plain+guard"), 200)


#: (variant, iterations): the 13 plugin configurations twice in RGB, once elsewhere
PLUGIN_RUNS = [("llvm_ad_rgb", 26), ("llvm_ad_spectral", 13), ("llvm_ad_spectral_polarized", 13)]


@pytest.mark.slow
@pytest.mark.parametrize("variant, iterations", PLUGIN_RUNS, ids=[v for v, _ in PLUGIN_RUNS])
def test_every_plugin_and_wrapper_survives_a_pass_at_every_allocation(variant, iterations):
    if variant not in mi.variants():
        pytest.skip(f"no {variant} variant")
    _survived(_run(variant, iterations, "1", "thinfilm"), iterations)


def test_the_guard_is_installed_by_importing_the_package():
    import gc

    import thinfilm_mi  # noqa: F401
    from thinfilm_mi.render import gc_guard

    assert gc_guard.installed()
    gc_guard.install()   # idempotent
    assert sum(cb is gc_guard._guard for cb in gc.callbacks) == 1


def test_a_forked_child_starts_its_own_watcher():
    """A child made by fork has no watcher thread: the guard must not think it has one
    (it would owe collections that nobody asks the main thread for)."""
    import os

    from thinfilm_mi.render import gc_guard

    guard = gc_guard._guard
    saved, guard.watcher = guard.watcher, object()   # as after a first deferred pass
    try:
        pid = os.fork()
        if pid == 0:
            os._exit(0 if guard.watcher is None else 1)
        _, status = os.waitpid(pid, 0)
        assert os.waitstatus_to_exitcode(status) == 0
    finally:
        guard.watcher = saved
