"""The public numpy API: a thin-film :class:`Stack` and its float64 reflectance.

    >>> import numpy as np, thinfilm_mi as tf
    >>> stack = tf.Stack(layers=[(1.46, 500.0), (0.42 + 2.47j, 20.0)], substrate=1.6)
    >>> res = stack.rt(wavelength=np.array([450.0, 550.0]), theta=np.radians(30))
    >>> res.R.shape
    (2,)

Units: thicknesses and wavelengths in nm, angles in radians. ``ambient`` (the
medium the light comes from) must be non-absorbing; the substrate may absorb.
``T`` is the power entering the substrate. The computation is the float64 run
of the same recursion that the BSDFs trace into their kernels
(:mod:`thinfilm_mi.optics.core`), on Dr.Jit's LLVM backend.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials import catalog as _materials
from thinfilm_mi.materials.model import SPECTRAL_RANGE, Material

__all__ = ["Layer", "Stack", "RTResult", "parse_layers", "format_layers", "format_nm", "quote_material",
           "check_thickness"]

#: Largest extinction coefficient k accepted for a medium that light comes *from*
#: (the ambient, or the substrate of a reversed stack). Real glasses and water
#: have k ~ 1e-9..1e-7 in the visible, which changes R by less than 1e-6 at film
#: scales; their real part is used. Anything above this is an absorbing ambient,
#: which the formalism (a real n0 sin(theta0)) does not admit.
AMBIENT_K_TOL = 1e-6


#: Most films a stack may hold. The plugins' evaluators loop over deep stacks, so
#: load and kernel costs grow linearly (1000 films load in 0.8-1.7 s per plugin,
#: measured); beyond this a stack is refused with a clear error rather than left
#: to overflow the float64 rescaling factor 2^(films + 1) of the unrolled
#: recursion at 1023 films (or to take minutes and gigabytes to trace).
MAX_FILMS = 1000


def check_film_count(count: int, name: str = "layers") -> None:
    """:class:`ThinFilmError` if a stack of ``count`` films exceeds :data:`MAX_FILMS`."""
    if count > MAX_FILMS:
        raise ThinFilmError(f"{name}: {count} films given, at most {MAX_FILMS} are supported")


def check_thickness(value: Any, name: str) -> float:
    """``value`` as a finite float >= 0 (nm), or :class:`ThinFilmError` naming ``name``."""
    try:
        d = float(value)
    except (TypeError, ValueError):
        raise ThinFilmError(f"{name}: thickness must be a number of nm, got {value!r}") from None
    if not math.isfinite(d) or d < 0:
        raise ThinFilmError(f"{name}: thickness must be a finite number >= 0 nm, got {value!r}")
    return d


@dataclass(frozen=True)
class Layer:
    """One film: a :class:`~thinfilm_mi.materials.catalog.Material` and a thickness in nm."""

    material: Material
    thickness: float

    def __str__(self) -> str:
        return f"{self.material.name} {self.thickness:g}"


#: one token of a layer: a quoted material ("..." or '...', which may hold ';', spaces
#: and the other quote) or a run of characters other than white space, ';' and quotes
_TOKEN = re.compile(r"""\s*(?:"([^"]*)"|'([^']*)'|([^\s;"']+))""")
#: what ends a layer outside quotes
_SEPARATORS = ";\n"
_QUOTING = ("a material name or file path that holds ';', spaces or quotes goes in quotes, "
            """e.g. '"my films/a;b.csv" 100' (in scene XML: value='"my films/a;b.csv" 100')""")


def _split_layers(text: str, name: str) -> list[list[str]]:
    """The layers of ``text``, each a list of its tokens, quotes removed."""
    layers, tokens, pos = [], [], 0
    while pos < len(text):
        if text[pos] in _SEPARATORS:
            layers.append(tokens)
            tokens, pos = [], pos + 1
            continue
        if text[pos].isspace():
            pos += 1
            continue
        m = _TOKEN.match(text, pos)
        if m is None:   # an unclosed quote
            raise ThinFilmError(f"{name}: unclosed quote {text[pos]} at character {pos + 1} of {text!r}; "
                                f"{_QUOTING}")
        tokens.append(next(g for g in m.groups() if g is not None))
        pos = m.end()
        if pos < len(text) and not (text[pos].isspace() or text[pos] in _SEPARATORS):
            raise ThinFilmError(f"{name}: {text[m.start():pos + 1].strip()!r} in {text!r}: a quoted name "
                                f"must be followed by white space or ';'; {_QUOTING}")
    layers.append(tokens)
    return layers


