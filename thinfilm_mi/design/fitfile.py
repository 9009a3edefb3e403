"""The measurements file of a fit: the nominal stack, the measured spectra, what is free.

A YAML file (or the same structure as a dict)::

    ambient: 1.0
    substrate: BK7                  # anything `layers`/`substrate` accept
    substrate_thickness_mm: 1.0     # optional: a thick substrate whose back side counts (incoherently)
    layers: "H 60; SiO2 95; H 60"   # the nominal stack, films from the ambient side
    materials:                      # optional dispersion models of materials named in `layers`
      H: {model: cauchy, A: 2.2, B: 0.02, free: [A, B]}
    thickness: each                 # each (default) | scale (one common factor) | fixed
    bounds: {"d[0]": [40, 80], "H.A": [2.0, 2.5]}    # optional, by parameter name
    instrument: {bandwidth_nm: 2.0, cone_half_angle: 3.0}   # optional; default 0 and 0
    starts: 8                       # starts of the fit (default 8), the first the nominal stack
    spread: 0.1                     # random starts: every parameter off by up to ±10 % (default;
                                    # the global stage picks the next starts, random ones fill the rest)
    seed: 0
    data:
      - {file: r0.csv, quantity: R, angle: 0}
      - {file: r45s.csv, quantity: R, angle: 45, polarization: s, scale: free}
      - {file: t0.csv, quantity: T, angle: 0, sigma: 0.002}

Data files are CSV (``#`` comments): columns ``wavelength`` (nm), ``value`` (a
fraction 0-1) and optionally ``sigma`` (its standard uncertainty, > 0) and
``angle`` (degrees; then one file holds several angles). A first row of names
gives the columns in any order; without one they are wavelength, value[, sigma].
Rows may come in any order; a wavelength given twice (at one angle) with two values
is refused with its line and the line of its first occurrence.
A dataset's ``sigma`` key gives one σ for all its points. Either every dataset
carries σ or none does (the fit then scales its uncertainties by χ²/dof).

The free parameters, by name: ``d[j]`` each film's thickness (nm;
``thickness: each``) or ``thickness_scale`` (``thickness: scale``);
``MATERIAL.PARAM`` each parameter a ``materials`` entry lists in ``free``
(models: :mod:`.dispersion`); ``data[i].scale`` a dataset's scale factor
(``scale: free``, or ``scale: {value: 1.0, free: true}``). ``bounds`` may bound any
of them. Every error raises :class:`~thinfilm_mi.errors.ThinFilmError` naming
the file and the entry (``data[1] (t0.csv): sigma must be > 0, got 0 (line 7)``).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from thinfilm_mi.design.dispersion import DispersionModel, model_class
from thinfilm_mi.design.parsing import fail, parse_choice, parse_number
from thinfilm_mi.design.targets import check_keys, locate_file, read_yaml, resolve_material
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials import MIN_INDEX, Material
from thinfilm_mi.materials.stack import AMBIENT_K_TOL, parse_layers
from thinfilm_mi.optics.polarization import ALIASES, POLARIZATIONS, Polarization

__all__ = ["Dataset", "FitMaterial", "Parameter", "Measurement", "load_measurements", "QUANTITIES",
           "THICKNESS_MODES", "ParameterKind", "THICKNESS", "DISPERSION", "DATA_SCALE"]

#: What a dataset measures: the power reflected or transmitted.
QUANTITIES = ("R", "T")


class ThicknessMode:
    """How the films' thicknesses are free (``thickness:`` in the file)."""

    name = ""

    def parameters(self, nominal: np.ndarray) -> list["Parameter"]:
        """The free parameters of films of ``nominal`` thicknesses (nm)."""
        return []

    def thicknesses(self, values: np.ndarray, nominal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(d (L,), dd/dvalues (L, len(values)))`` from the parameters' ``values``."""
        return nominal.copy(), np.zeros((nominal.size, 0))


class EachThickness(ThicknessMode):
    """Every film's thickness is a parameter ``d[j]`` (nm)."""

    name = "each"

    def parameters(self, nominal):
        return [Parameter(f"d[{j}]", float(d), 0.0, math.inf, THICKNESS, j) for j, d in enumerate(nominal)]

    def thicknesses(self, values, nominal):
        return np.asarray(values, dtype=np.float64).copy(), np.eye(nominal.size)


class ScaleThickness(ThicknessMode):
    """One common factor ``thickness_scale`` of the nominal thicknesses."""

    name = "scale"

    def parameters(self, nominal):
        return [Parameter("thickness_scale", 1.0, 0.0, math.inf, THICKNESS)]

    def thicknesses(self, values, nominal):
        return values[0] * nominal, nominal[:, None].copy()


class FixedThickness(ThicknessMode):
    """The nominal thicknesses, not fitted."""

    name = "fixed"


#: The thickness modes by name: each film's own thickness, one common factor, or none.
THICKNESS_MODES: dict[str, ThicknessMode] = {m.name: m() for m in (EachThickness, ScaleThickness, FixedThickness)}

_TOP_KEYS = ("ambient", "substrate", "substrate_thickness_mm", "layers", "materials", "thickness", "bounds",
             "instrument", "starts", "spread", "seed", "data")
_DATA_KEYS = ("file", "quantity", "angle", "polarization", "sigma", "scale")
_COLUMNS = ("wavelength", "value", "sigma", "angle")


@dataclass
class Dataset:
    """One measured spectrum: ``wavelengths`` (nm), ``angles`` (degrees, one per
    point), ``value`` and ``sigma`` (``None``: not given) per point."""

    index: int
    file: str
    quantity: str
    polarization: Polarization
    wavelengths: np.ndarray
    angles: np.ndarray
    value: np.ndarray
    sigma: np.ndarray | None
    scale: float = 1.0

    @property
    def name(self) -> str:
        return f"data[{self.index}] ({Path(self.file).name})"

    def describe(self) -> str:
        a = np.unique(self.angles)
        angle = f"{a[0]:g}°" if a.size == 1 else f"{a.size} angles {a[0]:g}-{a[-1]:g}°"
        pol = self.polarization.describe()
        return f"{self.quantity} at {angle}{pol and ', ' + pol}, " \
               f"{self.wavelengths.min():g}-{self.wavelengths.max():g} nm ({self.value.size} points)"


@dataclass
class FitMaterial:
    """A film material: fixed (``material``) or given by a dispersion ``model``."""

    name: str
    material: Material | None = None
    model: DispersionModel | None = None

    def range(self) -> tuple[float, float]:
        return self.material.wavelength_range if self.model is None else self.model.wavelength_range


@dataclass(frozen=True)
class ParameterKind:
    """What a free parameter sets: :data:`THICKNESS` (of the file's
    :class:`ThicknessMode`), :data:`DISPERSION` (``target`` (material name,
    parameter)) or :data:`DATA_SCALE` (``target`` the dataset); the model
    (:class:`~thinfilm_mi.design.fitmodel.FitModel`) groups the columns by it."""

    name: str


THICKNESS, DISPERSION, DATA_SCALE = ParameterKind("thickness"), ParameterKind("dispersion"), ParameterKind("data_scale")


@dataclass
class Parameter:
    """A free parameter: ``name``, start ``value``, bounds, and what it sets,
    ``kind`` (a :class:`ParameterKind`) and its ``target``."""

    name: str
    value: float
    lower: float
    upper: float
    kind: ParameterKind
    target: Any = None
    relative: bool = True         # multi-start spread relative to the value (else of the bounds' width)


@dataclass
class Measurement:
    """A parsed measurements file (see the module docstring)."""

    ambient: Material
    substrate: Material
    films: list[tuple[str, float]]                  # (material name, nominal nm)
    materials: dict[str, FitMaterial]
    datasets: list[Dataset]
    parameters: list[Parameter]
    thickness: ThicknessMode = field(default_factory=EachThickness)
    substrate_thickness_mm: float | None = None
    bandwidth_nm: float = 0.0
    cone_half_angle: float = 0.0
    starts: int = 8
    spread: float = 0.1
    seed: int = 0
    source: str = "measurements"
    ambient_spec: str = "1.0"
    substrate_spec: str = ""
    base: Path | None = None
    sigma_given: bool = False


def _read_csv(path: Path, where: str) -> dict[str, np.ndarray]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as e:
        fail(where, f"cannot read {path} ({e.strerror or e})")
    rows = [(n, r) for n, r in enumerate(csv.reader(text.splitlines()), 1)
            if r and "".join(r).strip() and not r[0].lstrip().startswith("#")]
    if not rows:
        fail(where, "no data rows")
    header = [c.strip().lower() for c in rows[0][1]]
    try:
        [float(c) for c in header]
        names = list(_COLUMNS[:len(header)]) if len(header) <= 3 else None
        if names is None:
            fail(where, f"{len(header)} columns and no header row naming them ({', '.join(_COLUMNS)})")
    except ValueError:
        names = [{"wavelength_nm": "wavelength", "wl": "wavelength", "lambda": "wavelength", "wavelength (nm)":
                  "wavelength"}.get(c, c) for c in header]
        rows = rows[1:]
        unknown = [c for c in names if c not in _COLUMNS]
        if unknown:
            fail(where, f"unknown column {unknown[0]!r}; expected {', '.join(_COLUMNS)}")
    for col in ("wavelength", "value"):
        if col not in names:
            fail(where, f"missing column {col!r} (columns: {', '.join(names)})")
    if not rows:
        fail(where, "no data rows")
    out = {c: np.empty(len(rows)) for c in names}
    for i, (line, row) in enumerate(rows):
        if len(row) != len(names):
            fail(where, f"line {line}: {len(row)} columns, expected {len(names)} ({', '.join(names)})")
        for c, cell in zip(names, row):
            try:
                x = float(cell)
            except ValueError:
                fail(where, f"line {line}: {c} {cell.strip()!r} is not a number")
            if not math.isfinite(x):
                fail(where, f"line {line}: {c} must be finite, got {cell.strip()!r}")
            out[c][i] = x
    line_of = [line for line, _ in rows]
    for c, ok, need in (("wavelength", lambda v: v > 0, "> 0 nm"), ("sigma", lambda v: v > 0, "> 0"),
                        ("angle", lambda v: (v >= 0) & (v < 90), "in [0, 90) degrees")):
        if c in out and not np.all(ok(out[c])):
            i = int(np.argmin(ok(out[c])))
            fail(where, f"{c} must be {need}, got {out[c][i]:g} (line {line_of[i]})")
    _check_repeats(out, line_of, where, path)
    return out


def _check_repeats(cols: dict[str, np.ndarray], line_of: list[int], where: str, path: Path) -> None:
    """Refuse a wavelength given twice (at one angle) with two values or sigmas, as
    material files are refused: the fit could match only one of them. Rows may run in
    any order (decreasing as spectrometers write them, angle by angle)."""
    angles = cols.get("angle", np.zeros_like(cols["wavelength"]))
    measured = [cols[c] for c in ("value", "sigma") if c in cols]
    first: dict[tuple[float, float], int] = {}
    for i, point in enumerate(zip(cols["wavelength"].tolist(), angles.tolist())):
        j = first.setdefault(point, i)
        if j != i and any(m[i] != m[j] for m in measured):
            at = f" at {point[1]:g}°" if "angle" in cols else ""
            fail(where, f"line {line_of[i]} of {path} repeats the wavelength {point[0]:g} nm{at} with another "
                        f"value (first on line {line_of[j]}); give one value per wavelength")


def _dataset(entry: Any, i: int, base: Path | None) -> tuple[Dataset, bool]:
    where = f"data[{i}]"
    if not isinstance(entry, dict) or "file" not in entry:
        fail(where, f"expected a mapping such as {{file: r0.csv, quantity: R, angle: 0}}, got {entry!r}")
    where = f"data[{i}] ({Path(str(entry['file'])).name})"
    unknown = [k for k in entry if k not in _DATA_KEYS]
    if unknown:
        fail(where, f"unknown key {unknown[0]!r}; expected {', '.join(_DATA_KEYS)}")
    if "quantity" not in entry:
        fail(where, f"missing 'quantity' ({' or '.join(QUANTITIES)})")
    quantity = parse_choice(entry["quantity"], QUANTITIES, where, "quantity")
    polarization = parse_choice(entry.get("polarization", "unpolarized"), POLARIZATIONS, where,
                                "polarization", ALIASES)
    path = Path(str(entry["file"]))
    if not path.is_absolute() and base is not None:
        path = base / path
    cols = _read_csv(path, where)
    if "angle" in cols:
        if "angle" in entry:
            fail(where, "the angle is given twice: by the file's angle column and by the 'angle' key")
        angles = cols["angle"]
    else:
        a = parse_number(entry.get("angle", 0.0), where, "angle")
        if not 0 <= a < 90:
            fail(where, f"angle must be in [0, 90) degrees, got {a:g}")
        angles = np.full(cols["value"].shape, a)
    sigma = cols.get("sigma")
    if "sigma" in entry:
        if sigma is not None:
            fail(where, "sigma is given twice: by the file's sigma column and by the 'sigma' key")
        s = parse_number(entry["sigma"], where, "sigma")
        if s <= 0:
            fail(where, f"sigma must be > 0, got {s:g}")
        sigma = np.full(cols["value"].shape, s)
    scale, scale_free = 1.0, False
    raw = entry.get("scale", 1.0)
    if isinstance(raw, dict):
        bad = [k for k in raw if k not in ("value", "free")]
        if bad:
            fail(where, f"scale: unknown key {bad[0]!r}; expected value, free")
        scale = parse_number(raw.get("value", 1.0), where, "scale value")
        scale_free = bool(raw.get("free", False))
    elif isinstance(raw, str) and raw.strip().lower() == "free":
        scale_free = True
    else:
        scale = parse_number(raw, where, "scale")
    if scale <= 0:
        fail(where, f"scale must be > 0, got {scale:g}")
    ds = Dataset(i, str(path), quantity, polarization, cols["wavelength"], angles, cols["value"], sigma, scale)
    return ds, scale_free


def _material(name: str, entry: Any, base: Path | None) -> tuple[FitMaterial, list[str]]:
    where = f"materials.{name}"
    if not isinstance(entry, dict) or "model" not in entry:
        fail(where, f"expected a mapping such as {{model: cauchy, A: 1.46, B: 0.004, free: [A, B]}}, got {entry!r}")
    cls = model_class(entry["model"], where)
    free = entry.get("free", [])
    free = [free] if isinstance(free, str) else free
    if not isinstance(free, (list, tuple)):
        fail(where, f"free: expected a list of parameter names of model {cls.name}, got {free!r}")
    rest = {k: v for k, v in entry.items() if k not in ("model", "free")}
    model = cls(rest, where, lambda spec, w: resolve_material(spec, w, base))
    for p in free:
        if p not in cls.parameters:
            fail(where, f"free: unknown parameter {p!r} of model {cls.name}; expected {', '.join(cls.parameters)}")
    return FitMaterial(name, model=model), [str(p) for p in free]


def _bounds(parameters: list[Parameter], given: Any):
    if given is None:
        return
    if not isinstance(given, dict):
        fail("bounds", f"expected a mapping from parameter names to [LO, HI], got {given!r}")
    by_name = {p.name: p for p in parameters}
    for name, pair in given.items():
        p = by_name.get(str(name))
        if p is None:
            fail(f"bounds.{name}", "not a free parameter; free parameters: " + (", ".join(by_name) or "none"))
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            fail(f"bounds.{name}", f"expected [LO, HI], got {pair!r}")
        lo, hi = (parse_number(v, f"bounds.{name}", "bound") if v is not None else d
                  for v, d in zip(pair, (-math.inf, math.inf)))
        if not lo < hi:
            fail(f"bounds.{name}", f"need LO < HI, got [{lo:g}, {hi:g}]")
        if not lo <= p.value <= hi:
            fail(f"bounds.{name}", f"the start value {p.value:g} is outside [{lo:g}, {hi:g}]")
        p.lower, p.upper, p.relative = lo, hi, not (math.isfinite(lo) and math.isfinite(hi))


def _integer(doc: dict, key: str, default: int, low: int) -> int:
    v = doc.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int) or v < low:
        fail(key, f"expected an integer >= {low}, got {v!r}")
    return v


