r"""The parameter rows that the film-stack plugins' doc blocks share, written once.

Every BSDF that reads a stack through
:meth:`thinfilm_mi.render.reader.PluginProperties.stack_options` reads the same five
properties (:data:`SHARED_NAMES`): ``thickness``, ``tabulate``, ``table_error``,
``spectral_resolution`` and ``coherence_thickness``. Their rows of a doc
block's ``.. pluginparameters::`` table are written here, and
``scripts/compose_docblocks.py`` writes them into each plugin's doc block, so that the doc
block in the source still reads alone (Mitsuba's doc generator reads module docstrings
as they are) while the text exists once. ``tests/cross/test_docblocks.py`` fails when a doc
block's rows differ from :func:`shared_rows`.

Two rows say what differs between the plugin families (:data:`FAMILIES`), which each doc
block names in a comment before its table, ``.. shared-rows: FAMILY`` (a comment renders
to nothing): when ``tabulate="auto"`` builds a table, and what a ``thickness`` texture
does to the tables. A number of the ``tabulate`` policy is written as a placeholder,
``{policy.NAME}``, filled from :mod:`thinfilm_mi.tabulate.policy`
(``tests/cross/test_docblocks.py`` fails on a literal); the policy itself is explained in
the tables guide, which the rows link to.
"""
from __future__ import annotations

from dataclasses import dataclass

from thinfilm_mi.tabulate.policy import fill

__all__ = ["FAMILIES", "SHARED_NAMES", "Family", "shared_rows", "templates"]

#: the properties whose rows are shared, in the order of the tables
SHARED_NAMES = ("thickness", "tabulate", "table_error", "spectral_resolution", "coherence_thickness")


@dataclass(frozen=True)
class Family:
    """What the shared rows of one plugin family say differently."""

    #: what ``tabulate="auto"`` tabulates (the words after "``auto`` tabulates")
    auto: str
    #: what a ``thickness`` texture does to the tables
    thickness: str


_SPECULAR_THICKNESS = ("In spectral variants the stack is then evaluated exactly (no table); RGB and "
                       "mono variants tabulate the colour over its range, read at load.")

#: family name -> :class:`Family`; a doc block names its family in ``.. shared-rows: NAME``
FAMILIES = {
    "conductor": Family(
        auto="every stack with films",
        thickness=_SPECULAR_THICKNESS),
    "dielectric": Family(
        auto="stacks of absorbing films from {policy.RT_AUTO_MIN_FILMS} films, of other films from "
             "{policy.AUTO_MIN_FILMS} ({policy.MIRROR_AUTO_MIN_FILMS} between media of constant index)",
        thickness=_SPECULAR_THICKNESS),
    "diffuse": Family(
        auto="a coating from {policy.COATING_RT_MIN_FILMS} films (films that do not absorb, "
             "whose table holds ``R`` alone, from {policy.AUTO_MIN_FILMS})",
        thickness="``R_dh``, ``T_hemi`` (RGB/mono: the integrated diffuse term) are tabulated "
                  "over its range, read at load."),
}

#: where the policy and its numbers are explained (a label of ``docs/guides/tables.md``)
_GUIDE = ":ref:`the tables guide <tabulate-policy>`"

#: the rows, each ``(name, type, description)``; ``{auto}`` and ``{thickness}`` are the
#: family's, ``{policy.NAME}`` a constant of :mod:`thinfilm_mi.tabulate.policy`
_ROWS = (
    ("thickness", "|float| or |texture|",
     "Optional scale on every film's thickness at the hit, e.g. a ``bitmap`` with ``raw=\"true\"`` "
     "(clamped to >= 0; default: 1). {thickness}"),
    ("tabulate", "|string| or |bool|",
     "``auto`` (default), ``true`` or ``false``: whether ``R`` (and ``T``) is read from a verified "
     "table over (angle, wavelength), whose cost does not grow with the films, instead of the "
     "recursion. ``auto`` tabulates {auto} in vectorised variants, without a ``thickness`` texture "
     "or gradients, where a table within budget meets ``table_error``; ``true`` tabulates every "
     "stack it can, with {policy.REQUESTED_BUDGET_SCALE}x the build budget. When and why: " + _GUIDE + "."),
    ("table_error", "|float|",
     "Target max abs error of a table in ``R`` and ``T`` (default: 0.001)."),
    ("spectral_resolution", "|float|",
     "Spectral resolution (nm) tables may assume where no table resolves the exact values (deep "
     "stacks on a metal): ``R`` and ``T`` are then tabulated convolved with a Gaussian in "
     "wavenumber of this standard deviation at 560 nm, if that keeps the colour (default: 1; 0: "
     "exact values only). Under lasers or line spectra narrower than this pass 0; see " + _GUIDE + "."),
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
    words = {"auto": fill(FAMILIES[family].auto), "thickness": fill(FAMILIES[family].thickness)}
    rows = {}
    for name, kind, description in _ROWS:
        text = _wrap(fill(description).format(**words), "     ")
        text[0] = "   - " + text[0][5:]
        rows[name] = "\n".join([f" * - {name}", f"   - {kind}", *text])
    return rows


def templates() -> list[str]:
    """Every text the rows are composed from, placeholders unfilled (the rows' descriptions and
    the families' words): where a number of the policy must be a ``{policy.NAME}``."""
    words = [text for family in FAMILIES.values() for text in (family.auto, family.thickness)]
    return [description for _, _, description in _ROWS] + words
