"""``python -m thinfilm_mi``: command-line tools of thinfilm-mi.

Subcommands::

    render     render one or more scenes (the same options as ``thinfilm-render``)
    materials  list the named materials
    spectrum   print (or plot) R and T of a stack against wavelength at given angles
    colour     colour of a stack at given angles: XYZ, xy, L*a*b*, sRGB swatch, luminous Y
               (table, --json, --csv, --plot), under D65, A, F11 or blackbody:T
    demo       render scenes/demo.xml into OUT/demo.exr and OUT/demo.png
    design     design a coating for a targets file (thinfilm_mi.cli.design)
    fit        fit a stack to measured spectra (thinfilm_mi.cli.fit)

Examples::

    python -m thinfilm_mi render scenes/demo.xml --spp 64 --size 640x480
    python -m thinfilm_mi spectrum --layers "1.46 500; 0.42+2.47j 20" --substrate 1.6 \\
        --angles 0,30,60 --wl 360:830:5 --plot rt.png
    python -m thinfilm_mi colour --layers "MgF2 99.6" --substrate 1.52 --angles 0:80:10 \\
        --illuminant D65 --plot colour.png
    python -m thinfilm_mi demo --out out
"""
from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path
from typing import Sequence

import numpy as np

from thinfilm_mi.batch.scene import DEFAULT_VARIANT, parse_size, render_file, setup_llvm_only
from thinfilm_mi.batch.scene import PROG as RENDER_PROG
from thinfilm_mi.cli import render as render_command
from thinfilm_mi.cli.parser import ArgumentParser, failure, report_error, run_command
from thinfilm_mi.errors import RenderError, ThinFilmError, UsageError, require_extra

__all__ = [
    "PROG", "DEMO_LAYERS", "DEMO_SUBSTRATE", "DEMO_DESCRIPTION", "cmd_materials", "MAX_GRID_POINTS",
    "parse_angles", "parse_wavelengths", "spectrum_table", "format_spectrum", "plot_spectrum", "cmd_spectrum",
    "cmd_colour", "find_demo_scene", "reflectance_colours", "write_reflectance_image", "cmd_demo", "build_parser",
    "main",
]

PROG = "python -m thinfilm_mi"

#: The demo stack of the README: a 500 nm SiO2-like film over 20 nm of an
#: Au-like metal on glass (constant indices).
DEMO_LAYERS = "1.46 500; 0.42+2.47j 20"
DEMO_SUBSTRATE = "1.6"
DEMO_DESCRIPTION = "SiO2-like 1.46 500 nm; Au-like 0.42+2.47j 20 nm on glass 1.6"


def _pyplot(purpose: str = "--plot"):
    """``matplotlib.pyplot`` on the Agg backend; :class:`~thinfilm_mi.errors.MissingExtra`
    naming the ``[plot]`` extra when matplotlib is not installed."""
    matplotlib = require_extra("matplotlib", "plot", purpose)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save_figure(fig, path) -> Path:
    """Lay out ``fig``, write it to ``path`` (creating folders) and close it."""
    plt = _pyplot()
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


# --------------------------------------------------------------------------------------
# materials


def cmd_materials(args: argparse.Namespace) -> int:
    from thinfilm_mi.materials import catalog as materials

    fmt = getattr(materials, "format_material_table", None)
    if fmt is None:
        print("no material table: this version of thinfilm_mi.materials.catalog has no named "
              "materials (format_material_table is missing); use numeric indices such as "
              "'1.46' or '0.42+2.47j'", file=sys.stderr)
        return 0
    try:
        table = fmt()
    except Exception as e:
        return report_error(f"{PROG} materials",
                            failure(e, f"cannot list materials: {type(e).__name__}: {e}"), args.verbose)
    print(table if isinstance(table, str) else "\n".join(map(str, table)))
    return 0


# --------------------------------------------------------------------------------------
# spectrum


#: Most values a START:STOP:STEP grid may hold (0.001 nm steps over 360-830 nm);
#: more would only exhaust memory (``--wl 360:830:1e-7`` asked for 35 GiB).
MAX_GRID_POINTS = 1_000_000


