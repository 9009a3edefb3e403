"""``thinfilm-render``: render a Mitsuba 3 scene that uses thin-film BSDFs.

Mitsuba's own ``mitsuba`` executable cannot load Python plugins, so this
command does the same job from Python::

    thinfilm-render SCENE.xml [SCENE.xml ...] [-o OUT.exr | --out-dir DIR]
                    [--spp N] [--size WxH] [--variant V] [-D name=value ...]
                    [--seed S] [--verbose]

Parameter grids (many frames of one scene, on Dask worker processes or a
cluster) are ``thinfilm-render sweep``: see :mod:`thinfilm_mi.cli.sweep`.

Several scenes are rendered one after the other in the same process (Mitsuba
and the plugins are set up once), each into ``DIR/<scene-stem>.exr``; ``-o``
names the output of a single scene only. What a render does (``-D`` parameters,
the polarized variant a scene may need, ``--size``/``--spp`` overrides, passes,
EXR and PNG output) is :func:`thinfilm_mi.batch.scene.render_file`; this module
parses the command line and reports.

Exit codes (:func:`thinfilm_mi.cli.parser.exit_code`): 0 success; 2 a bad
command line, scene, parameter or machine set-up (one line
``thinfilm-render: error: ...`` on stderr); 1 a failure while rendering or
writing the output. ``--verbose`` adds the traceback. With several scenes, a
scene that fails is reported (one line) and the others are still rendered; the
exit status is then the highest of the failures'.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Sequence

from thinfilm_mi.batch.scene import (
    DEFAULT_MAX_PASS_SAMPLES,
    DEFAULT_OUT_DIR,
    DEFAULT_VARIANT,
    PROG,
    RenderResult,
    default_output,
    parse_defines,
    parse_size,
    render_file,
)
from thinfilm_mi.cli.parser import ArgumentParser, exit_code, failure, report_error, run_command
from thinfilm_mi.errors import RenderError, UsageError

__all__ = ["render_main", "run", "add_render_arguments", "build_parser", "plan_outputs", "summary"]


def add_render_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options of ``thinfilm-render`` (shared with ``python -m thinfilm_mi render``)."""
    parser.add_argument("scene", nargs="+", help="Mitsuba 3 scene file(s) (XML)")
    parser.add_argument("-o", "--output", metavar="OUT.exr",
                        help="output EXR of a single scene (a PNG preview is written beside "
                             "it); default OUT_DIR/<scene-stem>.exr")
    parser.add_argument("--out-dir", default=DEFAULT_OUT_DIR, metavar="OUT_DIR",
                        help=f"folder of the outputs not named with -o (default {DEFAULT_OUT_DIR})")
    parser.add_argument("--spp", type=int, metavar="N",
                        help="samples per pixel (default: the scene's sampler sample_count)")
    parser.add_argument("--size", metavar="WxH", help="film size in pixels, e.g. 640x480")
    parser.add_argument("--variant", default=DEFAULT_VARIANT,
                        help=f"Mitsuba variant (default {DEFAULT_VARIANT}); a scene that needs a "
                             "polarized one (a stokes integrator, a polarizer) is rendered in the "
                             "polarized variant of its family, said on stderr")
    parser.add_argument("-D", dest="defines", action="append", default=[], metavar="name=value",
                        help="set the scene parameter $name (repeatable)")
    parser.add_argument("--seed", type=int, default=0, help="base random seed (default 0)")
    parser.add_argument("--sensor", type=int, default=0, metavar="INDEX",
                        help="which sensor of the scene to render (default 0)")
    parser.add_argument("--max-pass-samples", type=int, default=DEFAULT_MAX_PASS_SAMPLES,
                        metavar="N", help="at most N samples (pixels x spp) per render pass "
                                          f"(default {DEFAULT_MAX_PASS_SAMPLES})")
    parser.add_argument("--verbose", action="store_true",
                        help="print tracebacks and Mitsuba's log messages")
    return parser


