"""The sheared wavenumber axis of band-limited tables: ``ν' = ν P(sin²θ)``.

A stack's interference orders sit where ``ν Σ_j d_j q_j(θ)`` takes fixed values,
``q_j = Re sqrt(n_j² - n_0² sin²θ)`` (the films' normal wave numbers over ``ν``): as
the angle grows they move to larger ``ν`` together, by up to ~20 % at grazing
incidence for the benchmark stacks. On the plain (angle, wavenumber) grid every
fringe and resonance of ``R_σ`` therefore runs diagonally, and a cubic along the
angle needs hundreds of rows to follow it (385 for the 30-film benchmark stack at
1e-3). In the coordinate

    ν' = ν P(s),   s = sin²θ,   P(s) ≈ Σ_j d_j q_j(θ) / Σ_j d_j Re n_j

they run along the angle axis instead: measured on the benchmark stacks, a cubic
through 65 rows errs by 5e-4 (30 films; 0.28 unsheared) and 129 rows by 1.3e-4
(10 films; 9e-3 unsheared).

``P`` is a cubic in ``s`` fitted to that ratio at 550 nm (:meth:`Shear.of`). It is a
choice of coordinates, not an approximation: the build evaluates ``R_σ`` at the
wavenumbers ``ν'_t / P(s)`` of its nodes and the lookup computes the same ``ν'``
from the same coefficients, so how well ``P`` follows the films only decides how
many rows the table needs. The axis covers ``ν'`` from ``low = σ_min P_min`` to
``σ_max`` (360 nm at ``s = 0``), with ``P_min`` the least ``P`` on ``[0, 1]``.
"""
from __future__ import annotations

import math

import numpy as np

from thinfilm_mi.tabulate.base import SIGMA_MAX, SIGMA_MIN, opaque_float

__all__ = ["MIN_FACTOR", "REFERENCE_WAVELENGTH", "Shear"]

#: The wavelength (nm) of the indices ``P`` is fitted at.
REFERENCE_WAVELENGTH = 550.0
#: Stacks whose ``P`` would fall below this on ``[0, 1]`` (films of index near or
#: below the ambient's, where ``q_j`` vanishes) keep the plain axis.
MIN_FACTOR = 0.5


def _range(coeffs) -> tuple[float, float]:
    """The least and the largest ``P`` on ``[0, 1]`` (on 257 points; between them a
    lookup falls within the table's ghost nodes)."""
    p = np.polynomial.polynomial.polyval(np.linspace(0.0, 1.0, 257), coeffs)
    return (float(p.min()), float(p.max())) if np.all(np.isfinite(p)) else (math.nan, math.nan)


class Shear:
    """``ν' = ν P(s)`` with ``P(s) = c0 + c1 s + c2 s² + c3 s³`` (``coeffs``) and the
    table's v axis from ``σ_max`` down to ``low`` (its node ``nv - 1``)."""

    def __init__(self, coeffs, low: float):
        self.coeffs = tuple(float(c) for c in coeffs)
        self.low = float(low)
        self._opaque = None

    @classmethod
    def of(cls, films, n0: complex) -> "Shear | None":
        """The shear of ``films`` (pairs ``(index function of λ, thickness)``, the
        coherent films) under an ambient of index ``n0``, or ``None`` where none helps
        (no films, or ``P`` below :data:`MIN_FACTOR`)."""
        if not films:
            return None
        wl = np.array([REFERENCE_WAVELENGTH])
        n = np.array([complex(np.asarray(f(wl))[0]) for f, _ in films])
        d = np.array([float(t) for _, t in films])
        n0r = float(np.real(n0))
        total = float(np.sum(d * n.real))
        if total <= 0:
            return None
        s = 0.5 - 0.5 * np.cos(np.pi * (np.arange(33) + 0.5) / 33)     # Chebyshev points on [0, 1]
        q = np.sqrt((n[None, :] ** 2 - (n0r * n0r) * s[:, None]).astype(np.complex128)).real
        ratio = (q * d[None, :]).sum(axis=1) / total
        coeffs = np.polynomial.polynomial.polyfit(s, ratio, 3)
        low, _ = _range(coeffs)
        if not np.isfinite(low) or low < MIN_FACTOR:
            return None
        return cls(coeffs, SIGMA_MIN * low)

    @property
    def min_factor(self) -> float:
        """``P_min``: the least ``P`` on ``[0, 1]`` (``low / σ_min``)."""
        return self.low / SIGMA_MIN

    @property
    def max_factor(self) -> float:
        """The largest ``P`` on ``[0, 1]`` (1 at normal incidence, to the fit)."""
        return _range(self.coeffs)[1]

    def factor_np(self, s: np.ndarray) -> np.ndarray:
        """``P(s)`` (float64 numpy)."""
        return np.polynomial.polynomial.polyval(np.asarray(s, np.float64), self.coeffs)

    def factor(self, sin_i):
        """``P(sin_i²)`` in a render kernel (opaque coefficients: another stack's shear
        reuses the kernel)."""
        if self._opaque is None:
            self._opaque = [opaque_float(c) for c in self.coeffs]
        c0, c1, c2, c3 = self._opaque
        s = sin_i * sin_i
        return c0 + s * (c1 + s * (c2 + s * c3))

    def node_wavenumbers(self, t: np.ndarray, nv: int) -> np.ndarray:
        """``ν'`` of the v node coordinates ``t`` of an axis of ``nv`` nodes."""
        return SIGMA_MAX - np.asarray(t, np.float64) * ((SIGMA_MAX - self.low) / (nv - 1))

    def to_plain(self) -> dict:
        return {"coeffs": list(self.coeffs), "low": self.low}

    @classmethod
    def from_plain(cls, data: dict) -> "Shear":
        coeffs, low = data["coeffs"], data["low"]
        if len(coeffs) != 4 or not all(np.isfinite(coeffs)) or not 0 < low < SIGMA_MAX:
            raise ValueError(f"not a shear: {data!r}")
        return cls(coeffs, low)
