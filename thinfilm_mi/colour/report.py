"""Colour of a stack: the numbers a coating designer reads beside the render.

    >>> from thinfilm_mi import Stack
    >>> from thinfilm_mi.colour.report import colour_report
    >>> report = colour_report(Stack("1.38 99.6", substrate=1.52), angles=[0, 30, 60],
    ...                        illuminant="D65", observer=2)
    >>> rec = report.records()[0]          # angle 0, reflection
    >>> rec.quantity, round(100 * rec.Y, 2), rec.srgb
    ('R', 1.3, '#1f1d23')

For reflection (``R``) and transmission (``T``) at each angle of incidence
(degrees, in the ambient medium) :func:`colour_report` gives CIE XYZ (``Y`` as
a fraction, 0-1: the perfect reflector has ``Y = 1``), the chromaticity ``xy``,
CIE L*a*b*, an sRGB swatch and the luminous (photopic) ``Yv``, weighted by the
CIE 1924 photopic efficiency V(λ) (``Yv = ∫ R V S dλ / ∫ V S dλ``); for the 2°
observer ``Yv`` equals ``Y`` (its ȳ *is* V(λ)). Unpolarised light by default,
s and p separately on request. The optics is :meth:`Stack.rt
<thinfilm_mi.materials.stack.Stack.rt>` (the exact float64 recursion); all colorimetry
(colour-matching functions, illuminants, Planck's law, L*a*b*, sRGB) is
colour-science's.

Choices, stated once:

- **Spectral grid.** 1 nm over the colour-matching functions' range (360-830 nm)
  intersected with where the illuminant is tabulated: 360-780 nm for D65 and A
  (colour-science's tables stop at 780 nm), 380-780 nm for F11 (FL11),
  360-830 nm for ``blackbody:T``. Tables at 5 nm are interpolated by
  colour-science (its default interpolator); the stack is evaluated at every
  1 nm sample, so interference fringes down to ~10 nm period are resolved.
- **Illuminants.** ``"D65"``, ``"A"``, ``"F11"`` (colour-science's ``FL11``) and
  ``"blackbody:T"`` (T in kelvin, Planck's law via :func:`colour.sd_blackbody`;
  ``"blackbody:2856"`` is CIE illuminant A's incandescent lamp).
- **Normalisation and white.** ``Y = 1`` for the perfect reflector under the
  chosen illuminant and observer; L*a*b* is relative to that same white (the
  illuminant's XYZ computed from its spectrum, not a rounded table value), so a
  perfect reflector is exactly L* = 100, a* = b* = 0.
- **sRGB swatch.** sRGB is defined on the CIE 1931 2° observer, so the swatch
  always comes from the 2° XYZ (also when the report's observer is 10°). By
  default it is chromatically adapted (CAT02) from the illuminant's white to
  sRGB's D65 white - the colour an observer adapted to the light sees, so a
  perfect reflector is ``#ffffff`` under any illuminant. With
  ``chromatic_adaptation=None`` it is not adapted ("as lit": a white object under
  a 2856 K lamp is orange), which is what a spectral Mitsuba render shows, since
  Mitsuba's film does not white-balance. Out-of-gamut values are clipped to
  [0, 1] before the sRGB encoding.
- **Black.** Where ``X + Y + Z = 0`` (T of an opaque stack) ``xy`` is the white's
  chromaticity (achromatic) instead of undefined.
"""
from __future__ import annotations

import csv
import io
import json
import math
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.choices import choose
from thinfilm_mi.optics.polarization import ALIASES, POLARIZATIONS, UNPOLARIZED, P, S

__all__ = [
    "ILLUMINANTS", "OBSERVERS", "RECORD_KEYS", "Illuminant", "ColourValues",
    "ColourRecord", "ColourReport", "resolve_illuminant", "resolve_observer", "check_angles",
    "integration_wavelengths", "spectrum_colour", "colour_report",
]

#: Named illuminants -> colour-science's ``SDS_ILLUMINANTS`` keys.
ILLUMINANTS = {"D65": "D65", "A": "A", "F11": "FL11"}

#: Observers (field size in degrees) -> colour-science's ``MSDS_CMFS`` keys.
OBSERVERS = {2: "CIE 1931 2 Degree Standard Observer", 10: "CIE 1964 10 Degree Standard Observer"}

