"""The material model: a complex refractive index ``n + ik`` (``k >= 0``) as a function of
the vacuum wavelength in nm, constant, tabulated (linear interpolation) or given by
one of the refractiveindex.info dispersion formulas (:mod:`.dispersion`), and the
ranges every index must keep (:data:`MIN_INDEX`, :data:`MAX_INDEX`) and every dataset
must cover (:data:`SPECTRAL_RANGE`). :mod:`thinfilm_mi.materials.catalog` turns specifications into
these objects.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials.dispersion import formula_by_number

__all__ = [
    "SPECTRAL_RANGE", "RANGE_RTOL", "DATA_DIR", "MIN_INDEX", "MAX_INDEX", "check_index_range", "Material",
    "ConstantMaterial", "TabulatedIndex", "DispersionFormula", "DispersiveMaterial", "GRID",
    "check_wavelengths", "RESAMPLE_TOL", "RESAMPLE_STEPS", "UniformResampling", "uniform_grid",
]

#: Mitsuba 3's spectral range (nm): every dataset used for rendering must cover it.
SPECTRAL_RANGE = (360.0, 830.0)

# Relative slack on a range's ends, so that a range limit that went through a
# unit conversion (um -> nm: 0.83 * 1000 = 829.9999999999999) still counts.
RANGE_RTOL = 1e-9

DATA_DIR = Path(__file__).resolve().parent.parent / "data"

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


class TabulatedIndex:
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


class DispersionFormula:
    """n from refractiveindex.info dispersion formula number ``formula`` (an entry of
    :data:`~thinfilm_mi.materials.dispersion.FORMULAS`, λ in µm) with the file's
    ``coefficients``, valid over ``range`` (nm)."""

    kind = "formula"

    def __init__(self, formula: int, coefficients: Sequence[float], range_nm: tuple[float, float]):
        self.formula = formula_by_number(formula)
        self.coefficients = tuple(float(x) for x in coefficients)
        self.range = (float(range_nm[0]), float(range_nm[1]))

    def __call__(self, wl: np.ndarray) -> np.ndarray:
        return self.formula.n(self.coefficients, wl * 1e-3)


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
        for part, what, bad, need in ((n_part, "n", np.less_equal, "> 0"), (k_part, "k", np.less, ">= 0")):
            if isinstance(part, TabulatedIndex):
                vals = part.values
                if not np.all(np.isfinite(vals)):
                    raise MaterialError(f"material {name!r}: its {what} table holds non-finite values")
                if np.any(bad(vals, 0)):
                    raise MaterialError(f"material {name!r}: {what} must be {need}, "
                                        f"its table has {what} = {vals.min()!r}")

    def knots(self) -> np.ndarray:
        """Wavelengths (nm) of the tabulated data points, where the linear
        interpolant may bend (empty for formulas). Resampling on a grid that
        includes them reproduces the interpolant exactly."""
        parts = [p.wl for p in (self._n, self._k) if isinstance(p, TabulatedIndex)]
        return np.unique(np.concatenate(parts)) if parts else np.empty(0)

    def uniform_resampling(self) -> "UniformResampling | None":
        """This material on the coarsest grid of :data:`RESAMPLE_STEPS` over
        :data:`SPECTRAL_RANGE` whose linear interpolation stays within
        :data:`RESAMPLE_TOL` of :meth:`index` in n and in k; ``None`` where no step
        does (or the data do not cover the range). Found once per material."""
        if not hasattr(self, "_uniform"):
            self._uniform = UniformResampling.fit(self)
        return self._uniform

    def covers(self, lo: float, hi: float) -> bool:
        """Whether the data cover ``[lo, hi]`` nm."""
        a, b = self.wavelength_range
        return lo >= a * (1 - RANGE_RTOL) and hi <= b * (1 + RANGE_RTOL)

    def index(self, wavelength_nm) -> np.ndarray:
        wl = np.asarray(wavelength_nm, dtype=np.float64)
        lo, hi = self.wavelength_range
        if wl.size:
            bad = ~np.isfinite(wl) | (wl < lo * (1 - RANGE_RTOL)) | (wl > hi * (1 + RANGE_RTOL))
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


#: Mitsuba's spectral range on a 1 nm grid (where datasets and checks are evaluated).
GRID = np.linspace(SPECTRAL_RANGE[0], SPECTRAL_RANGE[1],
                   int(SPECTRAL_RANGE[1] - SPECTRAL_RANGE[0]) + 1)


def check_wavelengths(wl: np.ndarray, lines: Sequence[int], where: str, what: str) -> None:
    """Refuse a table whose wavelengths repeat or turn back: each wavelength has one
    value, and the rows run one way (increasing, or decreasing as some spectrometers
    write them). ``lines[i]`` is the line of row ``i`` in ``what`` (a file, or a table
    in one). A repeated wavelength with two values would make n step there."""
    step = np.diff(wl)
    if len(step) == 0:
        return
    direction = 1.0 if step[0] > 0 else -1.0
    bad = np.flatnonzero(step * direction <= 0)
    if len(bad):
        i = int(bad[0]) + 1
        if wl[i] == wl[i - 1] or wl[i] in wl[:i]:
            first = lines[int(np.flatnonzero(wl[:i] == wl[i])[0])]
            raise MaterialError(f"{where}: line {lines[i]} of {what} repeats the wavelength {wl[i]:g} nm "
                                f"(first on line {first}); give one value per wavelength")
        raise MaterialError(f"{where}: line {lines[i]} of {what} turns back to {wl[i]:g} nm after "
                            f"{wl[i - 1]:g} nm; the wavelengths must increase (or decrease) row by row")


#: Largest deviation (in n and in k) of a uniform resampling from a dataset's own
#: interpolation: a reflectance moves by less than about 1e-4 per unit of index error
#: near normal incidence, below what a 16-spp render resolves.
RESAMPLE_TOL = 1e-4

#: Steps (nm) of the uniform grids a dataset may be resampled on, coarsest first: powers
#: of two, so the grids nest (the union of two is the finer one) and a wavelength's cell
#: is exact in float32.
RESAMPLE_STEPS = (1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125)


def uniform_grid(step: float) -> np.ndarray:
    """The wavelengths (nm) ``step`` apart over :data:`SPECTRAL_RANGE`."""
    lo, hi = SPECTRAL_RANGE
    return lo + step * np.arange(int(round((hi - lo) / step)) + 1)


class UniformResampling:
    """A dataset's index on :func:`uniform_grid` (``step``): ``values`` (complex128, one
    per grid wavelength) and the measured ``deviation`` ``(n, k)`` of their linear
    interpolation from the dataset's own, at its knots (where the difference of two
    piecewise-linear functions peaks: both agree at the grid's nodes) and at the cells'
    midpoints (where a formula's, of nearly constant curvature across a cell, does)."""

    def __init__(self, step: float, values: np.ndarray, deviation: tuple[float, float]):
        self.step = step
        self.grid = uniform_grid(step)
        self.values = values
        self.deviation = deviation

    @classmethod
    def fit(cls, material: "DispersiveMaterial") -> "UniformResampling | None":
        if not material.covers(*SPECTRAL_RANGE):
            return None
        lo, hi = SPECTRAL_RANGE
        knots = material.knots()
        knots = knots[(knots > lo) & (knots < hi)]
        exact_knots = material.index(knots)
        for step in RESAMPLE_STEPS:
            grid = uniform_grid(step)
            values = material.index(grid)
            mids = grid[:-1] + 0.5 * step
            probe = np.concatenate([knots, mids])
            exact = np.concatenate([exact_knots, material.index(mids)])
            dn = np.abs(np.interp(probe, grid, values.real) - exact.real).max()
            dk = np.abs(np.interp(probe, grid, values.imag) - exact.imag).max()
            if max(dn, dk) <= RESAMPLE_TOL:
                return cls(step, values, (float(dn), float(dk)))
        return None
