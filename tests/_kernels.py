"""Test helpers for the files that evaluate thin-film stacks in LLVM kernels."""
from __future__ import annotations

import numpy as np

import drjit as dr
import mitsuba as mi


def interaction(wls):
    """A SurfaceInteraction3f whose four wavelength channels are the arrays ``wls``."""
    si = dr.zeros(mi.SurfaceInteraction3f, len(wls[0]))
    si.wavelengths = mi.Spectrum(*[mi.Float(np.asarray(w, np.float32)) for w in wls])
    return si


def compiled(history):
    """JIT kernels in a ``dr.kernel_history()`` that were compiled (not cache hits)."""
    return [k for k in history if k["type"] == dr.KernelType.JIT
            and not k.get("cache_hit", False) and not k.get("cache_disk", False)]