def quote_material(spec: str) -> str:
    """``spec`` as a ``layers`` string writes it: in quotes where it holds ';', white
    space or a quote (a file path, say), as it is otherwise."""
    if spec and not re.search(r"""[\s;"']""", spec):
        return spec
    return f"'{spec}'" if '"' in spec else f'"{spec}"'


def format_nm(d: float) -> str:
    """A thickness in nm as a ``layers`` string writes it (to 0.1 pm)."""
    return f"{d:.4f}".rstrip("0").rstrip(".") or "0"


def format_layers(films) -> str:
    """``"MATERIAL NM; ..."`` from ``(material spec, thickness nm)`` pairs: what
    :func:`parse_layers` reads back and every plugin's ``layers`` accepts."""
    return "; ".join(f"{quote_material(spec)} {format_nm(d)}" for spec, d in films)


def parse_layers(text: str, name: str = "layers") -> list[tuple[Any, float]]:
    """Parse ``"MATERIAL THICKNESS_NM; ..."`` (outside in) into ``[(material, nm), ...]``.

    Layers are separated by ``;`` or new lines; each holds a material
    specification and a thickness in nm separated by white space. A material
    that holds ``;``, white space or a quote (a file path) is written in double
    or single quotes: ``'"my films/a;b.csv" 100; SiO2 50'``. The empty
    string (or only white space) means no films. Materials are returned as
    written (strings, quotes removed); :class:`Stack` resolves them.
    """
    if not isinstance(text, str):
        raise ThinFilmError(f"{name}: expected a string 'MATERIAL THICKNESS_NM; ...', got {text!r}")
    out = []
    if not text.strip():
        return out
    parts = _split_layers(text.strip(), name)
    for i, tokens in enumerate(parts):
        where = f"{name}[{i}] ({' '.join(tokens)!r} in {text!r})"
        if not tokens:
            if i == len(parts) - 1:  # a trailing separator is harmless
                continue
            raise ThinFilmError(f"{where}: empty layer; separate layers with ';' as in 'SiO2 500; Au 20'")
        if len(tokens) == 1:
            raise ThinFilmError(f"{where}: missing thickness; write 'MATERIAL THICKNESS_NM', e.g. 'SiO2 500'; "
                                f"{_QUOTING}")
        if len(tokens) > 2:
            raise ThinFilmError(
                f"{where}: expected 'MATERIAL THICKNESS_NM', got {len(tokens)} tokens; "
                f"separate layers with ';'; {_QUOTING}"
            )
        try:
            float(tokens[1])
        except ValueError:
            # most often a name cut at a space or ';' ("my films/a;b.csv 100")
            raise ThinFilmError(f"{where}: thickness must be a number of nm, got {tokens[1]!r} after "
                                f"{tokens[0]!r}; {_QUOTING}") from None
        out.append((tokens[0], check_thickness(tokens[1], f"{name}[{i}] thickness")))
        check_film_count(len(out), name)
    return out


@dataclass
class RTResult:
    """Reflection and transmission of a stack; arrays broadcast from the inputs.

    ``Rs, Rp, Ts, Tp``: energy fractions per polarisation; ``R = (Rs + Rp)/2`` and
    ``T = (Ts + Tp)/2`` for unpolarised light (the paper's k_r, k_t, eq. 5-6);
    ``A = 1 - R - T`` the absorbed fraction. ``rs, rp, ts, tp``: complex
    amplitudes in tmm's sign convention (E-field ratios).
    """

    rs: np.ndarray
    rp: np.ndarray
    ts: np.ndarray
    tp: np.ndarray
    Rs: np.ndarray
    Rp: np.ndarray
    Ts: np.ndarray
    Tp: np.ndarray

    @property
    def R(self) -> np.ndarray:
        return 0.5 * (self.Rs + self.Rp)

    @property
    def T(self) -> np.ndarray:
        return 0.5 * (self.Ts + self.Tp)

    @property
    def A(self) -> np.ndarray:
        return 1.0 - self.R - self.T


def _resolve(spec: Any, name: str) -> Material:
    """:func:`materials.resolve` with errors that name the argument (``substrate``,
    ``ambient``, ``layers[2] material``)."""
    try:
        return _materials.resolve(spec)
    except ValueError as e:
        msg = str(e)
        if msg.startswith("material: "):
            msg = msg[len("material: "):]
        raise ThinFilmError(f"{name}: {msg}") from None