def _instrument(doc: Any) -> tuple[float, float]:
    if doc is None:
        return 0.0, 0.0
    if not isinstance(doc, dict):
        fail("instrument", f"expected a mapping {{bandwidth_nm: FWHM, cone_half_angle: DEGREES}}, got {doc!r}")
    bad = [k for k in doc if k not in ("bandwidth_nm", "cone_half_angle")]
    if bad:
        fail("instrument", f"unknown key {bad[0]!r}; expected bandwidth_nm, cone_half_angle")
    bw = parse_number(doc.get("bandwidth_nm", 0.0), "instrument", "bandwidth_nm")
    cone = parse_number(doc.get("cone_half_angle", 0.0), "instrument", "cone_half_angle")
    if bw < 0:
        fail("instrument", f"bandwidth_nm must be >= 0 (a Gaussian's FWHM), got {bw:g}")
    if not 0 <= cone < 30:
        fail("instrument", f"cone_half_angle must be in [0, 30) degrees, got {cone:g}")
    return bw, cone


def _measurement(doc: Any, base: Path | None, name: str) -> Measurement:
    check_keys(doc, _TOP_KEYS, ("substrate", "layers", "data"), "measurements file")
    ambient_spec = doc.get("ambient", 1.0)
    ambient = resolve_material(ambient_spec, "ambient", base)
    if ambient.constant is None or ambient.constant.imag > AMBIENT_K_TOL:
        fail("ambient", f"expected a constant index that does not absorb, got {ambient_spec!r}")
    substrate = resolve_material(doc["substrate"], "substrate", base)
    thick = doc.get("substrate_thickness_mm")
    if thick is not None:
        thick = parse_number(thick, "substrate_thickness_mm", "thickness")
        if thick <= 0:
            fail("substrate_thickness_mm", f"must be > 0, got {thick:g}")
    raw = doc.get("materials") or {}
    if not isinstance(raw, dict):
        fail("materials", f"expected a mapping from material names to models, got {raw!r}")
    materials, free_of = {}, {}
    for key, entry in raw.items():
        materials[str(key)], free_of[str(key)] = _material(str(key), entry, base)
    films = []
    for j, (spec, d) in enumerate(parse_layers(str(doc["layers"]), "layers")):
        spec = str(spec)
        if spec not in materials:
            materials[spec] = FitMaterial(str(locate_file(spec, base)).strip(),
                                          material=resolve_material(spec, f"layers[{j}] material", base))
        films.append((spec, d))
    unused = [k for k in raw if str(k) not in {f for f, _ in films}]
    if unused:
        fail(f"materials.{unused[0]}", "appears in no film of layers, so in no data")
    mode = THICKNESS_MODES[parse_choice(doc.get("thickness", "each"), tuple(THICKNESS_MODES), "thickness",
                                        "thickness")]
    data = doc["data"]
    if not isinstance(data, (list, tuple)) or not data:
        fail("data", "expected a list of data sets ({file: r0.csv, quantity: R, angle: 0})")
    parsed = [_dataset(e, i, base) for i, e in enumerate(data)]
    datasets = [d for d, _ in parsed]
    given = [d.sigma is not None for d in datasets]
    if any(given) and not all(given):
        fail(datasets[given.index(not given[0])].name,
             "either every data set carries sigma (a column or the 'sigma' key) or none does")
    params = mode.parameters(np.array([d for _, d in films], dtype=np.float64))
    for key, names in free_of.items():
        model = materials[key].model
        params += [Parameter(f"{key}.{p}", model.values[p], model.lower.get(p, -math.inf), math.inf,
                             DISPERSION, (key, p)) for p in names]
    params += [Parameter(f"data[{d.index}].scale", d.scale, 0.0, math.inf, DATA_SCALE, d.index)
               for d, free in parsed if free]
    _bounds(params, doc.get("bounds"))
    bw, cone = _instrument(doc.get("instrument"))
    spread = parse_number(doc.get("spread", 0.1), "spread", "spread")
    if not 0 <= spread < 1:
        fail("spread", f"expected a fraction in [0, 1), got {spread:g}")
    m = Measurement(ambient, substrate, films, materials, datasets, params, mode, thick, bw, cone,
                    _integer(doc, "starts", 8, 1), spread, _integer(doc, "seed", 0, 0), name,
                    str(locate_file(ambient_spec, base)).strip(), str(locate_file(doc["substrate"], base)).strip(),
                    base, all(given))
    if not params:
        fail("measurements file", "no free parameter (thickness: fixed and no free dispersion or scale)")
    _check_reach(m)
    return m


