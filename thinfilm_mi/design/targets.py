"""The targets file of a coating design: what the coating must do, and from what.

A YAML file (or the same structure as a dict)::

    ambient: 1.0                  # the medium the light comes from (default 1.0)
    substrate: "1.52"             # anything `layers`/`substrate` accept: number, n+kj, name, file
    materials: ["1.38", "2.35"]   # film materials, first = outermost of a seed stack
    max_layers: 8                 # at most this many films (default 8)
    start: "1.38 100; 2.35 20"    # optional starting stack; otherwise synthesised
    seeds: 6                      # starting designs tried when there is no start (default 6)
    seed: 0                       # random seed of those starts (default 0)
    targets:
      - {quantity: R, wavelengths: "420:680:5", angles: [0], value: 0.0, tolerance: 0.005}
      - {quantity: T, wavelengths: "550", angles: [0, 30], value: 0.9, tolerance: 0.01, kind: ">="}
      - {quantity: colour, illuminant: D65, angles: [0, 45], Lab: [60, 10, -40], tolerance: 2.0}
      - {quantity: Y, illuminant: D65, angles: [0], value: 0.95, tolerance: 0.01, kind: ">="}

Materials are resolved with :func:`thinfilm_mi.materials.catalog.resolve` (a file path
relative to the targets file is found beside it). A material may be a mapping
``{index: 2.1, free: [1.9, 2.3]}``: its real part ``n`` is then a design variable
within the bounds (``free: true``: within ±10 % of the given ``n``), shared by
every film of that material. Seed stacks alternate the materials in the order
given; a needle may be any of them.

Target keys:

``quantity``
    ``R``, ``T``, ``A`` (absorptance ``1 - R - T``) at each wavelength and angle;
    ``Y``, the luminous (CIE Y) reflectance or transmittance (``of``) under
    ``illuminant``; ``colour`` (or ``color``), its L*a*b* (``Lab: [L, a, b]``,
    residual CIEDE2000) or chromaticity (``xy: [x, y]``, residual the distance in xy).
``wavelengths``
    R, T and A only: ``"START:STOP:STEP"`` (nm, STOP included when on the grid),
    one number or a list.
``angles``
    Degrees in the incidence medium, each in [0, 90): a list, one number or
    ``"START:STOP:STEP"`` (default ``[0]``).
``value``
    The wanted value (a fraction 0-1): one number or, for R/T/A, a list with one
    per wavelength.
``tolerance``
    > 0, the same form as ``value`` (for colour targets: ΔE2000, or the xy distance).
    Each residual is ``(achieved - value) / tolerance``.
``kind``
    ``=`` (default), ``<=`` (only values above ``value`` count) or ``>=``; colour
    targets are ``=`` only.
``polarization``
    ``unpolarized`` (default), ``s`` or ``p``.
``side``
    ``front`` (default; light from the ambient) or ``back`` (light from the
    substrate, which must then not absorb).
``illuminant``, ``observer``, ``of``
    Y and colour only: ``D65`` (default), ``A``, ``F11`` or ``blackbody:T``;
    ``2`` (default) or ``10``; ``R`` (default) or ``T``.

Every error raises :class:`~thinfilm_mi.errors.ThinFilmError` naming the file and
the entry (``targets[2] (colour): ...``).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from thinfilm_mi import materials as _materials
from thinfilm_mi.design.options import KIND_ALIASES, KINDS, SIDES
from thinfilm_mi.design.parsing import fail, parse_choice, parse_grid, parse_number
from thinfilm_mi.design.target_quantities import (
    TARGET_QUANTITIES,
    TARGET_QUANTITY_ALIASES,
    Target,
)
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.sources import is_material_file
from thinfilm_mi.materials.stack import AMBIENT_K_TOL, MAX_FILMS, parse_layers
from thinfilm_mi.optics.choices import choose
from thinfilm_mi.optics.polarization import ALIASES, POLARIZATIONS

__all__ = ["DesignMaterial", "Target", "Problem", "load_problem", "films_from_layers", "check_keys", "locate_file",
           "read_yaml", "resolve_material"]

_TOP_KEYS = ("ambient", "substrate", "materials", "max_layers", "start", "seeds", "seed", "targets")


@dataclass
class DesignMaterial:
    """A film material: its specification as written (used in ``layers``
    strings), the resolved :class:`~thinfilm_mi.materials.catalog.Material`, the
    bounds of its real index when that is a design variable, and whether
    needles may be made of it (not for a material that only ``start`` names)."""

    spec: str
    material: _materials.Material
    free: tuple[float, float] | None = None
    needle: bool = True               # False: a material of the start only, never inserted

    @property
    def n0(self) -> complex:
        """The constant index given (numeric materials only)."""
        return complex(self.material.constant)


@dataclass
class Problem:
    """A parsed targets file: media, film materials, limits, start and targets."""

    ambient: _materials.Material
    substrate: _materials.Material
    materials: list[DesignMaterial]
    targets: list[Target]
    max_layers: int = 8
    start: list[tuple[int, float]] | None = None     # (material index, nm)
    seeds: int = 6
    seed: int = 0
    source: str = "targets"
    ambient_spec: str = "1.0"
    substrate_spec: str = ""
    base: Path | None = None          # the targets file's folder (relative material files)
    start_n: dict | None = None       # free index values the start gives {material index: n}


def locate_file(spec: Any, base: Path | None) -> Any:
    """A material file named relative to the targets file, as a path beside it."""
    if isinstance(spec, str) and base is not None and is_material_file(spec):
        candidate = base / spec.strip()
        if not Path(spec.strip()).is_absolute() and candidate.exists():
            return str(candidate)
    return spec


def resolve_material(spec: Any, where: str, base: Path | None) -> _materials.Material:
    spec = locate_file(spec, base)
    try:
        return _materials.resolve(spec, require_range=None)
    except ValueError as e:
        msg = str(e)
        fail(where, msg[len("material: "):] if msg.startswith("material: ") else msg)


def _material_entry(entry: Any, where: str, base: Path | None) -> DesignMaterial:
    free = None
    if isinstance(entry, dict):
        unknown = set(entry) - {"index", "free"}
        if unknown or "index" not in entry:
            fail(where, f"expected a material or {{index: N, free: [LO, HI]}}, got {entry!r}")
        spec, free_spec = entry["index"], entry.get("free", False)
    else:
        spec, free_spec = entry, False
    if isinstance(spec, (list, dict)) or spec is None:
        fail(where, f"expected a material (number, n+kj, name or file), got {spec!r}")
    material = resolve_material(spec, where, base)
    text = str(locate_file(spec, base)).strip()
    if any(c.isspace() for c in text) or ";" in text:
        fail(where, f"material {text!r}: a layers string cannot hold spaces or ';' in a material")
    if free_spec not in (False, None):
        if material.constant is None:
            fail(where, f"free: only a numeric index can be free, not the dataset {text!r}")
        n = material.constant.real
        if free_spec is True:
            lo, hi = 0.9 * n, 1.1 * n
        elif isinstance(free_spec, (list, tuple)) and len(free_spec) == 2:
            lo, hi = (parse_number(v, where, "free bounds") for v in free_spec)
        else:
            fail(where, f"free: expected true or [LO, HI], got {free_spec!r}")
        if not (_materials.MIN_INDEX <= lo <= n <= hi <= _materials.MAX_INDEX):
            fail(where, f"free: need {_materials.MIN_INDEX:g} <= LO <= n = {n:g} <= HI, got [{lo:g}, {hi:g}]")
        free = (lo, hi)
    return DesignMaterial(text, material, free)


def _check_reach(target: Target, wavelengths: np.ndarray, media: list[tuple[str, _materials.Material]]):
    """Every material must be defined at every wavelength the target needs."""
    lo, hi = float(wavelengths.min()), float(wavelengths.max())
    if lo <= 0:
        fail(target.name, f"wavelengths must be > 0 nm, got {lo:g}")
    for name, mat in media:
        a, b = mat.wavelength_range
        if lo < a * (1 - 1e-9) or hi > b * (1 + 1e-9):
            bad = lo if lo < a * (1 - 1e-9) else hi
            need = ("" if target.wavelengths is not None
                    else f" (the {target.illuminant} colour integral needs {lo:g}-{hi:g} nm)")
            fail(target.name, f"wavelength {bad:g} nm is out of reach: {name} {mat.name!r} has data "
                               f"for {a:g}-{b:g} nm only{need}")


def _target(entry: Any, i: int, media, back_ok: str | None) -> Target:
    where = f"targets[{i}]"
    if not isinstance(entry, dict):
        fail(where, f"expected a mapping such as {{quantity: R, wavelengths: '420:680:5', value: 0, "
                     f"tolerance: 0.005}}, got {entry!r}")
    if "quantity" not in entry:
        fail(where, f"missing 'quantity' (one of {', '.join(TARGET_QUANTITIES)})")
    try:
        quantity = choose(TARGET_QUANTITIES, entry["quantity"], "quantity", TARGET_QUANTITY_ALIASES)
    except ThinFilmError:
        fail(where, f"unknown quantity {entry['quantity']!r}; expected one of {', '.join(TARGET_QUANTITIES)}")
    where = f"targets[{i}] ({quantity.name})"
    unknown = [k for k in entry if k not in quantity.keys]
    if unknown:
        fail(where, f"unknown key {unknown[0]!r} for quantity {quantity.name}; expected "
                     f"{', '.join(k for k in quantity.keys if k != 'quantity')}")
    for key in quantity.required:
        if key not in entry:
            fail(where, f"missing {key!r}")
    angles = parse_grid(entry.get("angles", [0.0]), where, "angles")
    bad = angles[(angles < 0) | (angles >= 90)]
    if bad.size:
        fail(where, f"angles: each must be in [0, 90) degrees, got {bad[0]:g}")
    t = Target(i, quantity, angles, np.zeros(1))
    t.kind = parse_choice(entry.get("kind", "="), KINDS, where, "kind", KIND_ALIASES)
    t.polarization = parse_choice(entry.get("polarization", "unpolarized"), POLARIZATIONS, where, "polarization",
                                  ALIASES)
    t.side = parse_choice(entry.get("side", "front"), SIDES, where, "side")
    t.side.check(back_ok, lambda message: fail(where, message))
    need = quantity.parse(t, entry, where)
    if np.any(t.tolerance <= 0):
        fail(where, f"tolerance must be > 0, got {float(t.tolerance[t.tolerance <= 0][0]):g}")
    if t.value is not None and np.any((t.value < 0) | (t.value > 1)):
        bad_v = float(t.value[(t.value < 0) | (t.value > 1)][0])
        fail(where, f"value must be a fraction in [0, 1], got {bad_v:g}")
    _check_reach(t, need, media)
    return t


def films_from_layers(materials: list[DesignMaterial], text: Any, base: Path | None = None,
                      name: str = "layers") -> tuple[list[tuple[int, float]], dict[int, float]]:
    """``([(material index, nm), ...], {free material index: n})`` of a ``layers``
    string. Each film's material is matched to ``materials``: the same dataset or
    an equal constant index, or a free material of the same ``k`` whose bounds
    hold its ``n`` (which then becomes the free index's value; all its films must
    agree). A material matching none is appended to ``materials`` (``needle=False``)."""
    out, free = [], {}
    for j, (spec, d) in enumerate(parse_layers(str(text), name)):
        where = f"{name}[{j}] material"
        mat = resolve_material(spec, where, base)
        c = mat.constant
        match = [i for i, m in enumerate(materials) if not m.free and (m.material is mat or (
            c is not None and m.material.constant == c))]
        if not match and c is not None:
            match = [i for i, m in enumerate(materials) if m.free and m.n0.imag == c.imag
                     and m.free[0] <= c.real <= m.free[1]]
            if match:
                if free.setdefault(match[0], c.real) != c.real:
                    fail(where, f"films of the free material {materials[match[0]].spec!r} must share one "
                                 f"index, got {free[match[0]]:g} and {c.real:g}")
        if not match:
            materials.append(DesignMaterial(str(locate_file(spec, base)), mat, needle=False))
            match = [len(materials) - 1]
        out.append((match[0], d))
    return out, free


def read_yaml(source: Any, what: str) -> tuple[Any, Path | None, str]:
    """``(document, folder, name)`` of a YAML file path, a YAML string or a dict:
    ``folder`` is the file's (for files named relative to it, else ``None``) and
    ``name`` what errors call it (the path, else ``what``). An unreadable file or
    bad YAML raises :class:`ThinFilmError` naming it."""
    if isinstance(source, dict):
        return source, None, what
    import yaml

    base, name = None, what
    if isinstance(source, os.PathLike) or (isinstance(source, str) and "\n" not in source
                                           and source.strip().lower().endswith((".yml", ".yaml"))):
        path = Path(source)
        name = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as e:
            raise ThinFilmError(f"{name}: cannot read the {what} file ({e.strerror or e})") from None
        base = path.resolve().parent
    elif isinstance(source, str):
        text = source
    else:
        raise ThinFilmError(f"{what}: expected a file path, a YAML string or a dict, got {source!r}")
    try:
        return yaml.safe_load(text), base, name
    except yaml.YAMLError as e:
        raise ThinFilmError(f"{name}: not valid YAML ({' '.join(str(e).split())})") from None


def load_problem(source: Any) -> Problem:
    """A :class:`Problem` from a targets file path, a YAML string or a dict."""
    doc, base, name = read_yaml(source, "targets")
    try:
        return _problem(doc, base, name)
    except ThinFilmError as e:
        raise ThinFilmError(f"{name}: {e}") from None


def check_keys(doc: Any, allowed: tuple[str, ...], required: tuple[str, ...], what: str) -> None:
    """:class:`ThinFilmError` unless ``doc`` is a mapping of ``allowed`` keys holding every ``required`` one."""
    if not isinstance(doc, dict):
        fail(what, f"expected a mapping with {', '.join(required[:-1])} and {required[-1]}, got {doc!r}")
    unknown = [k for k in doc if k not in allowed]
    if unknown:
        fail(str(unknown[0]), f"unknown key; expected {', '.join(allowed)}")
    for key in required:
        if key not in doc:
            fail(key, "missing")


def _problem(doc: Any, base: Path | None, name: str) -> Problem:
    check_keys(doc, _TOP_KEYS, ("substrate", "materials", "targets"), "targets file")
    ambient_spec = doc.get("ambient", 1.0)
    ambient = resolve_material(ambient_spec, "ambient", base)
    substrate = resolve_material(doc["substrate"], "substrate", base)
    if ambient.constant is not None:
        ambient_k = ambient.constant.imag
    else:
        lo, hi = ambient.wavelength_range
        ambient_k = float(np.max(ambient.index(np.linspace(max(lo, 360.0), min(hi, 830.0), 95)).imag))
    if ambient_k > AMBIENT_K_TOL:
        fail("ambient", f"the medium the light comes from must not absorb, got {ambient.name} (k = {ambient_k:.3g})")
    mats = doc["materials"]
    if not isinstance(mats, (list, tuple)) or not mats:
        fail("materials", f"expected a list of film materials, e.g. [\"1.38\", \"2.35\"], got {mats!r}")
    materials = [_material_entry(m, f"materials[{i}]", base) for i, m in enumerate(mats)]
    max_layers = doc.get("max_layers", 8)
    if isinstance(max_layers, bool) or not isinstance(max_layers, int) or not 1 <= max_layers <= MAX_FILMS:
        fail("max_layers", f"expected an integer in [1, {MAX_FILMS}], got {max_layers!r}")
    seeds, seed = doc.get("seeds", 6), doc.get("seed", 0)
    if isinstance(seeds, bool) or not isinstance(seeds, int) or not 1 <= seeds <= 1000:
        fail("seeds", f"expected an integer in [1, 1000], got {seeds!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        fail("seed", f"expected an integer >= 0, got {seed!r}")
    start, start_n = None, {}
    if doc.get("start") is not None:
        start, start_n = films_from_layers(materials, doc["start"], base, "start")
        if len(start) > max_layers:
            fail("start", f"{len(start)} films, more than max_layers = {max_layers}")
    targets = doc["targets"]
    if not isinstance(targets, (list, tuple)) or not targets:
        fail("targets", "expected a list of targets")
    media = [("ambient", ambient), ("substrate", substrate)] + \
            [(f"materials[{i}]", m.material) for i, m in enumerate(materials)]
    sub_k = substrate.constant.imag if substrate.constant is not None else None
    back_ok = None
    if sub_k is None or sub_k > AMBIENT_K_TOL:
        if sub_k is None:
            lo, hi = substrate.wavelength_range
            sub_k = float(np.max(substrate.index(np.linspace(max(lo, 360.0), min(hi, 830.0), 95)).imag))
        if sub_k > AMBIENT_K_TOL:
            back_ok = f"the substrate {substrate.name} absorbs (k = {sub_k:.3g})"
    parsed = [_target(t, i, media, back_ok) for i, t in enumerate(targets)]
    return Problem(ambient, substrate, materials, parsed, max_layers, start, seeds, seed, name,
                   str(locate_file(ambient_spec, base)).strip(), str(locate_file(doc["substrate"], base)).strip(), base,
                   start_n)
