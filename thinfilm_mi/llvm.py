"""Guard against LLVM versions that make Dr.Jit abort the process.

Dr.Jit 1.5 emits the ``llvm.maximum``/``llvm.minimum`` intrinsics. LLVM 15 and 16
cannot lower them on x86-64 and abort the *whole process* (``LLVM ERROR: Cannot
select ... fmaximum``) the first time such a kernel is compiled, including for
Mitsuba's own built-in plugins. LLVM 14 and older are refused by Dr.Jit itself
(the LLVM backend is then missing). LLVM 19 (Debian's ``libllvm19``) is the
version this project is tested with; 17 and 18 are accepted with a warning.

:func:`require_llvm` is called before thinfilm-mi runs any LLVM kernel: by the
numpy API of :mod:`thinfilm_mi.optics.core`, when plugins are registered for an
``llvm_*`` variant, and by the command-line tools. It raises
:class:`LLVMVersionError`, which says how to fix the machine, instead of letting
the process abort.
"""
from __future__ import annotations

import os
import warnings

__all__ = ["TESTED", "FIX", "LLVMVersionError", "llvm_version", "check_version", "require_llvm"]

TESTED = 19

FIX = (
    "Install LLVM 19 and Dr.Jit picks it up by itself: on Debian/Ubuntu run "
    "'apt-get install libllvm19' (as root), or point Dr.Jit at a libLLVM of version 17 "
    "or newer with DRJIT_LIBLLVM_PATH=/path/to/libLLVM.so.19 before starting Python. "
    "'make demo' / 'make test' (scripts/ensure_llvm.py) do this for you."
)


class LLVMVersionError(RuntimeError):
    """The LLVM library that Dr.Jit loaded cannot run thinfilm-mi's kernels."""


_checked: tuple | None = None


def llvm_version() -> tuple:
    """The (major, minor, patch) of the LLVM that Dr.Jit loaded; (-1, -1, -1) if none."""
    import drjit as dr

    return tuple(dr.detail.llvm_version())


def check_version(version: tuple) -> None:
    """Raise :class:`LLVMVersionError` if Dr.Jit with LLVM ``version`` would abort or
    has no LLVM backend; warn if the version is newer than the known-bad ones but
    untested."""
    major = int(version[0])
    where = os.environ.get("DRJIT_LIBLLVM_PATH")
    loaded = f" (DRJIT_LIBLLVM_PATH={where})" if where else ""
    if major < 0:
        raise LLVMVersionError(
            "Dr.Jit found no usable LLVM library (it needs LLVM >= 15 to start and "
            f">= 17 to run thinfilm-mi){loaded}. {FIX}"
        )
    if major < 17:
        raise LLVMVersionError(
            f"Dr.Jit loaded LLVM {'.'.join(map(str, version))}{loaded}; Dr.Jit 1.5 aborts the "
            "whole Python process when it compiles kernels with LLVM 15 or 16 "
            "('LLVM ERROR: Cannot select ... fmaximum'). " + FIX
        )
    if major < TESTED:
        warnings.warn(
            f"Dr.Jit loaded LLVM {major}; thinfilm-mi is tested with LLVM {TESTED} "
            "(LLVM 15 and 16 are known to abort).",
            RuntimeWarning,
            stacklevel=3,
        )


def require_llvm() -> None:
    """Check once per process that Dr.Jit's LLVM backend can run our kernels."""
    global _checked
    if _checked is None:
        version = llvm_version()
        check_version(version)  # raises before anything is cached
        _checked = version
