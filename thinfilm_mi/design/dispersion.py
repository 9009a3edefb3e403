"""Dispersion models of a fit: a film material's ``n + ik`` from a few parameters.

A measurement file's ``materials`` entry names a model (``model: cauchy``) and
its parameters; :data:`MODELS` is the registry of them, one class per model,
each holding its parameter names, its defaults and the derivatives of the index
with respect to every parameter (the fit's Jacobian is chained through them,
point by point). Wavelengths are in nm; the formulas use λ in µm, as
refractiveindex.info writes them. ``cauchy`` and ``sellmeier`` are formulas of
:data:`thinfilm_mi.materials.dispersion.FORMULAS` with some coefficients fixed
(:class:`FormulaModel`): a fitted Sellmeier and a material file's are one code.

``constant``
    ``n + ik`` (parameters ``n``, ``k``).
``cauchy``
    ``n = A + B / λ² + C / λ⁴``, ``k = 0`` (``A``, ``B`` µm², ``C`` µm⁴): refractiveindex.info
    formula 5 with ``C1 = A, C2 = B, C3 = -2, C4 = C, C5 = -4``.
``sellmeier``
    ``n² = 1 + Σ Bi λ² / (λ² - Ci)``, ``k = 0`` (``B1 C1 B2 C2 B3 C3``, each pole ``Ci`` in µm²,
    the square of its resonance wavelength, as in SCHOTT's catalogue): refractiveindex.info
    formula 2 with its coefficients ``0 B1 C1 B2 C2 B3 C3``. A file's ``formula 1`` gives the
    resonance wavelengths instead: its ``0 B1 λ1 B2 λ2 B3 λ3`` are this model's with ``Ci = λi²``.
``catalogue``
    a named material (anything ``layers`` accepts) with ``n`` scaled and shifted,
    ``n' = scale · n + shift``, its ``k`` kept (``shift``, ``scale``).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from thinfilm_mi.design.parsing import parse_number
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials import MIN_INDEX, Material
from thinfilm_mi.materials.dispersion import FORMULAS, DifferentiableFormula
from thinfilm_mi.materials.model import ConstantMaterial, DispersiveMaterial, TabulatedIndex

__all__ = ["DispersionModel", "FormulaModel", "MODELS", "model_class", "TABLE_RANGE"]

#: The wavelengths (nm) over which a fitted dispersive material is tabulated: Mitsuba's
#: spectral range (360-830 nm) and a margin.
TABLE_RANGE = (300.0, 1100.0)


class DispersionModel:
    """A material's index from ``params`` (a dict of floats by name).

    Subclasses set ``name``, ``parameters`` (their names, in order), ``defaults``
    and implement :meth:`index_and_derivatives`."""

    name = ""
    parameters: tuple[str, ...] = ()
    defaults: dict[str, float] = {}
    #: lower bounds of parameters with a physical floor (the others are unbounded)
    lower: dict[str, float] = {}
    #: the material's own range (nm) where the formula holds; a catalogue material's data range
    wavelength_range = (0.0, np.inf)

    def __init__(self, entry: dict, where: str, resolve):
        """``entry``: the file's mapping without ``model`` and ``free``;
        ``resolve(spec, where)`` turns a material specification into a material."""
        unknown = [k for k in entry if k not in self.parameters + self.extra_keys()]
        if unknown:
            raise ThinFilmError(f"{where}: unknown key {unknown[0]!r} for model {self.name}; expected "
                                f"{', '.join(self.parameters + self.extra_keys())}")
        self.values = {p: parse_number(entry.get(p, self.defaults[p]), where, p) for p in self.parameters}

    @classmethod
    def extra_keys(cls) -> tuple[str, ...]:
        return ()

    def index_and_derivatives(self, wl: np.ndarray, params: dict) -> tuple[np.ndarray, np.ndarray]:
        """``(n + ik (P,), d(n + ik)/d parameter (P, len(parameters)))`` at ``wl`` nm
        (NaN where the parameters give no index)."""
        raise NotImplementedError

    def index(self, wl: np.ndarray, params: dict | None = None) -> np.ndarray:
        return self.index_and_derivatives(np.asarray(wl, dtype=np.float64), params or self.values)[0]

    def constant(self, params: dict) -> complex | None:
        """The index when it does not depend on wavelength (a ``layers`` string
        then writes it as a number), else ``None``."""
        return None

    def material(self, params: dict, name: str) -> Material:
        """The material these ``params`` describe, tabulated every 1 nm over
        :data:`TABLE_RANGE` (within the model's own range): what a fitted stack
        is rendered with."""
        c = self.constant(params)
        if c is not None:
            return ConstantMaterial(c, name)
        lo, hi = max(TABLE_RANGE[0], self.wavelength_range[0]), min(TABLE_RANGE[1], self.wavelength_range[1])
        wl = np.arange(np.ceil(lo), np.floor(hi) + 0.5, 1.0)
        n = self.index(wl, params)
        return DispersiveMaterial(name, TabulatedIndex(wl, n.real), TabulatedIndex(wl, n.imag),
                                  reference=f"fitted {self.name} model")


class Constant(DispersionModel):
    name = "constant"
    parameters = ("n", "k")
    defaults = {"n": 1.5, "k": 0.0}
    lower = {"n": MIN_INDEX, "k": 0.0}

    def constant(self, params):
        return complex(params["n"], params["k"])

    def index_and_derivatives(self, wl, params):
        ones = np.ones(wl.shape)
        return (params["n"] + 1j * params["k"]) * ones, np.stack([ones + 0j, 1j * ones], axis=-1)


class FormulaModel(DispersionModel):
    """A model that is a refractiveindex.info formula (``formula``, an entry of
    :data:`~thinfilm_mi.materials.dispersion.FORMULAS`) whose coefficients
    :meth:`coefficients` builds from the parameters; ``columns[i]`` is the coefficient
    that parameter ``i`` is."""

    formula: DifferentiableFormula
    columns: tuple[int, ...] = ()

    def coefficients(self, params: dict) -> tuple[float, ...]:
        """The formula's ``C1, C2, ...`` for these parameters."""
        raise NotImplementedError

    def index_and_derivatives(self, wl, params):
        n, grad = self.formula.n_and_gradient(self.coefficients(params), wl * 1e-3)
        return n + 0j, grad[..., list(self.columns)] + 0j


class Cauchy(FormulaModel):
    name = "cauchy"
    parameters = ("A", "B", "C")
    defaults = {"A": 1.5, "B": 0.0, "C": 0.0}
    formula = FORMULAS[5]
    columns = (0, 1, 3)

    def coefficients(self, params):
        return params["A"], params["B"], -2.0, params["C"], -4.0


class Sellmeier(FormulaModel):
    name = "sellmeier"
    parameters = ("B1", "C1", "B2", "C2", "B3", "C3")
    defaults = {"B1": 1.0, "C1": 0.01, "B2": 0.0, "C2": 0.0, "B3": 0.0, "C3": 0.0}
    formula = FORMULAS[2]
    columns = (1, 2, 3, 4, 5, 6)

    def coefficients(self, params):
        return (0.0,) + tuple(params[p] for p in self.parameters)


class Catalogue(DispersionModel):
    name = "catalogue"
    parameters = ("shift", "scale")
    defaults = {"shift": 0.0, "scale": 1.0}
    lower = {"scale": MIN_INDEX}

    def __init__(self, entry: dict, where: str, resolve):
        super().__init__(entry, where, resolve)
        if "material" not in entry:
            raise ThinFilmError(f"{where}: model catalogue needs 'material' (a name such as TiO2, or a file)")
        self.spec = str(entry["material"]).strip()
        self.material = resolve(entry["material"], where)
        self.wavelength_range = self.material.wavelength_range

    @classmethod
    def extra_keys(cls):
        return ("material",)

    def index_and_derivatives(self, wl, params):
        base = self.material.index(wl)
        n = params["scale"] * base.real + params["shift"] + 1j * base.imag
        return n, np.stack([np.ones(wl.shape), base.real], axis=-1) + 0j


#: The dispersion models by the name a measurement file gives (``model: NAME``).
MODELS: dict[str, type[DispersionModel]] = {m.name: m for m in (Constant, Cauchy, Sellmeier, Catalogue)}
MODELS["catalog"] = Catalogue


def model_class(name: Any, where: str) -> type[DispersionModel]:
    """The model called ``name``, or :class:`ThinFilmError` naming ``where`` and the models."""
    cls = MODELS.get(str(name).strip().lower())
    if cls is None:
        raise ThinFilmError(f"{where}: unknown model {name!r}; expected one of "
                            f"{', '.join(m for m in MODELS if m != 'catalog')}")
    return cls
