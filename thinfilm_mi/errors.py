"""Exceptions of thinfilm-mi (the base layer: every other layer may raise them).

Two families:

* :class:`ThinFilmError` (a ValueError): bad thin-film input (a stack, a layer
  list, a material, a plugin parameter). It names the parameter and the
  offending value, so a scene that fails to load says why.
* :class:`RenderError`: what loading, rendering and writing a scene, and a
  sweep, raise (the batch layer, :mod:`thinfilm_mi.batch`), told in one line.
  :class:`UsageError` is a bad scene file, parameter, argument or set-up;
  :class:`RenderFailure` a failure while rendering or writing the output.
  :class:`MissingExtra` (a UsageError and an ImportError) is an optional
  dependency that is not installed; its message names the extra to install.

:func:`plugin_boundary` is where a plugin's name joins an error: every plugin's
constructor and parameter update run inside it, so what they call names only the
parameter and the value.

The library never exits: the command line (:func:`thinfilm_mi.cli.parser.exit_code`)
maps these classes to exit statuses, in one place.
"""
from __future__ import annotations

import importlib
from collections.abc import Iterator
from contextlib import contextmanager
from types import ModuleType

__all__ = [
    "ThinFilmError", "MaterialError", "RenderError", "UsageError", "RenderFailure", "MissingExtra",
    "plugin_boundary", "require_extra",
]


class ThinFilmError(ValueError):
    """Bad thin-film input (stack, layer list, parameter)."""


class MaterialError(ThinFilmError):
    """An unknown material, an unreadable dataset, or an index outside its range."""


class RenderError(Exception):
    """An error of loading, rendering or writing a scene (or a sweep), told in one line."""


class UsageError(RenderError):
    """A bad scene file, parameter, argument or machine set-up (the command exits with 2)."""


class RenderFailure(RenderError):
    """The scene loaded, but rendering or writing the output failed (the command exits with 1)."""


class MissingExtra(UsageError, ImportError):
    """An optional dependency is not installed; the message says which extra installs it."""


def require_extra(module: str, extra: str, purpose: str) -> ModuleType:
    """Import ``module``, an optional dependency of the ``extra`` of
    ``pyproject.toml``; raise :class:`MissingExtra` saying what needs it
    (``purpose``) and how to install it when it cannot be imported."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        raise MissingExtra(f"{purpose} needs {module.partition('.')[0]}, which is not installed: "
                           f"pip install 'thinfilm-mi[{extra}]'") from e


@contextmanager
def plugin_boundary(plugin: str) -> Iterator[None]:
    """Run a plugin's constructor or parameter update: a ``ValueError`` (every
    :class:`ThinFilmError`) or ``TypeError`` raised inside leaves with ``"{plugin}: "``
    in front of its message, once (a message that already starts so is left as it is),
    as the same exception object."""
    try:
        yield
    except (ValueError, TypeError) as e:
        prefix = f"{plugin}: "
        if len(e.args) == 1 and isinstance(e.args[0], str) and not e.args[0].startswith(prefix):
            e.args = (prefix + e.args[0],)
        raise