def _parse_grid(text: str, option: str, default_step: float, example: str) -> np.ndarray:
    """``"START:STOP:STEP"`` (STOP included when on the grid), ``"START:STOP"``
    (``default_step``) or a list separated by commas or spaces -> float array;
    a malformed string (or a grid of more than :data:`MAX_GRID_POINTS` values)
    raises :class:`~thinfilm_mi.errors.UsageError` naming ``option``."""
    text = text.strip()
    try:
        if ":" in text:
            parts = [float(p) for p in text.split(":")]
            if len(parts) == 2:
                parts.append(default_step)
            if len(parts) != 3 or not all(math.isfinite(p) for p in parts):
                raise ValueError
            start, stop, step = parts
            if not (step > 0 and stop >= start):
                raise UsageError(f"{option} {text!r}: need STOP >= START and STEP > 0")
            n = int(math.floor((stop - start) / step + 1e-9)) + 1
            if n > MAX_GRID_POINTS:
                raise UsageError(f"{option} {text!r}: {n} values; at most "
                                 f"{MAX_GRID_POINTS} (use a larger STEP)")
            return start + step * np.arange(n)
        return np.array([float(t) for t in re.split(r"[,\s]+", text) if t], dtype=np.float64)
    except ValueError:
        raise UsageError(f"{option} {text!r}: expected {example}") from None


def parse_angles(text: str, below_90: bool = False) -> np.ndarray:
    """``"0,30,60"`` or ``"0:80:10"`` (degrees) -> array of degrees, each in
    [0, 90], or in [0, 90) with ``below_90`` (a colour needs light to arrive)."""
    values = _parse_grid(text, "--angles", 10.0, "degrees separated by commas, e.g. 0,30,60, "
                         "or START:STOP:STEP, e.g. 0:80:10")
    if values.size == 0:
        raise UsageError(f"--angles {text!r}: no angle given")
    top = "90)" if below_90 else "90]"
    for v in values:
        if not (math.isfinite(v) and 0.0 <= v and (v < 90.0 if below_90 else v <= 90.0)):
            raise UsageError(f"--angles {text!r}: angles must be in [0, {top} degrees, got {v:g}")
    return values


def parse_wavelengths(text: str) -> np.ndarray:
    """``"START:STOP:STEP"`` (nm, STOP included when on the grid), ``"START:STOP"``
    (5 nm steps) or a comma-separated list."""
    wl = _parse_grid(text, "--wl", 5.0, "START:STOP:STEP in nm, e.g. 360:830:5, or a list 450,550,650")
    if wl.size == 0 or not np.all(np.isfinite(wl)) or np.any(wl <= 0):
        raise UsageError(f"--wl {text!r}: wavelengths must be positive numbers of nm")
    return wl


def spectrum_table(stack, wavelengths: np.ndarray, angles_deg: np.ndarray):
    """``(R, T)`` arrays of shape (len(wavelengths), len(angles))."""
    res = stack.rt(wavelengths[:, None], np.radians(angles_deg)[None, :])
    return np.asarray(res.R, dtype=np.float64), np.asarray(res.T, dtype=np.float64)


def format_spectrum(wavelengths: np.ndarray, angles_deg: np.ndarray, R: np.ndarray,
                    T: np.ndarray) -> str:
    """Columns ``wl_nm  R@0  T@0  R@30  T@30 ...`` with a one-line header."""
    cols = ["wl_nm"]
    for a in angles_deg:
        cols += [f"R@{a:g}", f"T@{a:g}"]
    width = max(10, max(len(c) for c in cols) + 2)
    lines = ["".join(c.rjust(width) for c in cols)]
    for i, wl in enumerate(wavelengths):
        cells = [f"{wl:.6g}"]
        for j in range(len(angles_deg)):
            cells += [f"{R[i, j]:.6f}", f"{T[i, j]:.6f}"]
        lines.append("".join(c.rjust(width) for c in cells))
    return "\n".join(lines)


