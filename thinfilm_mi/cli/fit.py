"""``python -m thinfilm_mi fit MEASUREMENTS.yml``: fit a stack to measured spectra, report it, render it.

    python -m thinfilm_mi fit examples/fit/measurements.yml
    python -m thinfilm_mi fit examples/fit/measurements.yml --json --tolerance 1%:200
    python -m thinfilm_mi fit examples/fit/measurements.yml --plot out/fit.png --render out/fit.png

The fit is :func:`thinfilm_mi.design.fit` (imported when the command runs).
``--render`` is ``design``'s (:func:`thinfilm_mi.cli.design.render_design`): the
fitted stack on a sphere of the substrate on the demo scene's stage, ``OUT.xml``,
``OUT.exr`` and ``OUT.png``; a fitted dispersive material is written beside them
as a table (``fit_NAME.csv``), as ``--materials DIR`` writes it.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from types import SimpleNamespace

from thinfilm_mi.batch import scene as batch_scene
from thinfilm_mi.cli.design import RENDER_SIZE, RENDER_SPP, ProgressBar, render_design
from thinfilm_mi.cli.parser import failure, report_error
from thinfilm_mi.cli.render import summary
from thinfilm_mi.errors import RenderError, ThinFilmError, UsageError, require_extra

__all__ = ["add_parser", "cmd_fit"]

PROG = "python -m thinfilm_mi fit"


def cmd_fit(args: argparse.Namespace) -> int:
    """Run the ``fit`` subcommand; a failure is reported in one line."""
    bar = None
    try:
        from thinfilm_mi import design as dz

        if args.plot:
            require_extra("matplotlib", "plot", "--plot")
        tolerance = dz.parse_tolerance(args.tolerance) if args.tolerance else None
        if args.spp < 1:
            raise UsageError(f"--spp must be >= 1, got {args.spp}")
        batch_scene.parse_size(args.size)
        if args.render and Path(args.render).suffix.lower() not in (".png", ".exr"):
            raise UsageError(f"--render {args.render!r}: expected an .png (or .exr) file name")
        bar = None if args.quiet else ProgressBar(sys.stderr, "fit")
        result = dz.fit(args.measurements, starts=args.starts, seed=args.seed, tolerance=tolerance,
                        tolerance_seed=args.seed or 0, progress=bar)
    except (RenderError, ThinFilmError, ValueError) as e:
        return report_error(PROG, e, args.verbose)
    finally:
        if bar is not None:
            bar.close()
    if args.materials:
        try:
            layers = result.layers_in(args.materials)
        except (OSError, ThinFilmError) as e:
            return report_error(PROG, failure(e, f"cannot write --materials {args.materials}: {e}"), args.verbose)
        print(f"{PROG}: fitted stack with its material tables: {layers}", file=sys.stderr)
    print(result.to_json(indent=1) if args.json else result.table())
    if args.plot:
        try:
            path = Path(args.plot)
            path.parent.mkdir(parents=True, exist_ok=True)
            result.figure().savefig(path)
        except Exception as e:
            return report_error(PROG, failure(e, f"cannot write --plot {args.plot}: {e}"), args.verbose)
        print(f"{PROG}: wrote {path}", file=sys.stderr)
    if args.render:
        try:
            layers = result.layers_in(Path(args.render).parent)
            rendered = render_design(SimpleNamespace(problem=result.problem, layers=layers), args.render,
                                     size=args.size, spp=args.spp, variant=args.variant,
                                     progress=None if args.quiet else sys.stderr)
        except RenderError as e:
            return report_error(PROG, e, args.verbose)
        print(summary(rendered), file=sys.stderr)
    return 0


def add_parser(sub) -> argparse.ArgumentParser:
    """Add the ``fit`` subcommand to ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser(
        "fit", help="fit a stack's thicknesses and dispersion to measured spectra, with uncertainties",
        description="Fit the free parameters of a measurements file (thicknesses, dispersion models, data "
                    "scale factors) to its measured R and T spectra by weighted least squares from several "
                    "starts; report values, standard errors, correlations, χ²/dof and residuals. See the "
                    "README, 'Fitting measured spectra'.")
    p.add_argument("measurements", metavar="MEASUREMENTS.yml", help="the measurements file")
    p.add_argument("--starts", type=int, help="starts of the fit (default: the file's, else 8)")
    p.add_argument("--seed", type=int, help="random seed of the starts and the tolerance draws (default 0)")
    p.add_argument("--tolerance", metavar="SIGMA[:DRAWS][:DIST]",
                   help="Monte-Carlo thickness errors on the fitted stack, as in design (e.g. 1%%:200)")
    p.add_argument("--json", action="store_true", help="print JSON (layers, χ², parameters, residuals, ...)")
    p.add_argument("--plot", metavar="FIG.png", help="draw measured against fitted spectra, with residuals")
    p.add_argument("--materials", metavar="DIR", help="write fitted dispersive materials as tables into DIR")
    p.add_argument("--render", metavar="OUT.png", help="render the fitted stack on a sphere of the substrate "
                                                       "(also writes OUT.xml and OUT.exr)")
    p.add_argument("--size", default=RENDER_SIZE, metavar="WxH", help=f"render size (default {RENDER_SIZE})")
    p.add_argument("--spp", type=int, default=RENDER_SPP, help=f"render samples per pixel (default {RENDER_SPP})")
    p.add_argument("--variant", default=batch_scene.DEFAULT_VARIANT, help="Mitsuba variant of the render")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--verbose", action="store_true")
    p.set_defaults(func=cmd_fit)
    return p