#: The photopic luminous efficiency V(λ) of the luminous Y.
PHOTOPIC_LEF = "CIE 1924 Photopic Standard Observer"


#: The keys of one record of ``--json`` / ``--csv`` (plus ``polarization``
#: after ``quantity`` when s or p were asked for).
RECORD_KEYS = ("angle", "quantity", "X", "Y", "Z", "x", "y", "L", "a", "b", "srgb")

#: Wavelength range (nm) and step of the colour-matching functions used.
CMF_RANGE = (360.0, 830.0)
STEP_NM = 1.0

_BLACKBODY = re.compile(r"^\s*blackbody\s*:\s*(?P<t>[^\s]+?)\s*(?:k|K)?\s*$", re.IGNORECASE)


# --------------------------------------------------------------------------------------
# inputs


@dataclass(frozen=True)
class Illuminant:
    """A light source: its name as written (``"D65"``, ``"blackbody:2856"``), its
    spectral distribution (colour-science, relative) and, for a black body, its
    temperature in kelvin."""

    name: str
    sd: Any = field(compare=False, repr=False)
    temperature: float | None = None

    @property
    def shape(self):
        """The integration grid: the CMFs' range within the illuminant's, 1 nm."""
        import colour

        lo = max(CMF_RANGE[0], float(self.sd.shape.start))
        hi = min(CMF_RANGE[1], float(self.sd.shape.end))
        return colour.SpectralShape(lo, hi, STEP_NM)


def resolve_illuminant(spec: Any) -> Illuminant:
    """``"D65"``, ``"A"``, ``"F11"`` (any case) or ``"blackbody:T"`` (T in kelvin,
    > 0, an optional trailing ``K``) -> :class:`Illuminant`; an :class:`Illuminant`
    passes through. Anything else raises :class:`ThinFilmError` naming ``illuminant``."""
    if isinstance(spec, Illuminant):
        return spec
    if not isinstance(spec, str):
        raise ThinFilmError(f"illuminant: expected a name such as 'D65', 'A', 'F11' or "
                            f"'blackbody:2856', got {spec!r}")
    return _named_illuminant(spec.strip())


@lru_cache(maxsize=32)
def _named_illuminant(spec: str) -> Illuminant:
    import colour

    key = spec.upper()
    if key in ILLUMINANTS:
        return Illuminant(key, colour.SDS_ILLUMINANTS[ILLUMINANTS[key]].copy())
    m = _BLACKBODY.match(spec)
    if m is None:
        raise ThinFilmError(f"illuminant: unknown illuminant {spec!r}; expected one of "
                            f"{', '.join(ILLUMINANTS)} or blackbody:T (T in kelvin, e.g. blackbody:2856)")
    try:
        t = float(m.group("t"))
    except ValueError:
        raise ThinFilmError(f"illuminant {spec!r}: temperature must be a number of kelvin, "
                            f"got {m.group('t')!r}") from None
    if not (math.isfinite(t) and t > 0):
        raise ThinFilmError(f"illuminant {spec!r}: temperature must be a finite number > 0 K, got {t:g}")
    shape = colour.SpectralShape(CMF_RANGE[0], CMF_RANGE[1], STEP_NM)
    return Illuminant(f"blackbody:{t:g}", colour.sd_blackbody(t, shape), t)


def resolve_observer(observer: Any) -> int:
    """``2`` / ``10`` (also ``"2"``, ``"10°"``, colour-science's full names) ->
    ``2`` or ``10``; anything else raises :class:`ThinFilmError` naming ``observer``."""
    if isinstance(observer, str):
        for deg, name in OBSERVERS.items():
            if observer.strip() == name:
                return deg
        text = observer.strip().rstrip("°").strip()
    else:
        text = observer
    try:
        value = float(text)
    except (TypeError, ValueError):
        value = math.nan
    if value in OBSERVERS:
        return int(value)
    raise ThinFilmError(f"observer: expected 2 (CIE 1931) or 10 (CIE 1964) degrees, got {observer!r}")


