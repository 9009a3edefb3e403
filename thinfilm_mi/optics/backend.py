"""Runs the optics core in float64 on numpy data (Dr.Jit's LLVM backend).

The numpy API (:class:`thinfilm_mi.Stack`) and the tables build on this. Inputs
are flat numpy arrays; the core is traced once per call into one LLVM kernel
that evaluates every output together.
"""
from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.llvm import Float64

from thinfilm_mi.llvm import require_llvm
from thinfilm_mi.optics.core import Cx, stack_amplitudes, transmittance_factor_p, transmittance_factor_s

__all__ = ["aligned_array", "float64_array", "repeated", "to_drjit", "to_numpy", "to_inputs", "reference_rt"]

#: Alignment (bytes) of the buffers handed to Dr.Jit, see :func:`float64_array`.
_ALIGN = 128


def aligned_array(a, dtype, array_type):
    """A numpy array (flattened, converted to ``dtype``) as a Dr.Jit ``array_type``
    whose memory is 128-byte aligned.

    Dr.Jit's LLVM backend takes a numpy buffer's memory as it is and compiles
    the kernel for the alignment it finds (``align 128`` or ``align 1`` vector
    loads): equal inputs at other addresses give another kernel, hence a new
    compilation (~0.1 s) on most calls. An aligned copy keeps one kernel.
    """
    a = np.asarray(a, dtype).ravel()
    size = np.dtype(dtype).itemsize
    buf = np.empty(a.size + _ALIGN // size, dtype)
    start = (-buf.ctypes.data % _ALIGN) // size
    out = buf[start:start + a.size]
    out[...] = a
    return array_type(out)


def float64_array(a) -> Float64:
    """A numpy array as an aligned Float64 (:func:`aligned_array`)."""
    return aligned_array(a, np.float64, Float64)


def repeated(values, reps: int, complex_: bool = False):
    """Each value of a 1-D numpy array repeated ``reps`` times, in aligned buffers
    (:func:`float64_array`): a Float64, or with ``complex_`` a :class:`Cx` of
    Float64 (one index per wavelength spread over a row of angles)."""
    values = np.repeat(np.asarray(values, np.complex128 if complex_ else np.float64), reps)
    if complex_:
        return Cx(float64_array(values.real), float64_array(values.imag))
    return float64_array(values)


def to_drjit(a: np.ndarray):
    """A real numpy array as a Float64, a complex one as :class:`Cx` of Float64;
    arrays whose values are all equal become Python scalars (kernel literals)."""
    a = np.asarray(a)
    if np.iscomplexobj(a):
        return Cx(to_drjit(a.real), to_drjit(a.imag))
    a = np.ascontiguousarray(a, dtype=np.float64).ravel()
    if a.size and np.all(a == a[0]):
        return float(a[0])
    return float64_array(a)


def to_numpy(v) -> np.ndarray:
    if isinstance(v, Cx):
        return to_numpy(v.re) + 1j * to_numpy(v.im)
    return np.array(v, dtype=np.float64)


def to_inputs(n0, cos0, films, thicknesses, n_exit, wavelength, size=None):
    """The optics core's arguments as Dr.Jit float64 values, from numpy arrays of
    one flat length (or broadcastable scalars): ``(n0, cos0, films, n_exit,
    wavelength, size)``. Checks that the LLVM backend is usable first."""
    require_llvm()
    size = np.size(wavelength) if size is None else size
    cos0_d = float64_array(np.broadcast_to(np.asarray(cos0, np.float64), (size,)))
    wl = to_drjit(np.broadcast_to(wavelength, (size,)))
    n0_d = to_drjit(np.broadcast_to(n0, (size,)))
    film_d = [(to_drjit(np.broadcast_to(n, (size,))), float(d)) for n, d in zip(films, thicknesses)]
    nex = to_drjit(np.broadcast_to(n_exit, (size,)).astype(np.complex128))
    return n0_d, cos0_d, film_d, nex, wl, size


def reference_rt(n0, cos0, films, thicknesses, n_exit, wavelength, size=None):
    """Float64 amplitudes and powers; every argument a numpy array of the same
    flat length (or broadcastable scalars). Returns a dict of Dr.Jit arrays."""
    n0_d, cos0_d, film_d, nex, wl, size = to_inputs(n0, cos0, films, thicknesses, n_exit,
                                                    wavelength, size)
    a = stack_amplitudes(n0_d, cos0_d, film_d, nex, wl)
    q0 = dr.select(a.grazing, 1.0, a.q0)
    fs = transmittance_factor_s(a.q_exit, q0)
    fp = transmittance_factor_p(a.n_exit, a.q_exit, q0)
    out = {
        "rs": a.rs, "rp": a.rp, "ts": a.ts, "tp": a.tp,
        "Rs": a.rs.abs2(), "Rp": a.rp.abs2(),
        "Ts": dr.select(a.grazing, 0.0, a.ts.abs2() * fs),
        "Tp": dr.select(a.grazing, 0.0, a.tp.abs2() * fp),
    }
    # Broadcast literals to full arrays so every output has `size` entries.
    for k, v in list(out.items()):
        if isinstance(v, Cx):
            out[k] = Cx(v.re + dr.zeros(Float64, size), v.im + dr.zeros(Float64, size))
        else:
            out[k] = v + dr.zeros(Float64, size)
    leaves = [x for v in out.values() for x in ((v.re, v.im) if isinstance(v, Cx) else (v,))]
    dr.eval(*leaves)
    return out
