"""``python -m thinfilm_mi design TARGETS.yml``: design a coating, report it, render it.

    python -m thinfilm_mi design examples/design/ar.yml
    python -m thinfilm_mi design examples/design/ar.yml --tolerance 1%:200 --json
    python -m thinfilm_mi design examples/design/decorative.yml --plot out/deco.png \\
        --render out/deco.png

The design itself is :func:`thinfilm_mi.design.design` (imported when the
command runs, so other subcommands do not import scipy). ``--render`` writes a
scene, ``OUT.xml`` beside the image: the designed stack on a sphere of the
substrate (``thinfilm_dielectric``, or ``thinfilm_conductor`` for an absorbing
substrate) on the stage of the demo scene (``scenes/include/stage.xml``), and
renders it with :func:`thinfilm_mi.batch.scene.render_file` (``thinfilm-render``) into
``OUT.exr`` and ``OUT.png``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TextIO
from xml.sax.saxutils import quoteattr

from thinfilm_mi.batch import scene as batch_scene
from thinfilm_mi.cli.parser import failure, report_error
from thinfilm_mi.cli.render import summary
from thinfilm_mi.errors import RenderError, ThinFilmError, UsageError, require_extra

__all__ = ["add_parser", "cmd_design", "design_scene", "render_design", "ProgressBar", "check_output_options",
           "write_outputs", "add_output_options", "run_with_progress"]

PROG = "python -m thinfilm_mi design"
RENDER_SIZE = "320x213"
RENDER_SPP = 32


class ProgressBar:
    """A ``progress(fraction, message)`` callback (:func:`thinfilm_mi.design.design`,
    :func:`thinfilm_mi.design.fit`) on the one progress bar of the commands
    (:func:`thinfilm_mi.batch.scene.progress_bar`, tqdm), in thousandths."""

    def __init__(self, stream: TextIO, desc: str = "design"):
        self.bar = batch_scene.progress_bar(stream, total=1000, unit="‰", desc=desc)

    def __call__(self, fraction: float, message: str) -> None:
        self.bar.set_postfix_str(message, refresh=False)
        self.bar.update(int(round(1000 * min(max(fraction, 0.0), 1.0))) - self.bar.n)

    def close(self) -> None:
        self.bar.close()


def _stage() -> Path:
    for root in (Path.cwd(), Path(__file__).resolve().parents[2]):
        path = root / "scenes" / "include" / "stage.xml"
        if path.is_file():
            return path
    raise UsageError("--render: scenes/include/stage.xml (the demo scene's stage) was not found "
                         "in the working directory or the source checkout")


def design_scene(layers: str, substrate, substrate_spec: str, ambient_spec: str) -> str:
    """The XML of a sphere of ``substrate`` (a resolved material) under ``layers`` on the demo stage."""
    k = substrate.constant.imag if substrate.constant is not None else None
    if k is None:
        wl = [max(substrate.wavelength_range[0], 360.0), min(substrate.wavelength_range[1], 830.0)]
        import numpy as np

        k = float(np.max(substrate.index(np.linspace(wl[0], wl[1], 95)).imag))
    if k > 1e-6:
        if substrate.constant is not None:
            base = (f'<float name="eta" value="{substrate.constant.real!r}"/>\n'
                    f'            <float name="k" value="{substrate.constant.imag!r}"/>')
        else:
            base = f'<string name="material" value={quoteattr(substrate_spec)}/>'
        bsdf = "thinfilm_conductor"
    else:
        value = repr(substrate.constant.real) if substrate.constant is not None else substrate_spec
        base = f'<string name="int_ior" value={quoteattr(value)}/>'
        bsdf = "thinfilm_dielectric"
    return f"""<!-- written by {PROG} --render: the designed stack on a sphere of the substrate -->
<scene version="3.0.0">
    <include filename={quoteattr(str(_stage()))}/>
    <shape type="sphere">
        <point name="center" value="0, 0.75, 0"/>
        <float name="radius" value="0.75"/>
        <bsdf type="{bsdf}">
            {base}
            <string name="ext_ior" value={quoteattr(ambient_spec)}/>
            <string name="layers" value={quoteattr(layers)}/>
        </bsdf>
    </shape>