def check_angles(angles: Any) -> np.ndarray:
    """Angles of incidence in degrees as a 1-d float array, each finite and in
    [0, 90); anything else raises :class:`ThinFilmError` naming ``angles``."""
    try:
        a = np.atleast_1d(np.asarray(angles, dtype=np.float64))
    except (TypeError, ValueError):
        raise ThinFilmError(f"angles: expected numbers of degrees, got {angles!r}") from None
    if a.ndim != 1 or a.size == 0:
        raise ThinFilmError(f"angles: expected a list of degrees, got {angles!r}")
    bad = a[~(np.isfinite(a) & (a >= 0.0) & (a < 90.0))]
    if bad.size:
        raise ThinFilmError(f"angles: the angle of incidence must be in [0, 90) degrees, got {bad[0]:g}")
    return a


#: What ``polarizations=`` may name: a polarisation, or ``both`` (s and p).
_REPORTED = {**{name: (p,) for name, p in POLARIZATIONS.items()}, "both": (S, P)}


def _check_polarizations(polarizations: Any) -> tuple[str, ...]:
    items = [polarizations] if isinstance(polarizations, str) else polarizations
    try:
        items = list(items)
    except TypeError:
        items = [polarizations]
    out = []
    for p in items:
        try:
            chosen = choose(_REPORTED, p, "polarizations", ALIASES)
        except ThinFilmError:
            raise ThinFilmError(f"polarizations: expected {', '.join(POLARIZATIONS)} or both, got {p!r}") from None
        for n in chosen:
            if n.name not in out:
                out.append(n.name)
    if not out:
        raise ThinFilmError(f"polarizations: none given ({polarizations!r})")
    return tuple(out)


# --------------------------------------------------------------------------------------
# colorimetry of spectra


@dataclass(frozen=True)
class _Weights:
    """Everything a spectrum is integrated against, on one grid."""

    wavelengths: np.ndarray
    cmfs: Any            # colour MultiSpectralDistributions of the observer, aligned
    cmfs_2: Any          # the CIE 1931 2° CMFs, aligned (for sRGB)
    illuminant_sd: Any   # aligned
    shape: Any
    lef: np.ndarray      # V(λ) on the grid
    white_XYZ: np.ndarray
    white_xy: np.ndarray
    white_xy_2: np.ndarray


@lru_cache(maxsize=32)
def _weights(illuminant: Illuminant, observer: int) -> _Weights:
    import colour
    from colour.colorimetry import SDS_LEFS_PHOTOPIC, msds_to_XYZ_integration

    shape = illuminant.shape
    sd = illuminant.sd.copy().align(shape)
    cmfs = colour.MSDS_CMFS[OBSERVERS[observer]].copy().align(shape)
    cmfs_2 = colour.MSDS_CMFS[OBSERVERS[2]].copy().align(shape)
    lef = SDS_LEFS_PHOTOPIC[PHOTOPIC_LEF].copy().align(shape).values
    one = np.ones(len(shape.wavelengths))
    white = msds_to_XYZ_integration(one, cmfs, sd, shape=shape) / 100.0
    white_2 = msds_to_XYZ_integration(one, cmfs_2, sd, shape=shape) / 100.0
    return _Weights(np.asarray(shape.wavelengths, dtype=np.float64), cmfs, cmfs_2, sd, shape,
                    np.asarray(lef, dtype=np.float64), white, colour.XYZ_to_xy(white),
                    colour.XYZ_to_xy(white_2))


def integration_wavelengths(illuminant: Any = "D65") -> np.ndarray:
    """The wavelengths (nm) at which :func:`colour_report` evaluates the stack."""
    return _weights(resolve_illuminant(illuminant), 2).wavelengths.copy()


@dataclass
class ColourValues:
    """Colour of a set of spectra; arrays have the spectra's leading shape.

    ``XYZ`` (…, 3) with Y = 1 for the perfect reflector; ``xy`` (…, 2); ``Lab``
    (…, 3) relative to the illuminant's white; ``rgb`` (…, 3) display-encoded sRGB
    in [0, 1] (clipped); ``rgb_linear`` (…, 3) linear sRGB before clipping;
    ``luminous`` (…) the V(λ)-weighted Y; ``hex`` the ``"#rrggbb"`` of ``rgb``
    (a nested list of the leading shape).
    """

    XYZ: np.ndarray
    xy: np.ndarray
    Lab: np.ndarray
    rgb: np.ndarray
    rgb_linear: np.ndarray
    luminous: np.ndarray
    hex: Any
    white_XYZ: np.ndarray
    white_xy: np.ndarray


