"""Dispersion formulas: the index ``n`` of a material from a few coefficients, the one
implementation behind refractiveindex.info files (``type: formula N``) and the fit's
dispersion models (:mod:`thinfilm_mi.design.dispersion`).

:data:`FORMULAS` is the registry, by refractiveindex.info's formula number, one class
per formula (the two Sellmeier conventions are one class, :class:`Sellmeier`).
Conventions, as refractiveindex.info writes them: λ is the vacuum wavelength in µm;
``C1, C2, ...`` are the coefficients in the order the file lists them; a coefficient
the file leaves out counts as 0, one past the formula's last is ignored. The
definitions are those of the database's "Dispersion formulas" document
(``database/doc/Dispersion formulas.pdf`` of polyanskiy/refractiveindex.info-database),
as the site writes them out per page (its dispersion calculator prints Malitson's fused
silica, formula 1, as ``sqrt(1 + 0.6961663 x²/(x² - 0.0684043²) + ...)``, the poles
squared) and as the ``refractiveindex`` package (version 1.3.1) evaluates them:

====  =================  ==========================================================================
  1   Sellmeier          ``n² - 1 = C1 + Σ C(2j) λ² / (λ² - C(2j+1)²)``  (poles as wavelengths, µm)
  2   Sellmeier-2        ``n² - 1 = C1 + Σ C(2j) λ² / (λ² - C(2j+1))``   (poles squared, µm²)
  3   Polynomial         ``n² = C1 + Σ C(2j) λ^C(2j+1)``
  4   RefractiveIndex.   ``n² = C1 + C2 λ^C3/(λ² - C4^C5) + C6 λ^C7/(λ² - C8^C9)
      INFO               + Σ_{j>=5} C(2j) λ^C(2j+1)``
  5   Cauchy             ``n = C1 + Σ C(2j) λ^C(2j+1)``
  6   Gases              ``n - 1 = C1 + Σ C(2j) / (C(2j+1) - λ⁻²)``
  7   Herzberger         ``n = C1 + C2/(λ² - 0.028) + C3/(λ² - 0.028)² + C4 λ² + C5 λ⁴ + C6 λ⁶``
  8   Retro              ``(n² - 1)/(n² + 2) = C1 + C2 λ²/(λ² - C3) + C4 λ²``
  9   Exotic             ``n² = C1 + C2/(λ² - C3) + C4 (λ - C5)/((λ - C5)² + C6)``
====  =================  ==========================================================================

Where a formula gives ``n² <= 0`` (at or inside a resonance) there is no real index:
``n`` is NaN there, which a material refuses (naming the wavelength) and a fit's
optimiser answers with a shorter step. :class:`DifferentiableFormula` adds the
derivatives of ``n`` with respect to every coefficient, which the fit chains its
Jacobian through.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, Sequence

import numpy as np

from thinfilm_mi.errors import MaterialError

__all__ = ["Formula", "DifferentiableFormula", "Sellmeier", "Polynomial", "RefractiveIndexInfo", "Cauchy",
           "Gases", "Herzberger", "Retro", "Exotic", "FORMULAS", "formula_by_number"]

Coefficients = Sequence[float]


def _padded(c: Coefficients, count: int) -> list[float]:
    """``c`` as floats, with zeros for the coefficients up to ``count`` it leaves out."""
    return [float(x) for x in c] + [0.0] * max(0, count - len(c))


def _pairs(c: Coefficients) -> list[tuple[float, float]]:
    """``(C2, C3), (C4, C5), ...``: the terms' coefficient pairs (a last one alone with 0)."""
    c = [float(x) for x in c]
    return [(c[i], c[i + 1] if i + 1 < len(c) else 0.0) for i in range(1, len(c), 2)]


def _series(terms, shape) -> np.ndarray:
    """``Σ terms``, summed first (then added to the formula's constant), 0 without terms."""
    return sum(terms, np.zeros(shape))


def _power_series(c: Coefficients, lam: np.ndarray) -> np.ndarray:
    """``C1 + Σ C(2j) λ^C(2j+1)``: Cauchy's ``n``, the polynomial's ``n²``."""
    return _padded(c, 1)[0] + _series((a * lam ** e for a, e in _pairs(c)), lam.shape)