</scene>
"""


def render_design(result, output: str | Path, size: str = RENDER_SIZE, spp: int = RENDER_SPP,
                  variant: str = batch_scene.DEFAULT_VARIANT, seed: int = 0, progress: TextIO | None = None):
    """Write ``OUT.xml`` (:func:`design_scene`) and render it to ``OUT.exr`` and
    ``OUT.png`` with :func:`thinfilm_mi.batch.scene.render_file`; returns its
    :class:`~thinfilm_mi.batch.scene.RenderResult`."""
    out = Path(output)
    if out.suffix.lower() not in (".png", ".exr"):
        raise UsageError(f"--render {str(output)!r}: expected an .png (or .exr) file name")
    problem = result.problem
    xml = design_scene(result.layers, problem.substrate, problem.substrate_spec, problem.ambient_spec)
    scene = out.with_suffix(".xml")
    scene.parent.mkdir(parents=True, exist_ok=True)
    scene.write_text(xml, encoding="utf-8")
    return batch_scene.render_file(scene, out.with_suffix(".exr"), spp=spp, size=batch_scene.parse_size(size),
                           variant=variant, seed=seed, progress=progress)


def cmd_design(args: argparse.Namespace) -> int:
    """Run the ``design`` subcommand; a failure is reported in one line
    (:func:`thinfilm_mi.cli.parser.report_error`)."""

    def work(tolerance, progress):
        from thinfilm_mi import design as dz

        if args.evaluate is not None:
            return dz.evaluate(args.targets, args.evaluate, tolerance=tolerance, tolerance_seed=args.seed or 0)
        return dz.design(args.targets, start=args.start, max_layers=args.max_layers, seeds=args.seeds,
                         seed=args.seed, time_limit=args.time_limit, tolerance=tolerance,
                         tolerance_seed=args.seed or 0, progress=progress)

    result, status = run_with_progress(PROG, args, "design", work, bar=args.evaluate is None)
    return status if result is None else write_outputs(PROG, args, result)


def run_with_progress(prog: str, args: argparse.Namespace, desc: str, work, bar: bool = True):
    """``(work(tolerance, progress), None)``, after :func:`check_output_options`,
    with a :class:`ProgressBar` (unless ``--quiet`` or not ``bar``); on an error
    ``(None, exit status)``, the error reported in one line."""
    progress = None
    try:
        tolerance = check_output_options(args)
        progress = ProgressBar(sys.stderr, desc) if bar and not args.quiet else None
        return work(tolerance, progress), None
    except (RenderError, ThinFilmError, ValueError) as e:
        return None, report_error(prog, e, args.verbose)
    finally:
        if progress is not None:
            progress.close()


def check_output_options(args: argparse.Namespace):
    """Check the output options that ``design`` and ``fit`` share (before the
    work, so that a bad one fails first); returns the parsed ``--tolerance``."""
    from thinfilm_mi.design import parse_tolerance

    if args.plot:
        require_extra("matplotlib", "plot", "--plot")
    tolerance = parse_tolerance(args.tolerance) if args.tolerance else None
    if args.spp < 1:
        raise UsageError(f"--spp must be >= 1, got {args.spp}")
    batch_scene.parse_size(args.size)
    if args.render and Path(args.render).suffix.lower() not in (".png", ".exr"):
        raise UsageError(f"--render {args.render!r}: expected an .png (or .exr) file name")
    return tolerance


def write_outputs(prog: str, args: argparse.Namespace, result, rendered_stack=None) -> int:
    """Print ``result``'s table (or ``--json``), write ``--plot`` (its ``figure()``)
    and ``--render`` (:func:`render_design` of ``rendered_stack``, default the
    result: anything with ``layers`` and ``problem``); return the exit status."""
    print(result.to_json(indent=1) if args.json else result.table())
    if args.plot:
        try:
            fig = result.figure()
            path = Path(args.plot)
            path.parent.mkdir(parents=True, exist_ok=True)
            fig.savefig(path)
        except Exception as e:
            return report_error(prog, failure(e, f"cannot write --plot {args.plot}: {e}"), args.verbose)
        print(f"{prog}: wrote {path}", file=sys.stderr)
    if args.render:
        try:
            rendered = render_design(result if rendered_stack is None else rendered_stack, args.render,
                                     size=args.size, spp=args.spp, variant=args.variant,
                                     progress=None if args.quiet else sys.stderr)
        except RenderError as e:
            return report_error(prog, e, args.verbose)
        print(summary(rendered), file=sys.stderr)
    return 0


def add_output_options(p: argparse.ArgumentParser, json_help: str, plot_help: str, tolerance_help: str) -> None:
    """The options of :func:`check_output_options` and :func:`write_outputs`."""
    p.add_argument("--tolerance", metavar="SIGMA[:DRAWS][:DIST]", help=tolerance_help)
    p.add_argument("--json", action="store_true", help=json_help)
    p.add_argument("--plot", metavar="FIG.png", help=plot_help)
    p.add_argument("--render", metavar="OUT.png", help="render the stack on a sphere of the substrate "
                                                       "(also writes OUT.xml and OUT.exr)")
    p.add_argument("--size", default=RENDER_SIZE, metavar="WxH", help=f"render size (default {RENDER_SIZE})")
    p.add_argument("--spp", type=int, default=RENDER_SPP, help=f"render samples per pixel (default {RENDER_SPP})")
    p.add_argument("--variant", default=batch_scene.DEFAULT_VARIANT, help="Mitsuba variant of the render")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--verbose", action="store_true")


def add_parser(sub) -> argparse.ArgumentParser:
    """Add the ``design`` subcommand to ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser(
        "design", help="design a coating for a targets file (needle synthesis, refinement, tolerances)",
        description="Design a thin-film stack for the targets of a YAML file (R, T, A, luminous Y, colour, "
                    "each with a tolerance), report what it achieves, and optionally its tolerances, a "
                    "figure and a render. See the README, 'Designing a coating'.")
    p.add_argument("targets", metavar="TARGETS.yml", help="the targets file")
    p.add_argument("--start", metavar="'MAT NM; ...'", help="starting stack (default: the file's start, "
                                                            "else several seeds)")
    p.add_argument("--evaluate", metavar="'MAT NM; ...'", help="report what this stack achieves; no design")
    p.add_argument("--max-layers", type=int, help="at most this many films (default: the file's, else 8)")
    p.add_argument("--seeds", type=int, help="seed stacks tried without a start (default: the file's, else 6)")
    p.add_argument("--seed", type=int, help="random seed of the seeds and the tolerance draws (default 0)")
    p.add_argument("--time-limit", type=float, metavar="SECONDS", help="start no new seed after this")
    add_output_options(p, "print JSON (layers, merit, seconds, targets, tolerance)",
                       "draw spectra, colour against angle and tolerance spread",
                       "Monte-Carlo thickness errors, e.g. 1%%:200 (relative), 2nm:500 (absolute), "
                       "1%%:200:uniform (±1 %%); normal by default")
    p.set_defaults(func=cmd_design)
    return p