def _hex(rgb: np.ndarray):
    if rgb.ndim == 1:
        r, g, b = (int(round(255.0 * float(v))) for v in rgb)
        return f"#{r:02x}{g:02x}{b:02x}"
    return [_hex(v) for v in rgb]


def spectrum_colour(values: Any, wavelengths: Any = None, illuminant: Any = "D65", observer: Any = 2,
                    chromatic_adaptation: str | None = "CAT02") -> ColourValues:
    """Colour of reflectance / transmittance spectra ``values`` (…, len(wavelengths)),
    fractions 0-1, sampled at ``wavelengths`` (nm; default: the integration grid
    of ``illuminant``, :func:`integration_wavelengths`). Other grids are
    interpolated linearly and must cover the integration range."""
    import colour
    from colour.colorimetry import msds_to_XYZ_integration

    illum = resolve_illuminant(illuminant)
    obs = resolve_observer(observer)
    if chromatic_adaptation is not None and chromatic_adaptation not in colour.CHROMATIC_ADAPTATION_TRANSFORMS:
        raise ThinFilmError(f"chromatic_adaptation: expected None or one of "
                            f"{', '.join(colour.CHROMATIC_ADAPTATION_TRANSFORMS)}, got {chromatic_adaptation!r}")
    w = _weights(illum, obs)
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 0 or not np.all(np.isfinite(v)):
        raise ThinFilmError(f"values: expected finite spectra (…, wavelength), got {values!r}")
    if wavelengths is not None:
        wl = np.asarray(wavelengths, dtype=np.float64)
        if wl.ndim != 1 or wl.size != v.shape[-1] or not np.all(np.diff(wl) > 0):
            raise ThinFilmError(f"wavelengths: expected {v.shape[-1]} increasing wavelengths (nm), "
                                f"got shape {wl.shape}")
        if wl.size != w.wavelengths.size or not np.allclose(wl, w.wavelengths):
            if wl[0] > w.wavelengths[0] + 1e-9 or wl[-1] < w.wavelengths[-1] - 1e-9:
                raise ThinFilmError(f"wavelengths: must cover {w.wavelengths[0]:g}-{w.wavelengths[-1]:g} nm "
                                    f"(the integration range for {illum.name}), got {wl[0]:g}-{wl[-1]:g}")
            flat = v.reshape(-1, v.shape[-1])
            v = np.stack([np.interp(w.wavelengths, wl, row) for row in flat]).reshape(
                v.shape[:-1] + w.wavelengths.shape)
    elif v.shape[-1] != w.wavelengths.size:
        raise ThinFilmError(f"values: last axis must hold {w.wavelengths.size} samples "
                            f"({w.wavelengths[0]:g}-{w.wavelengths[-1]:g} nm, 1 nm) or give wavelengths, "
                            f"got {v.shape[-1]}")

    XYZ = msds_to_XYZ_integration(v, w.cmfs, w.illuminant_sd, shape=w.shape) / 100.0
    s = w.illuminant_sd.values
    luminous = (v @ (w.lef * s)) / float(np.dot(w.lef, s))
    total = XYZ.sum(axis=-1, keepdims=True)
    xy = np.where(total > 0, XYZ[..., :2] / np.where(total > 0, total, 1.0), w.white_xy)
    Lab = colour.XYZ_to_Lab(XYZ, illuminant=w.white_xy)
    XYZ_2 = XYZ if obs == 2 else msds_to_XYZ_integration(v, w.cmfs_2, w.illuminant_sd, shape=w.shape) / 100.0
    rgb_linear = colour.XYZ_to_sRGB(XYZ_2, illuminant=w.white_xy_2,
                                    chromatic_adaptation_transform=chromatic_adaptation,
                                    apply_cctf_encoding=False)
    rgb = colour.models.eotf_inverse_sRGB(np.clip(rgb_linear, 0.0, 1.0))
    return ColourValues(XYZ, xy, Lab, rgb, rgb_linear, luminous, _hex(rgb), w.white_XYZ, w.white_xy)


