#!/usr/bin/env python3
"""Set-up step: make sure Dr.Jit loads an LLVM >= 19 (see thinfilm_mi/llvm.py).

Dr.Jit 1.5 aborts the process when it compiles with LLVM 15 or 16, which is what
Debian 12 ships by default. Debian's ``libllvm19`` works and Dr.Jit finds it
without configuration. This script asks a fresh interpreter which LLVM Dr.Jit
would load and, if it is older than 19, installs ``libllvm19`` with apt when run
as root on Debian/Ubuntu; otherwise it prints what to do and exits non-zero.
"""
import os
import shutil
import subprocess
import sys

PROBE = "import drjit; print(drjit.detail.llvm_version()[0])"


def loaded_major() -> int:
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True)
    try:
        return int(out.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        return -1


def main() -> int:
    major = loaded_major()
    if major >= 19:
        print(f"ensure_llvm: Dr.Jit loads LLVM {major}: ok")
        return 0
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        print(f"ensure_llvm: DRJIT_LIBLLVM_PATH is set but Dr.Jit loads LLVM {major}; "
              "point it at libLLVM 19 (e.g. /usr/lib/x86_64-linux-gnu/libLLVM.so.19.1)",
              file=sys.stderr)
        return 1
    apt = shutil.which("apt-get")
    if apt and os.geteuid() == 0:
        print(f"ensure_llvm: Dr.Jit loads LLVM {major}; installing libllvm19 with apt-get")
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        subprocess.run([apt, "update", "-qq"], check=False, env=env)
        subprocess.run([apt, "install", "-y", "-qq", "libllvm19"], check=True, env=env)
        major = loaded_major()
        if major >= 19:
            print(f"ensure_llvm: Dr.Jit now loads LLVM {major}: ok")
            return 0
    print(
        f"ensure_llvm: Dr.Jit loads LLVM {major if major >= 0 else 'none'}, but needs LLVM >= 17 "
        "(19 is tested; 15 and 16 abort the process). Install it as root with "
        "'apt-get install libllvm19' (Debian/Ubuntu), or set DRJIT_LIBLLVM_PATH to a "
        "libLLVM.so of version 19.",
        file=sys.stderr,
    )
    return 1


if __name__ == "__main__":
    sys.exit(main())
