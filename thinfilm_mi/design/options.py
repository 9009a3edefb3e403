"""The side a target's light comes from and the kind of its bound: :data:`SIDES`, :data:`KINDS`.

Each option is one object holding its code; a targets file's string is parsed once
(:func:`thinfilm_mi.design.parsing.parse_choice`) into the object.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from thinfilm_mi.optics.choices import choose

__all__ = ["Side", "Kind", "FRONT", "BACK", "SIDES", "KINDS", "KIND_ALIASES", "as_side"]


class Side(ABC):
    """Where the light comes from: the media it goes between and the order it meets the films."""

    name: str

    @abstractmethod
    def media(self, ambient: np.ndarray, substrate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(n_in, n_out)``: the real float64 index of the medium the light comes
        from and the complex128 index of the exit medium, from the ambient's and
        the substrate's indices."""

    @abstractmethod
    def order(self, count: int) -> list[int]:
        """The films (indices from the ambient side) in the order the light meets them."""

    @abstractmethod
    def depths(self, depth: np.ndarray, thickness) -> np.ndarray:
        """A depth below a film's ambient side as the depth below its side the light meets first."""

    @abstractmethod
    def describe(self) -> str:
        """What a table appends to a target's description (``""`` for the front)."""

    @abstractmethod
    def front_order(self, arrays: tuple, perm: np.ndarray, axis: int) -> tuple:
        """``arrays`` of derivatives whose ``axis`` runs over the films in the order
        the light meets them, in the front order (``perm``, the identity for the front)."""

    def check(self, substrate_absorbs: str | None, fail) -> None:
        """Call ``fail(message)`` when this side cannot be lit (the substrate absorbs)."""


class _Front(Side):
    """Light from the ambient medium (the default)."""

    name = "front"

    def media(self, ambient, substrate):
        return ambient.real.astype(np.float64), substrate.astype(np.complex128)

    def order(self, count):
        return list(range(count))

    def depths(self, depth, thickness):
        return depth

    def front_order(self, arrays, perm, axis):
        return arrays

    def describe(self):
        return ""


class _Back(Side):
    """Light from the substrate, which must then not absorb."""

    name = "back"

    def media(self, ambient, substrate):
        return substrate.real.astype(np.float64), ambient.real.astype(np.complex128).astype(np.complex128)

    def order(self, count):
        return list(range(count))[::-1]

    def depths(self, depth, thickness):
        return thickness - depth

    def front_order(self, arrays, perm, axis):
        return tuple(np.take(a, perm, axis=axis) for a in arrays)

    def describe(self):
        return "from the substrate"

    def check(self, substrate_absorbs, fail):
        if substrate_absorbs:
            fail(f"side: back needs light coming from the substrate, but {substrate_absorbs}")


FRONT, BACK = _Front(), _Back()
#: The sides by name (the default first).
SIDES: dict[str, Side] = {s.name: s for s in (FRONT, BACK)}


def as_side(value: Any, what: str = "side") -> Side:
    """The :class:`Side` that ``value`` names (an object passes through)."""
    return value if isinstance(value, Side) else choose(SIDES, value, what)


class Kind(ABC):
    """How a target's value bounds what is achieved: the residuals that count."""

    name: str

    @abstractmethod
    def residuals(self, e: np.ndarray, de):
        """``(e, de)`` with the residuals that do not count set to 0 (``de`` may be ``None``)."""

    @abstractmethod
    def draw(self, ax, wavelengths, value, tolerance, color) -> None:
        """Mark the target's values and tolerance on a spectra plot (matplotlib ``ax``)."""


class _Equal(Kind):
    """``=``: every deviation counts."""

    name = "="

    def residuals(self, e, de):
        return e, de

    def draw(self, ax, wavelengths, value, tolerance, color):
        ax.errorbar(wavelengths, value, yerr=tolerance, fmt="none", ecolor=color, alpha=0.5, lw=0.8)


class _Bound(Kind):
    """A one-sided bound: only the residuals ``e`` with ``counts(e, 0)`` count; the
    bound is drawn at ``value + sign * tolerance``."""

    def __init__(self, name: str, counts, sign: float, marker: str):
        self.name, self.counts, self.sign, self.marker = name, counts, sign, marker

    def residuals(self, e, de):
        active = self.counts(e, 0)
        return np.where(active, e, 0.0), None if de is None else de * active[..., None]

    def draw(self, ax, wavelengths, value, tolerance, color):
        ax.plot(wavelengths, value, ls="none", marker=self.marker, ms=4, color=color)
        ax.plot(wavelengths, value + self.sign * tolerance, ls=":", color=color, lw=0.8)


#: The kinds by name (the default first): ``<=`` counts only values above the
#: wanted one, ``>=`` only those below it.
KINDS: dict[str, Kind] = {k.name: k for k in (_Equal(), _Bound("<=", np.greater, 1.0, "v"),
                                                  _Bound(">=", np.less, -1.0, "^"))}
#: Other spellings users write.
KIND_ALIASES = {"==": "="}
