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

from thinfilm_mi.cli.design import add_output_options, run_with_progress, write_outputs
from thinfilm_mi.cli.parser import failure, report_error
from thinfilm_mi.errors import ThinFilmError

__all__ = ["add_parser", "cmd_fit"]

PROG = "python -m thinfilm_mi fit"


def cmd_fit(args: argparse.Namespace) -> int:
    """Run the ``fit`` subcommand; a failure is reported in one line."""

    def work(tolerance, progress):
        from thinfilm_mi import design as dz

        return dz.fit(args.measurements, starts=args.starts, seed=args.seed, global_stage=args.global_stage,
                      tolerance=tolerance, tolerance_seed=args.seed or 0, progress=progress)

    result, status = run_with_progress(PROG, args, "fit", work)
    if result is None:
        return status
    try:
        if args.materials:
            layers = result.layers_in(args.materials)
            print(f"{PROG}: fitted stack with its material tables: {layers}", file=sys.stderr)
        # a fitted dispersive material is rendered from its table, written beside the image
        rendered = SimpleNamespace(problem=result.problem, layers=result.layers_in(Path(args.render).parent)) \
            if args.render else None
    except (OSError, ThinFilmError) as e:
        return report_error(PROG, failure(e, f"cannot write the fitted material tables: {e}"), args.verbose)
    return write_outputs(PROG, args, result, rendered)


def add_parser(sub) -> argparse.ArgumentParser:
    """Add the ``fit`` subcommand to ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser(
        "fit", help="fit a stack's thicknesses and dispersion to measured spectra, with uncertainties",
        description="Fit the free parameters of a measurements file (thicknesses, dispersion models, data "
                    "scale factors) to its measured R and T spectra by weighted least squares from several "
                    "starts, some chosen by a global search over the films' thicknesses; report values, "
                    "standard errors, correlations, χ²/dof (with its p-value) and residuals. See the "
                    "README, 'Fitting measured spectra'.")
    p.add_argument("measurements", metavar="MEASUREMENTS.yml", help="the measurements file")
    p.add_argument("--starts", type=int, help="local descents of the fit: from the nominal stack, the global "
                                              "stage's best, then random (default: the file's, else 8)")
    p.add_argument("--seed", type=int, help="random seed of the starts and the tolerance draws (default 0)")
    p.add_argument("--global", dest="global_stage", default="evolve", metavar="STAGE",
                   help="the search over the films' thicknesses that chooses starts of the local descents: "
                        "evolve (differential evolution within ±40%% of the nominal ones; the default) or none")
    p.add_argument("--materials", metavar="DIR", help="write fitted dispersive materials as tables into DIR")
    add_output_options(p, "print JSON (layers, χ², parameters with errors and correlations, residuals, ...)",
                       "draw measured against fitted spectra, with residuals",
                       "Monte-Carlo thickness errors on the fitted stack, as in design (e.g. 1%%:200)")
    p.set_defaults(func=cmd_fit)
    return p
