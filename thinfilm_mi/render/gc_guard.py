"""No cyclic garbage collection, on any thread, while some thread traces our plugins.

The defect (Mitsuba 3.9.1, Dr.Jit 1.5; upstream, not ours, see
``docs/upstream_gc_during_symbolic_call.md``):

* A symbolic virtual call (``ad_call_symbolic``, how an LLVM or CUDA variant's
  ``PathIntegrator`` calls ``BSDF::eval_pdf_sample``) traces *every* registered
  instance of the BSDF domain, those of scenes already dropped included. It
  holds no reference to an instance while it traces it.
* When a pass of the cyclic garbage collector frees a dropped scene (a scene kept
  only by a reference cycle: a kept exception's traceback, a notebook's ``Out[]``,
  a self-referencing dict) while some thread traces it, that thread's next call on
  the freed BSDF (or on a ``blendbsdf`` or ``twosided`` around it) is a
  use-after-free: a segfault, or Dr.Jit's abort "jit_registry_remove(): pointer is
  not registered". The pass may start on the tracing thread, inside a Python
  BSDF's traced method, or on any other thread that runs Python meanwhile: Mitsuba
  releases the GIL while it renders.

The guard: a process-wide set of the threads that are tracing, and a
:data:`gc.callbacks` hook that makes every pass a no-op (:func:`gc.freeze` moves
every tracked object to the permanent generation, so the pass examines nothing and
frees nothing) while that set is not empty, whichever thread starts the pass.

* A thread joins the set when a traced method of one of our plugins runs inside a
  symbolic scope (``dr.JitFlag.SymbolicScope``): every live instance of a Python
  BSDF is traced in every symbolic call of its domain, in whatever thread makes
  it, so our methods see every trace begin while an instance of ours is alive
  (:func:`watch_traces` wraps them when the plugins are registered). A pass that
  starts inside a symbolic scope adds its own thread too (a trace of another
  Python plugin).
* It leaves the set at its first Python event outside any symbolic scope: a
  profile function (:func:`sys.setprofile`, which is per thread) is set on the
  thread when one of our traced methods returns, and removed while the next one
  runs; the first event it sees outside a scope is the return of the render.
* :func:`rendering` puts a thread in the set for a whole block, after waiting for a
  pass that another thread began before (it may still be freeing: a pass can hand
  the GIL to other threads while it runs finalizers). Importing the package wraps
  ``mi.render`` in it, so that a render on any thread is covered from its start,
  before any method of ours runs (symbolic calls of other domains, an emitter's
  say, may come first). Our own entry points (the CLI, sweeps, the renders of
  design) render through ``mi.render`` (:func:`thinfilm_mi.batch.scene.render_scene`),
  so they are covered the same way.
* The thread that leaves the set last, once a pass was deferred, unfreezes the heap
  and runs one full :func:`gc.collect`, so the dropped scenes are freed once no
  thread traces them.

The second defect (also upstream): a symbolic call traces every instance registered in
its domain, and Mitsuba registers an instance in its base class's constructor, before the
instance is built (a ``blendbsdf`` whose nested BSDFs are not yet set, a Python plugin
whose ``__init__`` has not finished) or while it is being destroyed. A scene loaded on
one thread while another renders can so crash the render, with no Python plugin and no
collection involved (``tests/support/load_race_child.py``). So loads and renders take
turns (:func:`loading`, :func:`rendering`): any number of loads at once, or any number of
renders, never a load beside a render. A render waits for the loads in progress and lets
a waiting load go first; a load waits only for the renders in progress (a load that a
plugin's constructor starts inside another load must not wait for a render that waits
for the outer load). Importing the package wraps Mitsuba's ``load_dict``, ``load_file``
and ``load_string`` in :func:`loading`, as ``mi.render`` in :func:`rendering`.

The third hazard (upstream too): Mitsuba loads a scene's objects as tasks of the thread pool
that runs Dr.Jit's kernels, and a thread that waits for a kernel runs queued tasks meanwhile.
A constructor of ours that evaluates a kernel at load (a texture's range, a table) so runs
another object's constructor nested on its own thread, inside that wait; one such nesting
crashed a worker of the test suite (SIGSEGV under ``texture_range``, constructors nested two
deep on a loader thread). A scene that names one of our plugins (:func:`names_ours`) is
therefore loaded with ``parallel=False``: its constructors run one after the other on the
calling thread (:func:`parsed_names_ours` decides for a scene parsed by
:mod:`mitsuba.parser`, as :func:`thinfilm_mi.batch.scene.load_scene` does), and a new
Dr.Jit scope starts after it (:func:`after_serial_load`), as after a parallel load. Our
constructors hold the GIL, so they gain little from the loader's threads; scenes without
our plugins load as Mitsuba decides.

Limits: a render started another way (the integrator's own ``render``, or a
``render`` bound before this package was imported) is covered from the first
traced call of a method of ours, not before it; a thread that has a profile
function of its own (``cProfile``, a debugger's) leaves the set at its next pass
outside a scope instead; garbage made during a render waits for the last tracing
thread's render to end, and threads that render back to back without a moment in
which none traces defer collection until there is one; objects the user froze with
:func:`gc.freeze` are unfrozen by the owed collection. A scene freed by reference
counting (``del scene``) on one thread while another thread renders is outside a
garbage collector's reach: only the upstream fix covers it. Scalar variants make no
symbolic calls and never defer. A load made through ``mitsuba.parser`` directly, or
through a ``load_*`` bound before this package was imported, does not take its turn, and
runs our constructors on Mitsuba's loader threads unless told otherwise; a scene without
our plugins that another thread loads in parallel meanwhile can still have one of its
constructors run inside one of ours. What
the guard costs is measured in ``benchmarks/gc_guard_bench.py``.
"""
from __future__ import annotations