def _check_ambient(material: Material, name: str) -> Material:
    if material.constant is not None:
        if material.constant.imag > AMBIENT_K_TOL:
            raise ThinFilmError(
                f"{name}: the medium the light comes from must not absorb, got {material.name} "
                f"(k = {material.constant.imag!r})"
            )
        return material
    lo = max(material.wavelength_range[0], SPECTRAL_RANGE[0])
    hi = min(material.wavelength_range[1], SPECTRAL_RANGE[1])
    k = material.index(np.linspace(lo, hi, 95)).imag
    if np.any(k > AMBIENT_K_TOL):
        raise ThinFilmError(
            f"{name}: the medium the light comes from must not absorb, got {material.name} "
            f"(k up to {k.max():.3g})"
        )
    return material


class Stack:
    """A stack of thin films between an ambient medium and a substrate.

    Parameters
    ----------
    layers : sequence of (material, thickness_nm), or a string
        Films from the ambient side inwards, e.g. ``[(1.46, 500), (0.42+2.47j, 20)]``
        or ``"SiO2 500; Au 20"``. A material is anything
        :func:`thinfilm_mi.materials.catalog.resolve` accepts.
    substrate : material
        The exit medium (may absorb: a metal, a semiconductor).
    ambient : material
        The medium the light comes from; must not absorb.
    """

    def __init__(self, layers: Sequence[tuple[Any, float]] | str = (), substrate: Any = 1.0,
                 ambient: Any = 1.0):
        if isinstance(layers, str):
            layers = parse_layers(layers)
        try:
            items = list(layers)
        except TypeError:
            raise ThinFilmError(f"layers: expected a list of (material, thickness_nm), got {layers!r}") from None
        check_film_count(len(items))
        parsed = []
        for i, item in enumerate(items):
            if isinstance(item, Layer):
                parsed.append(item)
                continue
            if not isinstance(item, (tuple, list)) or len(item) != 2:
                raise ThinFilmError(f"layers[{i}]: expected (material, thickness_nm), got {item!r}")
            mat = _resolve(item[0], f"layers[{i}] material")
            parsed.append(Layer(mat, check_thickness(item[1], f"layers[{i}] thickness")))
        self.layers: tuple[Layer, ...] = tuple(parsed)
        self.substrate: Material = _resolve(substrate, "substrate")
        self.ambient: Material = _check_ambient(_resolve(ambient, "ambient"), "ambient")

    # -- description -------------------------------------------------------
    def __repr__(self) -> str:
        films = "; ".join(str(l) for l in self.layers) or "no films"
        return f"Stack({self.ambient.name} | {films} | {self.substrate.name})"

    def __len__(self) -> int:
        return len(self.layers)

    def reversed(self) -> "Stack":
        """The same films lit from the substrate side (substrate becomes the ambient).

        The substrate must not absorb (light cannot arrive from inside a metal).
        """
        _check_ambient(self.substrate, "substrate (as the ambient of the reversed stack)")
        return Stack(list(reversed(self.layers)), substrate=self.ambient, ambient=self.substrate)

    # -- evaluation -----------------------------------------------------------
    def indices(self, wavelength_nm: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
        """``(ambient, [film indices], substrate)`` as complex arrays at ``wavelength_nm``."""
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        return (self.ambient.index(wl).real, [l.material.index(wl) for l in self.layers],
                self.substrate.index(wl))

    def rt(self, wavelength: Any, theta: Any = 0.0) -> RTResult:
        """Reflectance, transmittance and amplitudes at ``wavelength`` (nm) and
        angle of incidence ``theta`` (radians, in [0, pi/2], measured in the
        ambient medium). Inputs broadcast like numpy arrays."""
        from thinfilm_mi.optics.backend import reference_rt, to_numpy

        wl = np.asarray(wavelength, dtype=np.float64)
        th = np.asarray(theta, dtype=np.float64)
        if not np.all(np.isfinite(wl)) or np.any(wl <= 0):
            raise ThinFilmError(f"wavelength: must be finite and > 0 nm, got {wavelength!r}")
        if not np.all(np.isfinite(th)) or np.any(th < 0) or np.any(th > math.pi / 2 + 1e-12):
            raise ThinFilmError(f"theta: must be in [0, pi/2] radians, got {theta!r}")
        wl, th = np.broadcast_arrays(wl, th)
        shape = wl.shape
        wl_flat = wl.ravel()
        n0, films, nsub = self.indices(wl_flat)
        out = reference_rt(n0, np.cos(th.ravel()), films,
                           [l.thickness for l in self.layers], nsub, wl_flat)
        return RTResult(**{k: to_numpy(v).reshape(shape) for k, v in out.items()})
