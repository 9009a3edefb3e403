"""Test helpers for the files that evaluate thin-film stacks in LLVM kernels."""
from __future__ import annotations

import contextlib
import gc

import drjit as dr
import mitsuba as mi
import numpy as np
from drjit.llvm import Float64, UInt32

from thinfilm_mi.optics import core as optics


def interaction(wls):
    """A SurfaceInteraction3f whose four wavelength channels are the arrays ``wls``."""
    si = dr.zeros(mi.SurfaceInteraction3f, len(wls[0]))
    si.wavelengths = mi.Spectrum(*[mi.Float(np.asarray(w, np.float32)) for w in wls])
    return si


def compiled(history):
    """JIT kernels in a ``dr.kernel_history()`` that were compiled (not cache hits)."""
    return [k for k in history if k["type"] == dr.KernelType.JIT
            and not k.get("cache_hit", False) and not k.get("cache_disk", False)]


@contextlib.contextmanager
def same_instances():
    """No BSDF instance freed by the garbage collector while the block runs: garbage is
    collected first, then automatic collection is off until the block ends.

    A render traces every live instance of a Python BSDF, those of a scene an earlier
    test dropped included, so a dropped scene freed between two renders changes the
    render kernel as an edit must not. A ``gc.collect()`` before the renders alone was
    not enough (two such failures in one full run of the suite, on one worker): an
    automatic pass during a render is deferred by ``thinfilm_mi.render.gc_guard``, whose
    owed collection at the render's end then frees what became garbage since."""
    enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def assert_edits_render_from_cache(scene, params, edits: dict) -> None:
    """Apply ``edits`` (key -> value) to ``params`` of ``scene``: the render after them runs
    every JIT kernel from the cache (the edited values are opaque inputs, nothing
    recompiles) and differs from the render before them (the edits took effect). The
    renders see the same BSDF instances (:func:`same_instances`)."""
    with same_instances():
        first = np.array(mi.render(scene, seed=1))
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        try:
            dr.kernel_history()  # clear
            for key, value in edits.items():
                params[key] = value
            params.update()
            second = np.array(mi.render(scene, seed=1))
            history = dr.kernel_history()
        finally:
            dr.set_flag(dr.JitFlag.KernelHistory, False)
    jit = [k for k in history if k["type"] == dr.KernelType.JIT]
    assert jit, "no kernel ran"
    assert all(k.get("cache_hit") for k in jit), "a parameter edit recompiled the render kernel"
    assert np.abs(first - second).mean() > 1e-3  # and the edits took effect


def loop_rt(n0, cos, n, k, d, n_exit, wl, Arr=Float64, rt=optics.stack_rt_loop, **hints):
    """``rt`` (``optics.stack_rt_loop``, or ``unpolarized.unpolarized_rt_loop``) with the
    films gathered from buffers of type ``Arr``, as the render kernels do (padded: a
    gather needs a non-empty source); ``k = None``: real films (a literal 0
    imaginary part)."""
    eta, thk = (Arr(np.r_[a, 0.0]) for a in (n, d))
    kk = None if k is None else Arr(np.r_[k, 0.0])

    def film(j):
        im = 0.0 if kk is None else dr.gather(Arr, kk, j)
        return optics.Cx(dr.gather(Arr, eta, j), im), dr.gather(Arr, thk, j)

    return rt(n0, Arr(cos), UInt32(len(n)), film, n_exit, Arr(wl), **hints)
