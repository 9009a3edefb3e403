"""No cyclic garbage collection while Dr.Jit traces a symbolic call.

The defect (Mitsuba 3.9.1, Dr.Jit 1.5; upstream, not ours):

* A symbolic virtual call (``ad_call_symbolic``, how an LLVM or CUDA variant's
  ``PathIntegrator`` calls ``BSDF::eval_pdf_sample``) traces *every* registered
  instance of the BSDF domain, those of scenes already dropped included. It
  holds no reference to an instance while it traces it.
* Mitsuba's base ``BSDF::eval_pdf_sample`` calls ``eval_pdf()`` and then
  ``sample()`` on ``this``; ``blendbsdf``, ``twosided`` and other wrappers call
  their nested BSDFs the same way.
* A Python BSDF's traced methods run Python code, which allocates; an
  allocation may start a pass of the cyclic garbage collector. When that pass
  frees a dropped scene (a scene kept only by a reference cycle: a kept
  exception's traceback, a notebook's ``Out[]``, a self-referencing dict), the
  scene's BSDFs die with it, the one being traced included, and the next call
  on ``this`` is a use-after-free: a segfault in
  ``BSDF::eval_pdf_sample`` or ``BlendBSDF::eval_pdf``. A pass during the
  trace of a *live* scene's BSDF is harmless. Related upstream: mitsuba3 #771
  (a dropped Python emitter still traced) and PR #776 (the lifetime of Python
  plugin references). ``tests/cross/test_gc_guard.py`` runs a reproducer
  without this package: a plain Python BSDF, a dropped scene in a cycle, a
  render of another scene.

The guard (:func:`install`, called by :func:`thinfilm_mi.register` once per
process): a :data:`gc.callbacks` hook. When a collection starts while this
thread is inside a symbolic scope (``dr.JitFlag.SymbolicScope``), it calls
:func:`gc.freeze`, which moves every tracked object to the permanent
generation, so that this pass examines nothing and frees nothing. A watcher
thread then asks the main thread, with ``Py_AddPendingCall`` every 20 ms, to
run :func:`gc.unfreeze` and a full :func:`gc.collect` at its next safe point
between two bytecodes, once it is outside the symbolic scope (the flag is per
thread, so only the main thread can tell); a pass that starts on the main
thread outside a scope (a user's ``gc.collect()`` included) unfreezes first. Without that collection, the deferred
garbage would wait indefinitely: the passes that froze it never count toward
the growth that makes Python collect the oldest generation, where unfreezing
puts it, and a loop whose allocations all happen inside traces would keep
every dropped scene. It protects every Python plugin of the process, ours
and others', in every variant; scalar variants make no symbolic calls and
never defer.

Why this and not another fix: disabling the collector inside our methods
does not work (the pending count fires at the first allocation after
re-enabling it, while C++ is still inside the trace); overriding
``eval_pdf_sample`` in Python does not either (Mitsuba 3.9.1 never calls the
override); keeping our own instances alive does not protect a dropped
``blendbsdf`` or ``twosided`` around them, which is what dies there.

What it costs: one Python call and one flag read per collection, and one full
collection after each trace during which a pass was deferred (measured in
``benchmarks/gc_guard_bench.py``); garbage made during a trace waits for the
trace to end. Its side effects, process-wide: objects frozen by the user
with :func:`gc.freeze` are unfrozen by the first owed collection; and
only traces on the main thread are protected: a collection that another
thread starts while the main thread traces, or one owed while another thread
traces, is not deferred (Mitsuba renders and traces on the calling thread).
"""
from __future__ import annotations

import ctypes
import gc
import os
import threading
import time

__all__ = ["install", "installed", "deferred_collections"]

_lock = threading.Lock()


class _Guard:
    """The hook and its state: whether it froze the heap, how many passes it
    deferred, and the watcher that asks the main thread for the owed collection."""

    #: seconds between two requests for the owed collection while one is owed
    POLL = 0.02

    def __init__(self, drjit) -> None:
        self.flag = drjit.flag
        self.symbolic = drjit.JitFlag.SymbolicScope
        self.frozen = False
        self.deferred = 0
        self.collections = 0
        self.owed = threading.Event()
        self.watcher: threading.Thread | None = None
        # a C function pointer for Py_AddPendingCall, alive as long as the guard
        self.pending = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p)(self._safe_point)

    def __call__(self, phase: str, info: dict) -> None:
        if phase != "start":
            return
        if not self.flag(self.symbolic):
            if self.frozen and threading.current_thread() is threading.main_thread():
                # the main thread is outside its trace: this pass (a user's
                # gc.collect() included) may see the deferred garbage again
                gc.unfreeze()
                self.frozen = False
        else:
            gc.freeze()
            self.frozen = True
            self.deferred += 1
            self.owed.set()
            if self.watcher is None:
                self.watcher = threading.Thread(target=self._watch, name="thinfilm_mi-gc-guard", daemon=True)
                self.watcher.start()

    def forget_watcher(self) -> None:
        self.watcher = None

    def _watch(self) -> None:
        """While a collection is owed, ask the main thread for it every :data:`POLL` s.
        (Only the main thread can tell whether it is inside a symbolic scope: the
        flag is per thread.)"""
        while True:
            self.owed.wait()
            ctypes.pythonapi.Py_AddPendingCall(self.pending, None)
            time.sleep(self.POLL)

    def _safe_point(self, _arg) -> int:
        """Run by the main thread between two bytecodes: unfreeze and collect what
        the deferred passes left, unless this thread is inside a trace (then the
        watcher asks again)."""
        if self.owed.is_set() and not self.flag(self.symbolic):
            self.owed.clear()
            if self.frozen:
                gc.unfreeze()
                self.frozen = False
            self.collections += 1
            gc.collect()
        return 0


_guard: _Guard | None = None


def install() -> None:
    """Add the hook to :data:`gc.callbacks`, once per process (idempotent)."""
    global _guard
    import drjit

    with _lock:
        if _guard is None:
            _guard = _Guard(drjit)
            gc.callbacks.append(_guard)
            # a forked child has no watcher thread: it starts its own when it needs one
            os.register_at_fork(after_in_child=_guard.forget_watcher)


def installed() -> bool:
    """Whether :func:`install` has run in this process."""
    return _guard is not None and _guard in gc.callbacks


def deferred_collections() -> tuple[int, int]:
    """How many collection passes the hook has deferred in this process, and how
    many full collections it has run for them."""
    return (0, 0) if _guard is None else (_guard.deferred, _guard.collections)