import contextlib
import functools
import gc
import os
import sys
import threading

__all__ = ["install", "installed", "deferred_collections", "loading", "rendering", "watch_traces",
           "names_ours", "parsed_names_ours", "after_serial_load", "TRACED_METHODS", "LOADS",
           "OURS"]

#: Mitsuba's functions that load a scene or an object (each takes its turn: :func:`loading`)
LOADS = ("load_dict", "load_file", "load_string")

#: what the type names of this package's plugins start with
OURS = "thinfilm_"

#: the methods Mitsuba calls on a Python BSDF or texture inside a symbolic call
TRACED_METHODS = ("sample", "eval", "pdf", "eval_pdf", "eval_pdf_sample", "eval_diffuse_reflectance",
                  "eval_null_transmission", "eval_attribute", "eval_attribute_1", "eval_attribute_3",
                  "eval_1", "eval_3", "eval_1_grad", "eval_3_grad", "sample_spectrum", "pdf_spectrum",
                  "mean")

_lock = threading.Lock()
#: seconds a render waits at most for a pass another thread began (a finalizer of that
#: pass waiting for a lock this thread holds must not hang both)
PASS_WAIT = 5.0


class _Guard:
    """The hook and its state: which threads trace, whether the heap is frozen, how
    many passes were deferred and how many owed collections were run."""

    def __init__(self, drjit) -> None:
        self.flag = drjit.flag
        self.symbolic = drjit.JitFlag.SymbolicScope
        #: threads seen inside a trace and not yet seen outside one
        self.tracing: set[int] = set()
        #: threads inside :func:`rendering`, with its nesting depth
        self.scoped: dict[int, int] = {}
        self.frozen = False
        self.deferred = 0
        self.collections = 0
        #: held while a pass runs, so that a render can wait for a pass that began
        #: before it (a plain lock: the hook runs no Python that could start a pass)
        self.pass_lock = threading.Lock()
        self.pass_held = False
        self.passing: int | None = None

    def busy(self) -> bool:
        return bool(self.tracing or self.scoped)

    # -- the gc.callbacks hook -------------------------------------------------
    def __call__(self, phase: str, info: dict) -> None:
        if phase != "start":
            self.passing = None
            if self.pass_held:
                self.pass_held = False
                self.pass_lock.release()
            return
        self.passing = me = threading.get_ident()
        self.pass_held = self.pass_lock.acquire(blocking=False)
        if self.flag(self.symbolic):
            self.join(me)
        elif self.tracing and me in self.tracing:
            self.tracing.discard(me)   # outside its trace (its profile function was taken)
        if self.tracing or self.scoped:
            self._forget_dead_threads()
        if self.tracing or self.scoped:
            gc.freeze()
            self.frozen = True
            self.deferred += 1
        elif self.frozen:
            # this pass may see the deferred garbage again; a full one frees it
            gc.unfreeze()
            self.frozen = False

    # -- joining and leaving ---------------------------------------------------
    def join(self, me: int) -> None:
        """The calling thread traces: it stays in the set until :meth:`watch` sees it
        outside every symbolic scope."""
        self.tracing.add(me)
        if sys.getprofile() is None:
            sys.setprofile(self.watch)

    def watch(self, frame, event, arg) -> None:
        """A profile function: the first Python event outside a symbolic scope takes
        the thread out of the set."""
        if self.flag(self.symbolic):
            return
        sys.setprofile(None)
        self.tracing.discard(threading.get_ident())
        self.collect_if_owed()

    def collect_if_owed(self) -> None:
        """Once no thread traces, free what the deferred passes kept."""
        if self.frozen and not self.busy():
            gc.unfreeze()
            self.frozen = False
            self.collections += 1
            gc.collect()

    def _forget_dead_threads(self) -> None:
        alive = sys._current_frames().keys()
        self.tracing.intersection_update(alive)   # in place: other threads hold this set
        for ident in list(self.scoped):   # (other threads may run between two lines)
            if ident not in alive:
                self.scoped.pop(ident, None)

    def forget_threads(self) -> None:
        """In a forked child, only the forking thread lives on (and no pass runs)."""
        me = threading.get_ident()
        self.tracing.intersection_update({me})
        self.scoped = {i: n for i, n in self.scoped.items() if i == me}
        self.pass_lock, self.pass_held, self.passing = threading.Lock(), False, None


