"""``thinfilm-render sweep``: the command line of parameter sweeps on Dask
(:func:`thinfilm_mi.sweep`, :mod:`thinfilm_mi.batch.sweeps`, which describes the
grid, the cluster and the outputs)::

    thinfilm-render sweep SCENE.xml -D thickness=100:800:25 -D spp=64 --out-dir out/sweep
                    [-P key=VALUES ...] [--workers N | --scheduler ADDRESS]
                    [--size WxH] [--spp N] [--variant V] [--seed S] [--threads T]

Exit codes: 0 all frames ok, 1 some failed (or the cluster could not start), 2
a bad command line or set-up (Dask not installed: one line naming the
``[sweep]`` extra), 130 interrupted.
"""
from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Sequence

from thinfilm_mi.batch.grid import COLUMNS
from thinfilm_mi.batch.outputs import DEFAULT_OUT_DIR
from thinfilm_mi.batch.scene import DEFAULT_MAX_PASS_SAMPLES, DEFAULT_VARIANT
from thinfilm_mi.batch.scene import PROG as RENDER_PROG
from thinfilm_mi.cli.parser import ArgumentParser, exit_code, failure, report_error
from thinfilm_mi.errors import RenderError, UsageError

if TYPE_CHECKING:  # the module itself imports Dask only when a sweep runs
    from thinfilm_mi.batch.sweeps import SweepResult

__all__ = ["sweep_main", "build_parser", "summary"]

PROG = f"{RENDER_PROG} sweep"


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``thinfilm-render sweep``."""
    parser = ArgumentParser(
        prog=PROG,
        description="Render a scene over a grid of parameter values on Dask (a local cluster "
                    "of worker processes, or a running cluster), one EXR + PNG per frame, "
                    "with manifest.csv and contact_sheet.png. Rerunning resumes.")
    parser.add_argument("scene", help="Mitsuba 3 scene file (XML)")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="name=VALUES",
                        help="a grid axis over the scene parameter $name: START:STOP:STEP "
                             "(STOP included), a,b,c or one value (repeatable)")
    parser.add_argument("-P", dest="parameters", action="append", default=[], metavar="key=VALUES",
                        help="a grid axis over a mi.traverse parameter (numbers), set on the "
                             "loaded scene without reloading it; key may be the end of one key, "
                             "e.g. bsdf.layers.0.thickness (repeatable)")
    parser.add_argument("--out-dir", default=DEFAULT_OUT_DIR,
                        help=f"output folder (default {DEFAULT_OUT_DIR})")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N",
                       help="worker processes of the local cluster (default: one per core, "
                            "one per GPU for cuda_* variants)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="use a running Dask cluster, e.g. tcp://10.0.0.5:8786")
    parser.add_argument("--threads", type=int, metavar="T",
                        help="Dr.Jit threads per worker (default: cores / local workers; on "
                             "a cluster, each worker's --nthreads)")
    parser.add_argument("--frames-per-task", type=int, metavar="K",
                        help="frames of one scene load per Dask task (default: about two "
                             "tasks per worker)")
    parser.add_argument("--spp", type=int, metavar="N", help="samples per pixel")
    parser.add_argument("--size", metavar="WxH", help="film size in pixels, e.g. 320x240")
    parser.add_argument("--variant", default=DEFAULT_VARIANT,
                        help=f"Mitsuba variant (default {DEFAULT_VARIANT}); a scene that needs a "
                             "polarized one is rendered in the polarized variant of its family")
    parser.add_argument("--seed", type=int, default=0, help="random seed of every frame (default 0)")
    parser.add_argument("--sensor", type=int, default=0, metavar="INDEX",
                        help="which sensor to render (default 0)")
    parser.add_argument("--max-pass-samples", type=int, default=DEFAULT_MAX_PASS_SAMPLES,
                        metavar="N", help="at most N samples (pixels x spp) per render pass")
    parser.add_argument("--timeout", type=float, metavar="SECONDS",
                        help="give up (like Ctrl-C) after this long")
    parser.add_argument("--no-contact-sheet", action="store_true", help="skip contact_sheet.png")
    parser.add_argument("--verbose", action="store_true", help="tracebacks and Mitsuba warnings")
    return parser


def summary(result: SweepResult) -> str:
    """The lines printed after a sweep: counts, time, files, and the first failures."""
    where = f"{result.workers} worker(s)" if result.rendered else "nothing to render"
    text = (f"{PROG}: {len(result)} frames ({result.rendered} rendered, {result.skipped} already "
            f"done) in {result.seconds:.1f} s with {where}: {len(result.ok)} ok, "
            f"{len(result.failed)} failed -> {result.manifest}")
    if result.contact_sheet:
        text += f", {result.contact_sheet}"
    for row in result.failed[:3]:
        params = " ".join(f"{k}={row[k]}" for k in result.columns[:-len(COLUMNS)])
        text += f"\n{PROG}: failed: {params}: {row['error']}"
    if len(result.failed) > 3:
        text += f"\n{PROG}: ... and {len(result.failed) - 3} more (see the manifest)"
    return text


def sweep_main(argv: Sequence[str] | None = None) -> int:
    """``thinfilm-render sweep ...``; returns the exit status (see the module docstring)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    verbose = "--verbose" in argv
    try:
        args = build_parser().parse_args(argv)
        if not args.defines and not args.parameters:
            raise UsageError("no grid: give at least one -D name=VALUES or -P key=VALUES")
        from thinfilm_mi.batch.sweeps import sweep  # Dask: the [sweep] extra

        result = sweep(args.scene, args.defines, args.parameters, args.out_dir,
                       workers=args.workers, scheduler=args.scheduler, spp=args.spp,
                       size=args.size, variant=args.variant, seed=args.seed, sensor=args.sensor,
                       max_pass_samples=args.max_pass_samples, threads=args.threads,
                       frames_per_task=args.frames_per_task,
                       contact_sheet=not args.no_contact_sheet, progress=sys.stderr,
                       timeout=args.timeout, verbose=args.verbose)
    except SystemExit as e:  # --help
        return int(e.code or 0)
    except RenderError as e:
        return report_error(PROG, e, verbose)
    except KeyboardInterrupt as e:
        print(f"{PROG}: interrupted; finished frames are in the manifest, rerun to resume",
              file=sys.stderr)
        return exit_code(e)
    except TimeoutError as e:
        return report_error(PROG, failure(e, f"timed out after {args.timeout} s; rerun to resume"),
                            verbose)
    except Exception as e:  # the cluster could not start, etc.: one line, as thinfilm-render
        return report_error(PROG, failure(e), verbose)
    print(summary(result), file=sys.stderr)
    return 1 if result.failed else 0
