"""The polarisations of the light a quantity is computed for: the registry :data:`POLARIZATIONS`.

``s`` (TE) and ``p`` (TM) are the two linear components the recursion computes
(:mod:`thinfilm_mi.optics.core` keys its per-component results by their names);
``unpolarized`` light is their average. Each polarisation is one object that knows
the components it averages, how it labels a quantity (``R``, ``Rs``) and how a
table describes it; each component knows its tilted admittance, the one place where
s and p differ in the characteristic matrices of :mod:`thinfilm_mi.design.matrices`.

A user's string (a targets or measurements file, ``polarizations=`` of the colour
report) is parsed once by :func:`as_polarization` (``unpolarised`` and ``u`` are
aliases of ``unpolarized``); everything after that holds the object.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

from thinfilm_mi.optics.choices import choose

__all__ = ["Polarization", "Component", "S", "P", "UNPOLARIZED", "POLARIZATIONS", "ALIASES", "as_polarization"]


class Polarization(ABC):
    """A polarisation of the incident light: ``name``, as files and records write
    it, and ``components``, the linear components whose powers it averages."""

    name: str
    components: tuple["Component", ...]

    @abstractmethod
    def label(self, quantity: str) -> str:
        """The name of ``quantity`` (``"R"``, ``"T"``) in this polarisation: ``R``, ``Rs``."""

    @abstractmethod
    def describe(self) -> str:
        """What a table appends to a quantity's description: ``""`` or ``"s-pol"``."""

    def __repr__(self) -> str:
        return f"<polarization {self.name}>"


class Component(Polarization):
    """A linear component (s or p): its own only component."""

    def __init__(self, name: str):
        self.name = name
        self.components = (self,)

    def label(self, quantity: str) -> str:
        return f"{quantity}{self.name}"

    def describe(self) -> str:
        return f"{self.name}-pol"

    @abstractmethod
    def admittance(self, n, q):
        """The tilted admittance of a medium of index ``n`` and normal index ``q``
        (complex arrays), in the convention of the characteristic matrices."""

    @abstractmethod
    def admittance_derivative(self, n, q, dn, dq):
        """The change of :meth:`admittance` for a change ``dn`` of ``n`` (``dq`` the change of ``q``)."""


class _S(Component):
    """s (TE): the electric field normal to the plane of incidence; admittance ``q``."""

    def admittance(self, n, q):
        return q

    def admittance_derivative(self, n, q, dn, dq):
        return dq


class _P(Component):
    """p (TM): the electric field in the plane of incidence; admittance ``n^2 / q``."""

    def admittance(self, n, q):
        return n * n / q

    def admittance_derivative(self, n, q, dn, dq):
        return 2.0 * n * dn / q - n * n * dq / (q * q)


class _Unpolarized(Polarization):
    """Unpolarised light: the mean of the s and p powers (eq. 5 of the paper)."""

    name = "unpolarized"

    def __init__(self, components: tuple[Component, ...]):
        self.components = components

    def label(self, quantity: str) -> str:
        return quantity

    def describe(self) -> str:
        return ""


S = _S("s")
P = _P("p")
UNPOLARIZED = _Unpolarized((S, P))

#: Every polarisation by name (the default, unpolarized, first).
POLARIZATIONS: dict[str, Polarization] = {p.name: p for p in (UNPOLARIZED, S, P)}
#: Other spellings users write.
ALIASES = {"unpolarised": "unpolarized", "u": "unpolarized"}


def as_polarization(value: Any, what: str = "polarization") -> Polarization:
    """The :class:`Polarization` that ``value`` names (an object passes through);
    :class:`~thinfilm_mi.errors.ThinFilmError` naming ``what`` otherwise."""
    if isinstance(value, Polarization):
        return value
    return choose(POLARIZATIONS, value, what, ALIASES)