class _Turns:
    """Loads and renders take turns (see the module docstring): ``kind`` is what holds
    the turn now (``"load"``, ``"render"`` or ``None``), ``count`` how many threads
    hold it; a thread that holds a turn enters again at once, whatever it asks for."""

    def __init__(self) -> None:
        self.cond = threading.Condition(threading.Lock())
        self.kind: str | None = None
        self.count = 0
        self.loads_waiting = 0
        #: the threads that hold a turn, with their nesting depth
        self.depth: dict[int, int] = {}

    def _may_enter(self, kind: str) -> bool:
        if kind == "load":
            return self.kind in (None, "load")
        return self.kind in (None, "render") and not self.loads_waiting

    @contextlib.contextmanager
    def turn(self, kind: str):
        me = threading.get_ident()
        with self.cond:
            if me in self.depth:
                self.depth[me] += 1
            else:
                self.loads_waiting += kind == "load"
                try:
                    self.cond.wait_for(lambda: self._may_enter(kind))
                finally:
                    self.loads_waiting -= kind == "load"
                self.kind, self.count, self.depth[me] = kind, self.count + 1, 1
        try:
            yield
        finally:
            with self.cond:
                self.depth[me] -= 1
                if not self.depth[me]:
                    del self.depth[me]
                    self.count -= 1
                    if not self.count:
                        self.kind = None
                    self.cond.notify_all()


_turns = _Turns()
_guard: _Guard | None = None


def install() -> None:
    """Add the hook to :data:`gc.callbacks` and make ``mi.render`` render inside
    :func:`rendering`, once per process (idempotent)."""
    global _guard
    import drjit

    with _lock:
        if _guard is None:
            _guard = _Guard(drjit)
            gc.callbacks.append(_guard)
            os.register_at_fork(after_in_child=_after_fork)
        _cover("render", rendering)
        for name in LOADS:
            _cover(name, loading, _load)


def _after_fork() -> None:
    """In a forked child only the forking thread lives on: no other thread holds a turn
    or traces."""
    global _turns
    _turns = _Turns()
    if _guard is not None:
        _guard.forget_threads()


def _cover(name: str, block, call=None) -> None:
    """Replace ``mitsuba.<name>`` (under every name Mitsuba's modules give it) by a wrapper
    that runs it inside ``block()`` (:func:`rendering` or :func:`loading`), so that a
    user's call on any thread is covered from its start; ``call(original, args, kwargs)``
    makes the call where given. Idempotent."""
    import mitsuba

    original = getattr(mitsuba, name, None)
    if original is None or getattr(original, "__wrapped_by_gc_guard__", False):
        return

    @functools.wraps(original)
    def covered(*args, **kwargs):
        with block():
            return original(*args, **kwargs) if call is None else call(original, args, kwargs)

    covered.__wrapped_by_gc_guard__ = True
    for module_name, module in list(sys.modules.items()):
        if ((module_name == "mitsuba" or module_name.startswith("mitsuba."))
                and getattr(module, name, None) is original):
            setattr(module, name, covered)


def _load(original, args: tuple, kwargs: dict):
    """A Mitsuba load, with ``parallel=False`` where its scene names one of our plugins
    (see the module docstring: no constructor nested in another's kernel wait), then
    :func:`after_serial_load`. Mitsuba's loads take ``(scene, parallel, optimize)``
    positionally."""
    if not args or not names_ours(args[0], kwargs):
        return original(*args, **kwargs)
    given = dict(zip(("parallel", "optimize"), args[1:3]))
    loaded = original(*args[:1], **{**kwargs, **given, "parallel": False})
    after_serial_load()
    return loaded