# --------------------------------------------------------------------------------------
# the report of a stack


@dataclass(frozen=True)
class ColourRecord:
    """One angle, polarisation and quantity of a :class:`ColourReport`."""

    angle: float
    quantity: str
    polarization: str
    X: float
    Y: float
    Z: float
    x: float
    y: float
    L: float
    a: float
    b: float
    srgb: str
    luminous: float

    def as_dict(self, polarization: bool = False) -> dict:
        """The ``--json`` record: :data:`RECORD_KEYS` in order (``polarization``
        after ``quantity`` when asked)."""
        d = {k: getattr(self, k) for k in RECORD_KEYS}
        if polarization:
            d = {"angle": d.pop("angle"), "quantity": d.pop("quantity"),
                 "polarization": self.polarization, **d}
        return d


@dataclass
class ColourReport:
    """The colour of a stack at several angles (see :func:`colour_report`).

    ``spectra[(polarization, quantity)]`` is the spectrum (angle, wavelength) and
    ``colours[(polarization, quantity)]`` its :class:`ColourValues` (over angles).
    """

    stack: Any
    angles: np.ndarray
    illuminant: Illuminant
    observer: int
    polarizations: tuple[str, ...]
    wavelengths: np.ndarray
    spectra: dict = field(repr=False)
    colours: dict = field(repr=False)

    @property
    def white_XYZ(self) -> np.ndarray:
        return next(iter(self.colours.values())).white_XYZ

    @property
    def white_xy(self) -> np.ndarray:
        return next(iter(self.colours.values())).white_xy

    @property
    def polarized(self) -> bool:
        """Whether the records name their polarisation (anything but unpolarised only)."""
        return self.polarizations != (UNPOLARIZED.name,)

    def describe(self) -> str:
        obs = "CIE 1931 2°" if self.observer == 2 else "CIE 1964 10°"
        return f"{self.stack!r}; illuminant {self.illuminant.name}, {obs} observer"

    def records(self) -> list[ColourRecord]:
        """One record per angle, polarisation and quantity (R then T), angle first."""
        out = []
        for i, angle in enumerate(self.angles):
            for pol in self.polarizations:
                for qty in ("R", "T"):
                    c = self.colours[pol, qty]
                    out.append(ColourRecord(
                        float(angle), qty, pol, *(float(v) for v in c.XYZ[i]), *(float(v) for v in c.xy[i]),
                        *(float(v) for v in c.Lab[i]), c.hex[i], float(c.luminous[i])))
        return out

    def as_dicts(self) -> list[dict]:
        """The ``--json`` records (:meth:`ColourRecord.as_dict`)."""
        return [r.as_dict(self.polarized) for r in self.records()]

    def to_json(self, **kwargs) -> str:
        return json.dumps(self.as_dicts(), **kwargs)

    def to_csv(self) -> str:
        rows = self.as_dicts()
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        return buf.getvalue()

    def write_csv(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.to_csv(), encoding="utf-8")
        return path

    def table(self) -> str:
        """The terminal table: X, Y, Z and the luminous Yv in %, xy, L*a*b*, sRGB."""
        cols = ["angle"] + (["pol"] if self.polarized else []) + [
            "qty", "X%", "Y%", "Z%", "x", "y", "L*", "a*", "b*", "sRGB", "Yv%"]
        widths = [6] + ([12] if self.polarized else []) + [4, 8, 8, 8, 8, 8, 7, 7, 7, 9, 8]
        lines = ["".join(c.rjust(w) for c, w in zip(cols, widths))]
        for r in self.records():
            cells = [f"{r.angle:g}"] + ([r.polarization] if self.polarized else []) + [
                r.quantity, f"{100 * r.X:.3f}", f"{100 * r.Y:.3f}", f"{100 * r.Z:.3f}", f"{r.x:.4f}",
                f"{r.y:.4f}", f"{r.L:.2f}", f"{r.a:.2f}", f"{r.b:.2f}", r.srgb, f"{100 * r.luminous:.3f}"]
            lines.append("".join(c.rjust(w) for c, w in zip(cells, widths)))
        return "\n".join(lines)

    def figure(self):
        """A matplotlib :class:`~matplotlib.figure.Figure` (no pyplot, so it draws
        headless): the R/T spectra at the report's angles, the chromaticity diagram
        with the colour's path over angle, and a strip of swatches against angle."""
        return _report_figure(self)