def plot_spectrum(path: str | Path, stack, wavelengths, angles_deg, R, T) -> Path:
    """Plot R and T against wavelength, one colour per angle, into ``path``."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(angles_deg)))
    for j, a in enumerate(angles_deg):
        ax.plot(wavelengths, R[:, j], color=colors[j], label=f"R, {a:g}°")
        ax.plot(wavelengths, T[:, j], color=colors[j], ls="--", label=f"T, {a:g}°")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("fraction of incident power")
    ax.set_ylim(-0.02, 1.02)
    ax.set_title(repr(stack), fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    return _save_figure(fig, path)


def cmd_spectrum(args: argparse.Namespace) -> int:
    prog = f"{PROG} spectrum"
    from thinfilm_mi import Stack

    try:
        if args.plot:
            _pyplot()
        angles = parse_angles(args.angles)
        wl = parse_wavelengths(args.wl)
        setup_llvm_only()
        stack = Stack(args.layers, substrate=args.substrate, ambient=args.ambient)
        R, T = spectrum_table(stack, wl, angles)
    except (UsageError, ThinFilmError, ValueError) as e:
        return report_error(prog, e, args.verbose)
    print(f"# {stack!r}; R, T unpolarised; angles in degrees in the ambient medium")
    print(format_spectrum(wl, angles, R, T))
    if args.plot:
        try:
            path = plot_spectrum(args.plot, stack, wl, angles, R, T)
        except Exception as e:
            return report_error(prog, failure(e, f"cannot write plot {args.plot}: {e}"), args.verbose)
        print(f"{prog}: wrote {path}", file=sys.stderr)
    return 0


# --------------------------------------------------------------------------------------
# colour


def cmd_colour(args: argparse.Namespace) -> int:
    prog = f"{PROG} colour"
    from thinfilm_mi import Stack

    try:
        if args.plot:
            _pyplot()
        angles = parse_angles(args.angles, below_90=True)
        setup_llvm_only()
        from thinfilm_mi.colour.report import colour_report

        stack = Stack(args.layers, substrate=args.substrate, ambient=args.ambient)
        report = colour_report(stack, angles, illuminant=args.illuminant, observer=args.observer,
                               polarizations=args.polarization.split(","))
    except (UsageError, ThinFilmError, ValueError) as e:
        return report_error(prog, e, args.verbose)
    if args.json:
        print(report.to_json(indent=1))
    else:
        print(f"# {report.describe()}; angles in degrees in the ambient medium")
        print("# X, Y, Z and the photopic Yv (V(λ)-weighted) in % of the perfect reflector; "
              "L*a*b* relative to the illuminant's white; sRGB adapted (CAT02) to D65")
        print(report.table())
    for option, path, write in (("--csv", args.csv, report.write_csv),
                                ("--plot", args.plot, lambda p: _save_figure(report.figure(), p))):
        if path:
            try:
                written = write(path)
            except Exception as e:
                return report_error(prog, failure(e, f"cannot write {option} {path}: {e}"),
                                    args.verbose)
            print(f"{prog}: wrote {written}", file=sys.stderr)
    return 0


# --------------------------------------------------------------------------------------
# demo


def find_demo_scene() -> Path | None:
    """``scenes/demo.xml`` of the working directory or of the source checkout."""
    for root in (Path.cwd(), Path(__file__).resolve().parents[2]):
        candidate = root / "scenes" / "demo.xml"
        if candidate.is_file():
            return candidate
    return None


def reflectance_colours(wavelengths: np.ndarray, R: np.ndarray) -> np.ndarray:
    """sRGB (clipped, display-encoded) colour of ``R`` (wavelength x angle)
    under D65 for the CIE 1931 2° observer (:func:`colorimetry.spectrum_colour`)."""
    from thinfilm_mi.colour.report import spectrum_colour

    return spectrum_colour(np.asarray(R, dtype=np.float64).T, wavelengths).rgb


def write_reflectance_image(path: str | Path) -> Path:
    """The demo stack's reflectance over angle and wavelength, with its D65 colour."""
    from thinfilm_mi import Stack

    plt = _pyplot("the demo's reflectance image")
    stack = Stack(DEMO_LAYERS, substrate=DEMO_SUBSTRATE)
    wl = np.arange(360.0, 830.0 + 1e-9, 2.0)
    angles = np.linspace(0.0, 89.0, 90)
    R, _ = spectrum_table(stack, wl, angles)
    rgb = reflectance_colours(wl, R)

    fig, (ax, ax_c) = plt.subplots(1, 2, figsize=(8, 4.2), dpi=120,
                                   gridspec_kw={"width_ratios": [12, 1]})
    im = ax.imshow(R.T, origin="lower", aspect="auto", cmap="magma", vmin=0, vmax=1,
                   extent=(wl[0], wl[-1], angles[0], angles[-1]))
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("angle of incidence (°)")
    ax.set_title(f"R(λ, θ): {DEMO_DESCRIPTION}", fontsize=8)
    fig.colorbar(im, ax=ax, label="reflectance (unpolarised)")
    ax_c.imshow(rgb[:, None, :], origin="lower", aspect="auto",
                extent=(0, 1, angles[0], angles[-1]))
    ax_c.set_xticks([])
    ax_c.set_title("D65\nsRGB", fontsize=8)
    ax_c.yaxis.tick_right()
    return _save_figure(fig, path)


def cmd_demo(args: argparse.Namespace) -> int:
    prog = f"{PROG} demo"
    out = Path(args.out)
    scene = find_demo_scene()
    if scene is not None:
        try:
            result = render_file(
                scene, out / "demo.exr", spp=args.spp, size=parse_size(args.size),
                variant=args.variant, seed=args.seed, progress=sys.stderr, verbose=args.verbose)
        except RenderError as e:
            return report_error(RENDER_PROG, e, args.verbose)
        print(render_command.summary(result), file=sys.stderr)
        return 0
    try:
        setup_llvm_only()
        path = write_reflectance_image(out / "demo_reflectance.png")
    except RenderError as e:
        return report_error(prog, e, args.verbose)
    except Exception as e:
        return report_error(prog, failure(e), args.verbose)
    print(f"{prog}: scenes/demo.xml not found, so no render; wrote the demo stack's "
          f"reflectance over angle and wavelength to {path}", file=sys.stderr)
    return 0


