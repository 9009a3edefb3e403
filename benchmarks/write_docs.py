"""Run every benchmark the documentation quotes and write its tables (``docs/_generated/``).

    python benchmarks/write_docs.py                 # all of them, one after the other
    python benchmarks/write_docs.py --only stability,rgb_bench
    python benchmarks/write_docs.py --list          # the benchmarks and their settings

Each benchmark of :data:`BENCHMARKS` runs in a process of its own with ``--write-docs``
and the settings listed there (the ones the benchmark page states), so each include file
``docs/_generated/<name>.md`` that ``docs/benchmarks.md`` shows is the output of one run,
headed by the machine (CPU, cores, load average at its start), the date and the commit
(``benchmarks/docs_output.py``). Ratios are taken within one run; on a shared machine the
seconds move with the load the header states. Commit the files it writes.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

__all__ = ["BENCHMARKS", "main"]

HERE = Path(__file__).resolve().parent

#: benchmark (benchmarks/<name>.py) -> the arguments the benchmark page's table is made with:
#: fewer rounds than the benchmarks' defaults where a full run takes tens of minutes on the
#: shared 2-core machine (medians of 3 rounds instead of 5-9; the first image once per
#: configuration); each table's header repeats the command it was made with
BENCHMARKS = {
    "optics_throughput": [],
    "speed_vs_error": [],
    "render_bench": ["--films", "1,10,30", "--repeats", "3", "--first-repeats", "1"],
    "plugin_bench": ["--repeats", "3", "--demo-repeats", "3", "--first-repeats", "3"],
    "rgb_bench": ["--build-repeats", "3"],
    "band_bench": ["--repeats", "3", "--first-repeats", "1", "--de-spp", "256"],
    "deep_bench": ["--rounds", "3"],
    "stability": ["--worst"],
    "diffuse_models": ["--spp", "32"],
    "diffuse_texture_bench": [],
    "diffuse_grad_bench": ["--repeats", "3", "--edit-repeats", "3"],
    "orennayar_energy": [],
    "design_bench": ["--cases", "10"],
    "fit_bench": [],
    "sweep_bench": [],
    "gc_guard_bench": [],
    "coating_bench": ["--repeats", "3", "--first-repeats", "1"],
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", help="comma-separated names of BENCHMARKS")
    ap.add_argument("--list", action="store_true")
    args = ap.parse_args(argv)
    names = args.only.split(",") if args.only else list(BENCHMARKS)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        ap.error(f"--only: {unknown} not in {list(BENCHMARKS)}")
    if args.list:
        for name in names:
            print(" ".join(["python", f"benchmarks/{name}.py", *BENCHMARKS[name], "--write-docs"]))
        return 0
    failed = []
    for name in names:
        start = time.perf_counter()
        print(f"== {name} {' '.join(BENCHMARKS[name])}", file=sys.stderr, flush=True)
        res = subprocess.run([sys.executable, str(HERE / f"{name}.py"), *BENCHMARKS[name], "--write-docs"],
                             stdout=subprocess.DEVNULL)
        print(f"== {name}: exit {res.returncode}, {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
        if res.returncode != 0:
            failed.append(name)
    if failed:
        print(f"failed: {failed}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