def build_parser(prog: str = PROG) -> argparse.ArgumentParser:
    """The parser of ``thinfilm-render`` (an :class:`~thinfilm_mi.cli.parser.ArgumentParser`)."""
    parser = ArgumentParser(
        prog=prog,
        description="Render a Mitsuba 3 scene with the thin-film BSDFs of thinfilm-mi "
                    "into a linear EXR and an sRGB PNG preview.",
        epilog=f"Parameter grids on Dask worker processes or a cluster: {prog} sweep --help",
    )
    return add_render_arguments(parser)


def summary(result: RenderResult) -> str:
    """The line printed after a render: size, samples, time, rate and the files written."""
    w, h = result.size
    sps = result.samples_per_second
    rate = f"{sps / 1e6:.2f} M" if sps >= 1e5 else f"{sps:.0f}"
    written = str(result.exr_path)
    if result.png_path is not None:
        written += f", {result.png_path}"
    else:
        written += " (no PNG: the film has no RGB/Y channels)"
    return (f"{PROG}: {w}x{h}, {result.spp} spp in {result.passes} passes: "
            f"{result.render_time:.2f} s ({rate} samples/s; scene loaded in {result.load_time:.2f} s)"
            f" -> {written}")


def plan_outputs(scenes: Sequence[str], output: str | None,
                 out_dir: str | os.PathLike = DEFAULT_OUT_DIR) -> list[Path]:
    """The EXR path of each scene: ``output`` for a single scene, else
    ``out_dir/<stem>.exr`` (two scenes with the same stem are an error)."""
    scenes = list(scenes)
    if output is not None:
        if len(scenes) != 1:
            raise UsageError(f"-o {output!r} names one output but {len(scenes)} scenes were "
                             "given; use --out-dir for several scenes")
        return [Path(output)]
    outs = [default_output(s, out_dir) for s in scenes]
    seen: dict[Path, str] = {}
    for scene, out in zip(scenes, outs):
        if out in seen:
            raise UsageError(f"{seen[out]} and {scene} would both be written to {out}; "
                             "render them separately with -o")
        seen[out] = scene
    return outs


def run(args: argparse.Namespace) -> int:
    """Run a parsed ``thinfilm-render`` command line; returns the exit status."""
    try:
        scenes = list(args.scene) if isinstance(args.scene, (list, tuple)) else [args.scene]
        outputs = plan_outputs(scenes, args.output, getattr(args, "out_dir", DEFAULT_OUT_DIR))
        size, params = parse_size(args.size), parse_defines(args.defines)
    except UsageError as e:
        return report_error(PROG, e, args.verbose)
    status = 0
    for scene, out in zip(scenes, outputs):
        try:
            result = render_file(
                scene, out, spp=args.spp, size=size, variant=args.variant, params=params,
                seed=args.seed, sensor=args.sensor, max_pass_samples=args.max_pass_samples,
                progress=sys.stderr, verbose=args.verbose)
        except RenderError as e:
            status = max(status, report_error(PROG, e, args.verbose))
            continue
        except KeyboardInterrupt as e:
            print(f"{PROG}: error: interrupted", file=sys.stderr)
            return exit_code(e)
        except Exception as e:  # anything unforeseen is a failure, still reported in one line
            status = max(status, report_error(PROG, failure(e), args.verbose))
            continue
        print(summary(result), file=sys.stderr)
    return status


def render_main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``thinfilm-render`` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["sweep"]:  # thinfilm-render sweep ...: parameter grids on Dask
        from thinfilm_mi.cli.sweep import sweep_main

        return sweep_main(argv[1:])
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as e:
        return report_error(PROG, e, "--verbose" in argv)
    except SystemExit as e:  # --help
        return int(e.code or 0)
    return run_command(run, args)


if __name__ == "__main__":
    sys.exit(render_main())