def _root(n2: np.ndarray) -> np.ndarray:
    """``n`` from ``n²``: NaN where ``n² <= 0`` (no real index)."""
    return np.sqrt(np.where(n2 > 0, n2, np.nan))


class Formula(ABC):
    """A refractiveindex.info dispersion formula: ``number``, ``name`` and ``definition``
    (the formula as written above) and :meth:`n`."""

    number = 0
    name = ""
    definition = ""

    def n(self, c: Coefficients, lam_um) -> np.ndarray:
        """``n`` at the wavelengths ``lam_um`` (µm) for the coefficients ``c`` (``C1, C2, ...``)."""
        lam = np.asarray(lam_um, dtype=np.float64)
        with np.errstate(all="ignore"):
            return self._n(c, lam)

    @abstractmethod
    def _n(self, c: Coefficients, lam: np.ndarray) -> np.ndarray:
        """The formula itself (floating-point errors are silenced by :meth:`n`)."""

    def __repr__(self) -> str:
        return f"<formula {self.number} ({self.name}): {self.definition}>"


class DifferentiableFormula(Formula):
    """A formula that also gives ``dn/dC`` for every coefficient (what a fit frees)."""

    def n_and_gradient(self, c: Coefficients, lam_um) -> tuple[np.ndarray, np.ndarray]:
        """``(n (P,), dn/dC (P, len(c)))`` at ``lam_um`` (µm, shape ``(P,)``)."""
        lam = np.asarray(lam_um, dtype=np.float64)
        with np.errstate(all="ignore"):
            return self._n_and_gradient([float(x) for x in c], lam)

    @abstractmethod
    def _n_and_gradient(self, c: list[float], lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The formula and its gradient (floating-point errors silenced by :meth:`n_and_gradient`)."""


class Sellmeier(DifferentiableFormula):
    """``n² - 1 = C1 + Σ B_j λ² / (λ² - P_j)``, each pole ``P_j`` in µm² (the square of
    the resonance wavelength), amplitudes ``B_j = C2, C4, ...``.

    refractiveindex.info writes the pole two ways, one instance each: formula 1
    (``squared_poles=False``) gives the resonance wavelength ``C(2j+1)`` in µm, ``P_j =
    C(2j+1)²``; formula 2 (``squared_poles=True``) gives ``P_j = C(2j+1)`` in µm² itself,
    as SCHOTT's and Zemax's "Sellmeier 1" catalogues do (N-BK7: ``C1 = 0.00600069867``
    µm²) and as the fit's ``sellmeier`` model's ``C1, C2, C3`` are."""

    def __init__(self, number: int, name: str, squared_poles: bool):
        self.number, self.name, self.squared_poles = number, name, squared_poles
        pole = "C(2j+1)" if squared_poles else "C(2j+1)²"
        self.definition = f"n² - 1 = C1 + Σ C(2j) λ² / (λ² - {pole})"

    def _pole(self, c: float) -> float:
        return c if self.squared_poles else c * c

    def _n(self, c, lam):
        l2 = lam * lam
        n2 = 1.0 + _padded(c, 1)[0] + _series((b * l2 / (l2 - self._pole(p)) for b, p in _pairs(c)), lam.shape)
        return _root(n2)

    def _n_and_gradient(self, c, lam):
        n = self._n(c, lam)
        l2 = lam * lam
        grad = np.zeros(lam.shape + (len(c),))
        grad[..., :1] = 1.0
        for j, (b, p) in enumerate(_pairs(c)):
            pole = self._pole(p)
            grad[..., 2 * j + 1] = l2 / (l2 - pole)
            if 2 * j + 2 < len(c):
                # d(n²)/dP_j, times dP_j/dC(2j+1): 1 for poles in µm², 2 C(2j+1) for wavelengths
                grad[..., 2 * j + 2] = b * l2 / (l2 - pole) ** 2 * (1.0 if self.squared_poles else 2.0 * p)
        return n, grad / (2.0 * n[..., None])


class Polynomial(Formula):
    number, name = 3, "Polynomial"
    definition = "n² = C1 + Σ C(2j) λ^C(2j+1)"

    def _n(self, c, lam):
        return _root(_power_series(c, lam))


class RefractiveIndexInfo(Formula):
    number, name = 4, "RefractiveIndex.INFO"
    definition = "n² = C1 + C2 λ^C3/(λ² - C4^C5) + C6 λ^C7/(λ² - C8^C9) + Σ_{j>=5} C(2j) λ^C(2j+1)"

    def _n(self, c, lam):
        k = _padded(c, 9)
        l2 = lam * lam
        n2 = k[0] + k[1] * lam ** k[2] / (l2 - k[3] ** k[4])
        if len(c) > 5:      # the second resonance, when the file gives it
            n2 = n2 + k[5] * lam ** k[6] / (l2 - k[7] ** k[8])
        for a, e in _pairs(k[8:]):
            n2 = n2 + a * lam ** e
        return _root(n2)


class Cauchy(DifferentiableFormula):
    """``n = C1 + Σ C(2j) λ^C(2j+1)``: the fit's ``cauchy`` model ``n = A + B/λ² + C/λ⁴``
    is ``C1 = A, C2 = B, C3 = -2, C4 = C, C5 = -4``."""

    number, name = 5, "Cauchy"
    definition = "n = C1 + Σ C(2j) λ^C(2j+1)"

    def _n(self, c, lam):
        return _power_series(c, lam)

    def _n_and_gradient(self, c, lam):
        grad = np.zeros(lam.shape + (len(c),))
        grad[..., :1] = 1.0
        for j, (a, e) in enumerate(_pairs(c)):
            power = lam ** e
            grad[..., 2 * j + 1] = power
            if 2 * j + 2 < len(c):
                grad[..., 2 * j + 2] = a * power * np.log(lam)
        return self._n(c, lam), grad


class Gases(Formula):
    number, name = 6, "Gases"
    definition = "n - 1 = C1 + Σ C(2j) / (C(2j+1) - λ⁻²)"

    def _n(self, c, lam):
        return 1.0 + _padded(c, 1)[0] + _series((a / (b - 1.0 / (lam * lam)) for a, b in _pairs(c)), lam.shape)


class Herzberger(Formula):
    number, name = 7, "Herzberger"
    definition = "n = C1 + C2/(λ² - 0.028) + C3/(λ² - 0.028)² + C4 λ² + C5 λ⁴ + C6 λ⁶"

    def _n(self, c, lam):
        k = _padded(c, 6)
        l2 = lam * lam
        d = l2 - 0.028
        return k[0] + k[1] / d + k[2] / (d * d) + k[3] * l2 + k[4] * l2 ** 2 + k[5] * l2 ** 3


class Retro(Formula):
    number, name = 8, "Retro"
    definition = "(n² - 1)/(n² + 2) = C1 + C2 λ²/(λ² - C3) + C4 λ²"

    def _n(self, c, lam):
        k = _padded(c, 4)
        l2 = lam * lam
        x = k[0] + k[1] * l2 / (l2 - k[2]) + k[3] * l2
        return _root((1.0 + 2.0 * x) / (1.0 - x))


class Exotic(Formula):
    number, name = 9, "Exotic"
    definition = "n² = C1 + C2/(λ² - C3) + C4 (λ - C5)/((λ - C5)² + C6)"

    def _n(self, c, lam):
        k = _padded(c, 6)
        d = lam - k[4]
        return _root(k[0] + k[1] / (lam * lam - k[2]) + k[3] * d / (d * d + k[5]))


#: The dispersion formulas by refractiveindex.info's number (``type: formula N``).
FORMULAS: dict[int, Formula] = {f.number: f for f in (
    Sellmeier(1, "Sellmeier", squared_poles=False), Sellmeier(2, "Sellmeier-2", squared_poles=True),
    Polynomial(), RefractiveIndexInfo(), Cauchy(), Gases(), Herzberger(), Retro(), Exotic())}


def formula_by_number(number: Any) -> Formula:
    """The formula numbered ``number``, or :class:`MaterialError` naming it."""
    try:
        return FORMULAS[int(number)]
    except (KeyError, TypeError, ValueError):
        raise MaterialError(f"unknown dispersion formula {number!r} (refractiveindex.info knows "
                            f"{min(FORMULAS)}-{max(FORMULAS)})") from None
