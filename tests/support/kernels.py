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
    render kernel as an edit must not. A ``gc.collect()`` before the renders alone is not
    enough: an automatic pass during a render is deferred by
    ``thinfilm_mi.render.gc_guard``, whose owed collection at the render's end then frees
    what became garbage since (a dropped scene made after the collection, under
    ``gc.set_threshold(10)``, changed the second render's kernel)."""
    enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


def render_kernels(scene):
    """``(image, hashes)``: a render of ``scene`` at seed 1 and the hashes of the JIT kernels
    it ran. Compared by hash, not by Dr.Jit's ``cache_hit``: a kernel that another process
    left in the kernel cache on disk counts as a hit, so a changed kernel went unnoticed
    wherever an earlier run had compiled it."""
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()  # clear
        image = np.array(mi.render(scene, seed=1))
        hashes = [k["hash"] for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert hashes, "no kernel ran"
    return image, hashes


def assert_edits_render_from_cache(scene, params, edits: dict) -> None:
    """Apply ``edits`` (key -> value) to ``params`` of ``scene``: the render after them runs
    no kernel the render before them did not (the edited values are opaque inputs, nothing
    recompiles) and differs from it (the edits took effect). The renders see the same BSDF
    instances (:func:`same_instances`)."""
    with same_instances():
        first, before = render_kernels(scene)
        for key, value in edits.items():
            params[key] = value
        params.update()
        second, after = render_kernels(scene)
    # (the first render may also evaluate what the load left unevaluated, in kernels of its own)
    assert set(after) <= set(before), "a parameter edit changed the render kernel"
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
