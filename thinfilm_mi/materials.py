"""Materials: complex refractive indices n + ik (k >= 0) as functions of wavelength.

This module is the single place where a material *specification* (a number, a
complex number, a name, a file) becomes a :class:`Material` whose
:meth:`Material.index` gives ``n + ik`` at vacuum wavelengths in nm.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import MaterialError

__all__ = ["Material", "ConstantMaterial", "resolve", "refractive_index"]


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

    def __init__(self, value: complex, name: str | None = None):
        value = complex(value)
        if not (math.isfinite(value.real) and math.isfinite(value.imag)):
            raise MaterialError(f"refractive index must be finite, got {value!r}")
        if value.real <= 0:
            raise MaterialError(f"refractive index: real part n must be > 0, got n = {value.real!r}")
        if value.imag < 0:
            raise MaterialError(
                f"refractive index: k must be >= 0 (gain media are not supported), got k = {value.imag!r}"
            )
        self.constant = value
        self.name = name or _format_complex(value)
        self.reference = "constant"

    def index(self, wavelength_nm) -> np.ndarray:
        return np.full(np.shape(wavelength_nm), self.constant, dtype=np.complex128)


def _format_complex(z: complex) -> str:
    if z.imag == 0:
        return f"{z.real:g}"
    return f"{z.real:g}{z.imag:+g}j"


def resolve(spec: Any) -> Material:
    """Turn a material specification into a :class:`Material`.

    Accepted: a :class:`Material`; a real or complex number; a string holding a
    number (``"1.46"``, ``"0.42+2.47j"``).
    """
    if isinstance(spec, Material):
        return spec
    if isinstance(spec, bool):
        raise MaterialError(f"material: expected a number or a name, got {spec!r}")
    if isinstance(spec, (int, float, complex, np.number)):
        return ConstantMaterial(complex(spec))
    if isinstance(spec, str):
        text = spec.strip().replace(" ", "")
        try:
            return ConstantMaterial(complex(text.replace("i", "j")))
        except ValueError:
            pass
    raise MaterialError(f"material: unknown material {spec!r}")


def refractive_index(material: Any, wavelength_nm) -> np.ndarray:
    """``n + ik`` (complex ndarray, ``k >= 0``) of ``material`` at ``wavelength_nm``."""
    return resolve(material).index(np.asarray(wavelength_nm, dtype=np.float64))
