r"""The parameter rows that the film-stack plugins' doc blocks share, written once.

Every BSDF that reads a stack through :func:`thinfilm_mi.render.props.stack_from_props`
reads the same five properties (:data:`SHARED_NAMES`): ``thickness``, ``tabulate``,
``table_error``, ``spectral_resolution`` and ``coherence_thickness``. Their rows of a doc
block's ``.. pluginparameters::`` table are written here, and
``scripts/compose_docblocks.py`` writes them into each plugin's doc block, so that the doc
block in the source still reads alone (Mitsuba's doc generator reads module docstrings
as they are) while the text exists once. ``tests/cross/test_docblocks.py`` fails when a doc
block's rows differ from :func:`shared_rows`.

Two rows say what differs between the plugin families (:data:`FAMILIES`), which each doc
block names in a comment before its table, ``.. shared-rows: FAMILY`` (a comment renders
to nothing): when ``tabulate="auto"`` builds a table, and what a ``thickness`` texture
does to the tables. The module imports nothing of the package, so that the script can
read it by its path while the package is mid-edit.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FAMILIES", "SHARED_NAMES", "Family", "shared_rows"]

#: the properties whose rows are shared, in the order of the tables
SHARED_NAMES = ("thickness", "tabulate", "table_error", "spectral_resolution", "coherence_thickness")


@dataclass(frozen=True)
class Family:
    """What the shared rows of one plugin family say differently."""

    #: when ``tabulate="auto"`` builds a table (the words after "``auto`` tabulates")
    auto: str
    #: what a ``thickness`` texture does to the tables
    thickness: str


_SPECULAR_THICKNESS = ("In spectral variants the stack is then evaluated exactly (no table); RGB and "
                       "mono variants tabulate the colour over its range, read at load.")

#: family name -> :class:`Family`; a doc block names its family in ``.. shared-rows: NAME``
FAMILIES = {
    "conductor": Family(
        auto="every stack with films in vectorised variants,",
        thickness=_SPECULAR_THICKNESS),
    "dielectric": Family(
        auto="in vectorised variants by measured cost: absorbing films from 4 films, "
             "non-absorbing ones between constant indices from 4 (both sides are then one "
             "exact recursion at the Snell-mapped angle), other non-absorbing ones from 1,",
        thickness=_SPECULAR_THICKNESS),
    "diffuse": Family(
        auto="in vectorised variants by measured cost (``R`` alone of films that do not absorb "
             "from 1 film, ``R`` and ``T`` from 5),",
        thickness="``R_dh``, ``T_hemi`` (RGB/mono: the integrated diffuse term) are tabulated "
                  "over its range, read at load."),
}

#: the rows, each ``(name, type, description)``; ``{auto}`` and ``{thickness}`` are the family's
_ROWS = (
    ("thickness", "|float| or |texture|",
     "Optional scale on every film's thickness at the hit, e.g. a ``bitmap`` with ``raw=\"true\"`` "
     "(clamped to >= 0; default: 1). {thickness}"),
    ("tabulate", "|string| or |bool|",
     "``auto`` (default), ``true`` or ``false``. With a table the stack's ``R`` (and ``T`` where "
     "needed) is read from a verified table over (angle, wavelength) instead of the recursion (a "
     "cubic B-spline, split at the critical angle where the exit medium can totally reflect; in "
     "spectral variants resampled finer and read bilinearly where that takes at most 8 MiB): its "
     "cost does not grow with the number of films. ``auto`` tabulates {auto} unless a "
     "``thickness`` texture is given, gradients are tracked, or the target cannot be met within "
     "2^19 texels (a table that still fits the cache), by a table of the exact values or one of "
     "the band-limited values (``spectral_resolution``) (then: exact), or in a build of ~2 s (70 "
     "films or more on a metal: not started); ``true`` waits up to 10x longer (100 films: ~2.5 s). "
     "Built tables are kept on disk (the table store). In ``*_spectral_polarized`` variants a "
     "table holds each lobe's Mueller components (``R``, ``(R_s - R_p)/2``, ``r_s conj(r_p)``; "
     "``T`` likewise), each within ``table_error``, and ``auto`` tabulates from 40 films (fewer "
     "are as cheap exact) within 2^21 floats."),
    ("table_error", "|float|",
     "Target max abs error of a table in ``R`` and ``T`` (default: 0.001)."),
    ("spectral_resolution", "|float|",
     "Spectral resolution (nm) tables may assume, for stacks whose exact values no table resolves "
     "(10 films or more on a metal: cavity resonances ~0.1 nm wide): their ``R`` and ``T`` are "
     "tabulated convolved with a Gaussian in wavenumber whose standard deviation is this at 560 nm "
     "(0.41x at 360 nm, 2.2x at 830 nm), i.e. light of coherence length ``1/(2π σ_ν)``, ~50 µm at "
     "1 nm. Such a table is verified within ``table_error`` against the convolved values and kept "
     "only if the colours of the exact and the convolved values under D65, A and F11 differ by "
     "ΔE2000 <= 0.5 (default: 1; 0: tables of the exact values only). Under lasers or "
     "line-spectrum emitters narrower than the resolution pass 0, or ``tabulate=false``."),
    ("coherence_thickness", "|float|",
     "Films thicker than this (nm) are averaged incoherently, as tmm's ``inc_tmm`` does, instead "
     "of showing ~1 nm fringes no broadband light shows (default: 5000)."),
)

#: the width the descriptions are wrapped to (the doc blocks' own)
_WIDTH = 88


def _wrap(text: str, indent: str) -> list[str]:
    """``text`` as lines of at most :data:`_WIDTH` characters after ``indent`` (words kept whole)."""
    lines, line = [], ""
    for word in text.split(" "):
        if line and len(indent) + len(line) + 1 + len(word) > _WIDTH:
            lines.append(indent + line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    return lines + [indent + line]


def shared_rows(family: str) -> dict[str, str]:
    """name -> the row of a ``.. pluginparameters::`` table (lines joined by newlines, in the
    doc blocks' layout: ``" * - NAME"``, ``"   - TYPE"``, ``"   - DESCRIPTION"`` wrapped)."""
    if family not in FAMILIES:
        raise ValueError(f"shared_rows: family={family!r} is not one of {sorted(FAMILIES)}")
    words = {"auto": FAMILIES[family].auto, "thickness": FAMILIES[family].thickness}
    rows = {}
    for name, kind, description in _ROWS:
        text = _wrap(description.format(**words), "     ")
        text[0] = "   - " + text[0][5:]
        rows[name] = "\n".join([f" * - {name}", f"   - {kind}", *text])
    return rows
