"""One lookup for every registry of options: a user's string to the object it names.

A variation point of the package is a registry, a dict of name -> object, each
option's code in its own class (as colour-science keeps ``DELTA_E_METHODS`` and
``validate_method``). :func:`choose` is the one place where a user's string is
compared with the names: case-insensitively, after the registry's aliases; a
string that names nothing raises :class:`~thinfilm_mi.errors.ThinFilmError`
naming the parameter, the value and the choices.
"""
from __future__ import annotations

from typing import Any, Mapping, TypeVar

from thinfilm_mi.errors import ThinFilmError

__all__ = ["choose"]

T = TypeVar("T")


def choose(registry: Mapping[str, T], value: Any, what: str, aliases: Mapping[str, str] | None = None) -> T:
    """The entry of ``registry`` that ``value`` names (``str(value)`` stripped;
    case-insensitive; ``aliases`` maps other lower-case spellings to names).
    Otherwise :class:`ThinFilmError` ``"{what}: expected one of A, B, C, got 'x'"``."""
    text = str(value).strip()
    key = (aliases or {}).get(text.lower(), text).lower()
    for name, entry in registry.items():
        if key == name.lower():
            return entry
    raise ThinFilmError(f"{what}: expected one of {', '.join(registry)}, got {value!r}")
