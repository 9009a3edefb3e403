"""The LLVM check (thinfilm_mi/llvm.py): LLVM 15 is refused with a clear error, not an
abort."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.support import LLVM15
from thinfilm_mi.llvm import LLVMVersionError, check_version


# --------------------------------------------------------------------------
# The LLVM guard
# --------------------------------------------------------------------------
def test_check_version_refuses_llvm15():
    with pytest.raises(LLVMVersionError) as e:
        check_version((15, 0, 6))
    msg = str(e.value)
    assert "libllvm19" in msg and "DRJIT_LIBLLVM_PATH" in msg and "15.0.6" in msg
    with pytest.raises(LLVMVersionError):
        check_version((16, 0, 0))
    with pytest.raises(LLVMVersionError):
        check_version((-1, -1, -1))
    check_version((19, 1, 7))  # the tested version passes silently


@pytest.mark.skipif(not os.path.exists(LLVM15), reason="no libLLVM-15 on this machine")
def test_llvm15_gives_a_clear_error_not_an_abort():
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=LLVM15)
    code = "import thinfilm_mi as tf; tf.Stack([(1.5, 100)]).rt(500.)"
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode > 0, (proc.returncode, proc.stderr[-2000:])  # no signal / abort
    assert "LLVMVersionError" in proc.stderr
    assert "libllvm19" in proc.stderr and "DRJIT_LIBLLVM_PATH" in proc.stderr
    # the last line is the Python exception, not LLVM's own abort message
    assert proc.stderr.strip().splitlines()[-1].startswith("thinfilm_mi.llvm.LLVMVersionError")