def colour_report(stack: Any, angles: Any = 0.0, illuminant: Any = "D65", observer: Any = 2,
                  polarizations: Any = ("unpolarized",),
                  chromatic_adaptation: str | None = "CAT02") -> ColourReport:
    """Colour of ``stack`` (a :class:`~thinfilm_mi.materials.stack.Stack`) in reflection and
    transmission at ``angles`` (degrees of incidence in the ambient medium, each
    in [0, 90)) under ``illuminant`` (``"D65"``, ``"A"``, ``"F11"``,
    ``"blackbody:T"``) for ``observer`` 2 or 10 degrees. ``polarizations``: any of
    ``"unpolarized"`` (default), ``"s"``, ``"p"`` (``"both"`` = s and p).
    ``chromatic_adaptation``: for the sRGB swatch only (see the module docstring).
    Bad input raises :class:`ThinFilmError` naming the parameter."""
    from thinfilm_mi.materials.stack import Stack

    if not isinstance(stack, Stack):
        raise ThinFilmError(f"stack: expected a thinfilm_mi.Stack, got {stack!r}")
    a = check_angles(angles)
    illum = resolve_illuminant(illuminant)
    obs = resolve_observer(observer)
    pols = _check_polarizations(polarizations)
    wl = _weights(illum, obs).wavelengths
    res = stack.rt(wl[None, :], np.radians(a)[:, None])
    spectra, colours = {}, {}
    for pol in pols:
        for qty in ("R", "T"):
            spectra[pol, qty] = np.asarray(getattr(res, POLARIZATIONS[pol].label(qty)), dtype=np.float64)
            colours[pol, qty] = spectrum_colour(spectra[pol, qty], None, illum, obs, chromatic_adaptation)
    return ColourReport(stack, a, illum, obs, pols, wl.copy(), spectra, colours)


# --------------------------------------------------------------------------------------
# figure


def _label(pol: str, qty: str) -> str:
    return POLARIZATIONS[pol].label(qty)


#: The line style of each quantity, ``(polarisation, R or T)``, in every panel.
_STYLES = {("unpolarized", "R"): "-", ("unpolarized", "T"): "--", ("s", "R"): "-",
           ("s", "T"): "--", ("p", "R"): ":", ("p", "T"): "-."}


