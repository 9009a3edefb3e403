"""Helpers that several test modules share (fixtures live in the ``conftest.py`` files)."""
from pathlib import Path

#: The repository's root folder.
ROOT = Path(__file__).resolve().parents[2]

#: An LLVM 15 library where Ubuntu puts one: Dr.Jit would abort with it, the package refuses
#: it with a clear error (tests/test_llvm.py, tests/cross/test_bad_input.py).
LLVM15 = "/usr/lib/x86_64-linux-gnu/libLLVM-15.so"
