"""When a :class:`~thinfilm_mi.render.kernel.KernelStack` reads tables (no plugin classes
here): the ``tabulate`` option as objects (:data:`TABULATE_OPTIONS`), the route a
stack takes (:class:`Route`), and the key under which a built table is shared
(:func:`table_key`).

* :data:`AUTO` (``"auto"``, the default): a side is tabulated where a table pays for
  itself (enough films, vectorised variants, no ``thickness`` texture), within the
  budget of a load-time build; a side whose build failed is not tried again.
* :data:`ALWAYS` (``true``): every side with films is tabulated, with
  :data:`~thinfilm_mi.tabulate.policy.REQUESTED_BUDGET_SCALE` times the build budget;
  a side that cannot be is evaluated exactly, with a warning.
* :data:`NEVER` (``false``): every side is evaluated exactly.
"""
from __future__ import annotations

import enum
import hashlib

from thinfilm_mi.render.textures import scalar
from thinfilm_mi.tabulate.policy import REQUESTED_BUDGET_SCALE

__all__ = ["ALWAYS", "AUTO", "NEVER", "TABULATE_OPTIONS", "Route",
           "TabulateOption", "table_key", "tabulate_option"]


class TabulateOption:
    """One value of the ``tabulate`` parameter (see the module). ``builds``: whether
    tables are built at all; ``selective``: whether a side is tabulated only where it
    pays (``"auto"``: its own texel budget, no retry after a failed build);
    ``required``: whether the user asked for tables (an error where none can be, a
    warning where a build fails); ``budget_scale``: the build budget's factor."""

    def __init__(self, name: str, builds: bool, selective: bool, budget_scale: float):
        self.name = name
        self.builds = builds
        self.selective = selective
        self.required = builds and not selective
        self.budget_scale = budget_scale

    def __repr__(self) -> str:
        return f"tabulate={self.name}"


AUTO = TabulateOption("auto", builds=True, selective=True, budget_scale=1.0)
ALWAYS = TabulateOption("true", builds=True, selective=False, budget_scale=REQUESTED_BUDGET_SCALE)
NEVER = TabulateOption("false", builds=False, selective=False, budget_scale=1.0)
#: The ``tabulate`` values a stack accepts (as :meth:`~thinfilm_mi.render.reader.PluginProperties.tabulate`
#: gives them) and their options.
TABULATE_OPTIONS = {"auto": AUTO, True: ALWAYS, False: NEVER}


def tabulate_option(value) -> TabulateOption:
    """The option of a ``tabulate`` value: ``"auto"``, ``True``, ``False`` or an option."""
    if isinstance(value, TabulateOption):
        return value
    if isinstance(value, (bool, str)) and value in TABULATE_OPTIONS:
        return TABULATE_OPTIONS[value]
    raise ValueError(f"tabulate: expected \"auto\", true or false, got {value!r}")


class Route(str, enum.Enum):
    """How a stack's planned sides are evaluated (:meth:`KernelStack.mode`): every one
    from a table, none, or some. A ``str`` enum: it equals its value."""
    TABLE = "table"
    EXACT = "exact"
    MIXED = "mixed"

    @classmethod
    def of(cls, tabled: list) -> "Route":
        """The route of sides of which ``tabled`` read a table."""
        if tabled and all(tabled):
            return cls.TABLE
        return cls.MIXED if any(tabled) else cls.EXACT

    def __str__(self) -> str:
        return self.value


def table_key(media_values, films, settings: tuple) -> str:
    """The key of a table in the caches (and the table store on disk): a SHA-1 of the
    media's values (``media_values``: numpy arrays, in order), the films' ``(thickness,
    incoherent)`` (``films``: the side's ``(index, thickness, incoherent)``, thickness a
    number or an opaque Float) and ``settings`` (what else decides the table), so that
    stacks with identical optics share one."""
    h = hashlib.sha1()
    for v in media_values:
        h.update(v.tobytes())
    h.update(repr([(scalar(d), inc) for _, d, inc in films]).encode())
    h.update(repr(settings).encode())
    return h.hexdigest()