#: A Gaussian bandwidth is sampled out to this many standard deviations (:mod:`.fitmodel`).
BANDWIDTH_REACH = 3.0


def _check_reach(m: Measurement):
    """Every material must have data at every wavelength a data set needs (its
    points widened by the bandwidth's reach)."""
    pad = BANDWIDTH_REACH * m.bandwidth_nm / (2.0 * math.sqrt(2.0 * math.log(2.0)))
    media = [("ambient", m.ambient.wavelength_range), ("substrate", m.substrate.wavelength_range)]
    media += [(f"material {k!r}", f.range()) for k, f in m.materials.items()]
    for d in m.datasets:
        lo, hi = float(d.wavelengths.min()) - pad, float(d.wavelengths.max()) + pad
        for what, (a, b) in media:
            if lo < a * (1 - 1e-9) or hi > b * (1 + 1e-9):
                bad = lo if lo < a * (1 - 1e-9) else hi
                fail(d.name, f"wavelength {bad:g} nm is out of reach: {what} has data for {a:g}-{b:g} nm only")
        for key, f in m.materials.items():
            if f.model is None:
                continue
            wl = np.linspace(max(lo, 1.0), hi, 64)
            n = f.model.index(wl)
            ok = np.isfinite(n) & (n.real >= MIN_INDEX) & (n.imag >= 0)
            if not np.all(ok):
                bad = int(np.argmin(ok))
                fail(f"materials.{key}", f"its {f.model.name} parameters {f.model.values} give n = "
                                         f"{complex(n[bad]):.4g} at {wl[bad]:g} nm, where {d.name} needs an index")


def load_measurements(source: Any) -> Measurement:
    """A :class:`Measurement` from a file path, a YAML string or a dict (data
    files are found relative to the measurements file)."""
    doc, base, name = read_yaml(source, "measurements")
    try:
        return _measurement(doc, base, name)
    except ThinFilmError as e:
        raise ThinFilmError(f"{name}: {e}") from None
