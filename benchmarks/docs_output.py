"""``--write-docs`` for every benchmark: its tables as an include file of the documentation.

A benchmark whose figures the documentation quotes runs its ``main`` under
:func:`write_docs_option`::

    if __name__ == "__main__":
        with write_docs_option("optics_throughput"):
            main()

Without ``--write-docs`` on the command line nothing changes. With it, the option is
taken out of ``sys.argv`` (the benchmark's own parser never sees it), what the benchmark
prints to stdout is passed through and kept, and at the end it is written to
``docs/_generated/<name>.md`` (``docs/benchmarks.md`` includes it) under a header line
that says where and when it was measured (:func:`provenance`: the machine's CPU model,
cores and load average when the run started, the date, the commit, the tree's state,
Mitsuba and Dr.Jit). Printed Markdown (tables, paragraphs) is kept as it is; a run that
prints no Markdown table is kept in a ``text`` block. So a figure on the benchmark page
is always one a script wrote, never one copied by hand. ``benchmarks/write_docs.py``
runs them all with the settings the page uses.
"""
from __future__ import annotations

import contextlib
import io
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["GENERATED", "provenance", "write", "write_docs_option"]

REPO = Path(__file__).resolve().parent.parent
#: the folder of the include files
GENERATED = REPO / "docs" / "_generated"


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ""


def provenance() -> str:
    """One line: machine (CPU model, cores, load average now), date (UTC), commit, versions."""
    load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    commit = _git("rev-parse", "--short", "HEAD") or "unknown"
    # the code and scenes measured (not the outputs a benchmark writes, such as its plot)
    dirty = _git("status", "--porcelain", "--untracked-files=no", "--", "thinfilm_mi/*.py", "benchmarks/*.py",
                 "scenes")
    versions = []
    for module in ("mitsuba", "drjit"):
        with contextlib.suppress(ImportError):
            versions.append(f"{module.capitalize().replace('Drjit', 'Dr.Jit')} {__import__(module).__version__}")
    return (f"Measured on {_cpu_model()}, {os.cpu_count()} cores, load average {load} (1 / 5 / 15 min) at the start; "
            f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; commit `{commit}`"
            + (" with uncommitted changes" if dirty else "") + "; " + ", ".join(versions) + ".")


def write(name: str, body: str, header: str) -> Path:
    """``docs/_generated/<name>.md``: ``header``, the command line, then ``body``."""
    GENERATED.mkdir(parents=True, exist_ok=True)
    command = " ".join(["python", f"benchmarks/{name}.py", *(a for a in sys.argv[1:] if a != "--write-docs")])
    # tmm prints its notices ("Warning: Layers that are almost perfectly opaque ...") on stdout,
    # where they would split a Markdown table
    body = "\n".join(line for line in body.splitlines() if not line.startswith("Warning: "))
    if not any(line.lstrip().startswith("|") for line in body.splitlines()):
        body = "```text\n" + body.strip("\n") + "\n```"
    path = GENERATED / f"{name}.md"
    path.write_text(f"*{header}* Command: `{command}`.\n\n{body.strip()}\n", encoding="utf-8")
    return path


class _Tee(io.TextIOBase):
    """Passes writes on to ``stream`` and keeps them."""

    def __init__(self, stream):
        self.stream, self.kept = stream, io.StringIO()

    def write(self, text: str) -> int:
        self.kept.write(text)
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()

    def reconfigure(self, **kwargs) -> None:
        """``sys.stdout.reconfigure`` (line buffering, as rgb_bench asks) of the stream it passes to."""
        self.stream.reconfigure(**kwargs)


@contextlib.contextmanager
def write_docs_option(name: str):
    """Run the block; with ``--write-docs`` in ``sys.argv``, write what it printed to the docs."""
    if "--write-docs" not in sys.argv:
        yield
        return
    sys.argv.remove("--write-docs")
    header = provenance()      # the load average at the start
    tee, stdout = _Tee(sys.stdout), sys.stdout
    sys.stdout = tee
    try:
        yield
    finally:
        sys.stdout = stdout
    path = write(name, tee.kept.getvalue(), header)
    print(f"wrote {path.relative_to(REPO)}", file=sys.stderr)