def _report_figure(report: ColourReport):
    from matplotlib import colormaps
    from matplotlib.figure import Figure

    fig = Figure(figsize=(13, 6.4), dpi=110)
    grid = fig.add_gridspec(2, 3, width_ratios=[1.6, 1, 1], height_ratios=[3.2, 1])
    ax_s = fig.add_subplot(grid[0, 0])
    ax_c = fig.add_subplot(grid[0, 1])
    ax_z = fig.add_subplot(grid[0, 2])
    ax_w = fig.add_subplot(grid[1, :])
    n = len(report.angles)
    colors = colormaps["viridis"](np.linspace(0.0, 0.85, n))
    step = max(1, n // 8)
    _plot_spectra(ax_s, report, colors, step)
    _plot_chromaticity(ax_c, ax_z, report)
    _plot_swatches(ax_w, report, step)
    fig.tight_layout()
    return fig


def _plot_spectra(ax_s, report: ColourReport, colors, step: int) -> None:
    """The spectra, one colour per angle (every ``step``-th in the legend), one line style
    per quantity."""
    from matplotlib.lines import Line2D

    keys = list(report.spectra)
    n = len(report.angles)
    for key in keys:
        for j in range(n):
            ax_s.plot(report.wavelengths, report.spectra[key][j], ls=_STYLES[key], color=colors[j], lw=1.1)
    handles = [Line2D([], [], color="k", ls=_STYLES[k], label=_label(*k)) for k in keys]
    handles += [Line2D([], [], color=colors[j], label=f"{report.angles[j]:g}°") for j in range(0, n, step)]
    ax_s.legend(handles=handles, fontsize=6, ncol=2)
    ax_s.set_xlabel("wavelength (nm)")
    ax_s.set_ylabel("fraction of incident power")
    ax_s.set_ylim(-0.02, 1.02)
    ax_s.grid(alpha=0.3)
    ax_s.set_title(report.describe(), fontsize=8)


def _plot_chromaticity(ax_c, ax_z, report: ColourReport) -> None:
    """The chromaticity diagram (the observer's spectral locus closed by the purple line)
    with each quantity's path over the angles, and its zoom on the paths."""
    import colour

    keys = list(report.spectra)
    markers = dict(zip(keys, "os^vDP"))
    cmfs = colour.MSDS_CMFS[OBSERVERS[report.observer]]
    locus = colour.XYZ_to_xy(cmfs.values)
    ax_c.plot(np.append(locus[:, 0], locus[0, 0]), np.append(locus[:, 1], locus[0, 1]), color="0.3", lw=1)
    for wl_mark in (460, 480, 500, 520, 540, 560, 580, 600, 620):
        i = int(np.argmin(np.abs(cmfs.wavelengths - wl_mark)))
        ax_c.annotate(f"{wl_mark}", locus[i], fontsize=6, color="0.4", xytext=(3, 0), textcoords="offset points")
    wx, wy = report.white_xy
    points = [np.array([[wx, wy]])]
    for ax in (ax_c, ax_z):
        ax.plot([wx], [wy], marker="+", color="k", ms=9, ls="none", label=f"white ({report.illuminant.name})")
        for key in keys:
            xy = report.colours[key].xy
            ax.plot(xy[:, 0], xy[:, 1], ls=_STYLES[key], color="0.45", lw=0.8)
            ax.scatter(xy[:, 0], xy[:, 1], c=report.colours[key].rgb, marker=markers[key], edgecolors="k",
                       linewidths=0.4, s=30 if ax is ax_z else 12, zorder=3, label=_label(*key))
            ax.scatter(xy[:1, 0], xy[:1, 1], facecolors="none", edgecolors="k", s=90 if ax is ax_z else 40,
                       zorder=4)
            points.append(xy)
    pts = np.concatenate(points)
    span = max(float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 1])), 0.01)
    centre = (pts.max(axis=0) + pts.min(axis=0)) / 2
    ax_z.set_xlim(centre[0] - 0.6 * span, centre[0] + 0.6 * span)
    ax_z.set_ylim(centre[1] - 0.6 * span, centre[1] + 0.6 * span)
    ax_z.set_title(f"zoom: path from {report.angles[0]:g}° (ringed) to {report.angles[-1]:g}°", fontsize=8)
    ax_z.legend(fontsize=6)
    ax_c.set_xlim(0, 0.8)
    ax_c.set_ylim(0, 0.9)
    ax_c.set_title(f"CIE {'1931 2°' if report.observer == 2 else '1964 10°'} chromaticity", fontsize=8)
    for ax in (ax_c, ax_z):
        ax.set_aspect("equal")
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        ax.grid(alpha=0.2)
        ax.tick_params(labelsize=7)


def _plot_swatches(ax_w, report: ColourReport, step: int) -> None:
    """The swatches: per quantity, the colour as seen and its hue brightened to full
    scale, along the angles (every ``step``-th labelled)."""
    import colour

    rows, labels = [], []
    for key in report.spectra:
        c = report.colours[key]
        lin = np.clip(c.rgb_linear, 0.0, None)
        peak = lin.max(axis=-1, keepdims=True)
        bright = np.where(peak > 0, lin / np.where(peak > 0, peak, 1.0), 0.0)
        rows += [c.rgb, colour.models.eotf_inverse_sRGB(bright)]
        labels += [_label(*key), f"{_label(*key)} hue"]
    ax_w.imshow(np.stack(rows), aspect="auto", interpolation="nearest")
    ax_w.set_yticks(range(len(labels)), labels, fontsize=7)
    ax_w.set_xticks(range(0, len(report.angles), step), [f"{a:g}°" for a in report.angles[::step]],
                    fontsize=7)
    ax_w.set_xlabel("angle of incidence")
    ax_w.set_title("sRGB swatches: as seen, and brightened to full scale (hue)", fontsize=8)