# --------------------------------------------------------------------------------------


def _add_stack_arguments(p: argparse.ArgumentParser, angles_help: str) -> None:
    """The options that describe a stack and its angles (``spectrum``, ``colour``)."""
    p.add_argument("--layers", required=True, metavar="'MAT NM; ...'",
                   help="films from the ambient side inwards, e.g. '1.46 500; 0.42+2.47j 20'")
    p.add_argument("--substrate", default="1.0", help="substrate material (default 1.0)")
    p.add_argument("--ambient", default="1.0", help="ambient material (default 1.0)")
    p.add_argument("--angles", default="0", help=f"{angles_help} (default 0)")


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog=PROG, description="thinfilm-mi command-line tools")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser("render", help="render scenes (same options as thinfilm-render)",
                       description="Render Mitsuba 3 scenes into linear EXRs and sRGB PNGs.")
    render_command.add_render_arguments(p)
    p.set_defaults(func=render_command.run)

    p = sub.add_parser("materials", help="list the named materials")
    p.add_argument("--verbose", action="store_true")
    p.set_defaults(func=cmd_materials)

    p = sub.add_parser("spectrum", help="R and T of a stack against wavelength",
                       description="Print (and optionally plot) the unpolarised reflectance R "
                                   "and transmittance T of a thin-film stack.")
    _add_stack_arguments(p, "angles of incidence in degrees, e.g. 0,30,60 or 0:90:15")
    p.add_argument("--wl", default="360:830:5", help="wavelengths START:STOP:STEP in nm "
                                                     "(default 360:830:5)")
    p.add_argument("--plot", metavar="OUT.png", help="also plot R and T into this image")
    p.add_argument("--verbose", action="store_true")
    p.set_defaults(func=cmd_spectrum)

    p = sub.add_parser("colour", aliases=["color"], help="colour of a stack: XYZ, xy, L*a*b*, sRGB, luminous Y",
                       description="CIE XYZ, xy, L*a*b*, an sRGB swatch and the photopic (V(λ)) Y "
                                   "of a stack in reflection and transmission at each angle, "
                                   "computed with colour-science (thinfilm_mi.colour.report).")
    _add_stack_arguments(p, "angles of incidence in degrees, each below 90, e.g. 0,30,60 or 0:80:10")
    p.add_argument("--illuminant", default="D65",
                   help="D65, A, F11 or blackbody:T (T in kelvin, e.g. blackbody:2856); default D65")
    p.add_argument("--observer", default="2", choices=["2", "10"],
                   help="CIE 1931 2° or CIE 1964 10° standard observer (default 2)")
    p.add_argument("--polarization", default="unpolarized", metavar="unpolarized|s|p|both",
                   help="light of these polarisations, comma-separated (default unpolarized); "
                        "with s or p the records gain a 'polarization' key")
    p.add_argument("--json", action="store_true", help="print a JSON list of records instead of the table")
    p.add_argument("--csv", metavar="FILE.csv", help="also write the records to this CSV file")
    p.add_argument("--plot", metavar="FIG.png", help="also draw spectra, chromaticity path and swatches")
    p.add_argument("--verbose", action="store_true")
    p.set_defaults(func=cmd_colour)

    p = sub.add_parser("demo", help="render scenes/demo.xml into OUT/demo.exr and OUT/demo.png")
    p.add_argument("--out", default="out", help="output folder (default out)")
    p.add_argument("--spp", type=int, help="samples per pixel (default: the scene's)")
    p.add_argument("--size", metavar="WxH", help="film size (default: the scene's)")
    p.add_argument("--variant", default=DEFAULT_VARIANT)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--verbose", action="store_true")
    p.set_defaults(func=cmd_demo)

    from thinfilm_mi.cli import design as design_cli
    from thinfilm_mi.cli import fit as fit_cli

    design_cli.add_parser(sub)
    fit_cli.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as e:
        prog = RENDER_PROG if argv[:1] == ["render"] else PROG
        return report_error(prog, e, "--verbose" in argv)
    except SystemExit as e:  # --help
        return int(e.code or 0)
    return run_command(args.func, args)


if __name__ == "__main__":
    sys.exit(main())