def after_serial_load() -> None:
    """Start a new Dr.Jit scope after a scene loaded on one thread, as Mitsuba's parallel
    loader does after its last object: without it the first render traced in the load's
    scope, where Dr.Jit merged its expressions with the constructors', and compiled a
    kernel that no later render reused (every later render compiled another)."""
    import drjit
    import mitsuba

    backend = drjit.backend_v(mitsuba.Float)
    if backend != drjit.JitBackend.Invalid:
        drjit.detail.new_scope(backend)


def names_ours(scene, kwargs: dict | None = None) -> bool:
    """Whether loading ``scene`` may build one of this package's plugins: a dict (at any
    depth) whose ``type`` starts with :data:`OURS`, or an XML string or file (a path;
    Mitsuba's file resolver finds relative ones) whose text or substituted parameters
    (``kwargs``, the ``$name`` values) name one, or that includes other files (not
    followed: assumed to). Anything else (an object already built, a file that cannot
    be read, for Mitsuba to refuse) is not."""
    values = [str(v) for v in (kwargs or {}).values()]
    if isinstance(scene, dict):
        stack = [scene]
        while stack:
            d = stack.pop()
            if str(d.get("type", "")).startswith(OURS):
                return True
            stack.extend(v for v in d.values() if isinstance(v, dict))
        return False
    if not isinstance(scene, (str, os.PathLike)):
        return False
    text = str(scene)
    if "<" not in text:   # a file name
        try:
            import mitsuba
            path = os.fspath(scene)
            if not os.path.exists(path):
                path = str(mitsuba.file_resolver().resolve(path))
            with open(path, encoding="utf-8", errors="replace") as f:
                text = f.read()
        except (OSError, RuntimeError, TypeError, ValueError):
            return False
    return any(OURS in t for t in [text, *values]) or "<include" in text


def parsed_names_ours(state) -> bool:
    """Whether a parsed scene (a ``mitsuba.parser`` state, its includes and parameters
    resolved) builds one of this package's plugins: to be instantiated with
    ``ParserConfig.parallel`` false (see the module docstring)."""
    return any(node.props.plugin_name().startswith(OURS) for node in state.nodes)


def installed() -> bool:
    """Whether :func:`install` has run in this process."""
    return _guard is not None and _guard in gc.callbacks


def deferred_collections() -> tuple[int, int]:
    """How many collection passes the hook has deferred in this process, and how
    many full collections it has run for them."""
    return (0, 0) if _guard is None else (_guard.deferred, _guard.collections)


@contextlib.contextmanager
def rendering():
    """No collection frees anything while the block runs on this thread (a render:
    its symbolic calls trace every live BSDF, dropped scenes' included), and no load runs
    on another thread (the block waits for the loads in progress). A pass that another
    thread began before is waited for: it may still be freeing."""
    install()
    with _turns.turn("render"):
        guard, me = _guard, threading.get_ident()
        guard.scoped[me] = guard.scoped.get(me, 0) + 1
        if guard.passing not in (None, me) and guard.pass_lock.acquire(timeout=PASS_WAIT):
            guard.pass_lock.release()
        try:
            yield
        finally:
            depth = guard.scoped.pop(me, 1) - 1
            if depth:
                guard.scoped[me] = depth
            guard.collect_if_owed()


@contextlib.contextmanager
def loading():
    """The block loads a scene or an object: it waits for the renders in progress on
    other threads, and no render starts on another thread while it runs (see the module
    docstring: a render traces what a load registers before it is built)."""
    install()
    with _turns.turn("load"):
        yield


def _traced(method):
    """``method``, putting its thread in the guard's set while it runs in a trace and
    watching for the thread's first event outside every scope once it returns."""
    @functools.wraps(method)
    def traced(*args, **kwargs):
        guard = _guard
        if guard is None or not guard.flag(guard.symbolic):
            return method(*args, **kwargs)
        guard.tracing.add(threading.get_ident())
        mine = sys.getprofile() in (None, guard.watch)
        if mine:
            sys.setprofile(None)   # no profile events while the method traces
        try:
            return method(*args, **kwargs)
        finally:
            if mine:
                sys.setprofile(guard.watch)
    traced.__wrapped_by_gc_guard__ = True
    return traced


def watch_traces(cls: type) -> type:
    """Wrap the :data:`TRACED_METHODS` that ``cls`` defines in Python (its own or a
    Python base's) so that a trace of them puts the thread in the guard's set.
    Idempotent; returns ``cls``."""
    for name in TRACED_METHODS:
        for klass in cls.__mro__:
            method = klass.__dict__.get(name)
            if method is not None:
                break
        if callable(method) and hasattr(method, "__code__") and not getattr(method, "__wrapped_by_gc_guard__", False):
            setattr(cls, name, _traced(method))
    return cls
