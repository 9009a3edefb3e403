"""The ``mi.traverse`` key a sweep's ``-P`` names (:mod:`thinfilm_mi.batch.sweeps`).

A ``-P`` key is taken, in order, as

- the key itself (``teapot.bsdf.layers.0.thickness``);
- a shape's path to a BSDF that has its own ``id``: ``mi.traverse`` names such a
  BSDF by that id (``<bsdf id="silver">`` referenced by ``<shape id="teapot">``
  gives ``silver.layers.0.thickness``), and ``teapot.bsdf.layers.0.thickness``
  names it too;
- the end of exactly one key, whole components (``bsdf.layers.0.thickness``
  when only one object has it), said on stderr with the key it chose.

An object without an ``id`` gets a name from Mitsuba (``object_<number>``) that
changes with every load: the messages say so and how to give it one. A key that
names nothing, or the end of several keys, is a
:class:`~thinfilm_mi.errors.UsageError` that lists what comes close.
"""
from __future__ import annotations

import difflib
import re
from typing import Iterable, Mapping, Sequence

from thinfilm_mi.errors import UsageError

__all__ = ["ParameterNames", "parameter_names", "resolve_all", "is_generated_name", "MAX_LISTED"]

#: how many candidate keys an error lists at most
MAX_LISTED = 6

#: the name ``mi.traverse`` gives an object without an ``id`` (with the ``_N`` it adds to a repeated name)
_GENERATED = re.compile(r"(?:object|_unnamed)_\d+(?:_\d+)?")


def is_generated_name(component: str) -> bool:
    """Whether a key's first component is a name Mitsuba made up for an object without an ``id``."""
    return _GENERATED.fullmatch(component) is not None


def _suffixes(name: str) -> Iterable[str]:
    """``a.b.c`` -> ``a.b.c``, ``b.c``, ``c``: the ends of a key, whole components."""
    parts = name.split(".")
    return (".".join(parts[i:]) for i in range(len(parts)))


class ParameterNames:
    """The names a ``-P`` key may take on one loaded scene.

    ``keys``: the scene's ``mi.traverse`` keys. ``shapes``: ``(shape id, BSDF id)``
    of each shape whose BSDF has its own id. ``holders``: for a generated first
    component, the object's class and XML element (``("PLYMesh", "shape")``), for the messages.
    """

    def __init__(self, keys: Iterable[str], shapes: Iterable[tuple[str, str]] = (),
                 holders: Mapping[str, tuple[str, str]] | None = None):
        self.keys = list(keys)
        self.holders = dict(holders or {})
        by_object: dict[str, list[str]] = {}
        for key in self.keys:
            if "." in key:  # a scene's own parameters (allow_thread_reordering) have none
                by_object.setdefault(key.split(".", 1)[0], []).append(key)
        self.aliases: dict[str, str] = {}
        for shape_id, bsdf_id in shapes:
            if shape_id and bsdf_id and shape_id != bsdf_id:
                for key in by_object.get(bsdf_id, ()):
                    self.aliases[f"{shape_id}.bsdf.{key.split('.', 1)[1]}"] = key
        self.objects = set(by_object) | {a.split(".", 1)[0] for a in self.aliases}
        self.owners: dict[str, set[str]] = {}
        for name, key in [(k, k) for k in self.keys] + list(self.aliases.items()):
            for end in _suffixes(name):
                self.owners.setdefault(end, set()).add(key)

    def resolve(self, name: str) -> tuple[str, str | None]:
        """The key ``name`` stands for and, unless it is that key, a line saying which
        key was chosen; a :class:`UsageError` when it names none or several."""
        if name in self.keys:
            return name, None
        if name in self.aliases:
            key = self.aliases[name]
            return key, (f"-P {name}: taken as {key} (the shape's BSDF has its own id, "
                         f"{key.split('.', 1)[0]}, which names it in mi.traverse)")
        found = sorted(self.owners.get(name, ()))
        if len(found) == 1:
            return found[0], f"-P {name}: taken as {found[0]}, the only parameter ending so{self._no_id(found)}"
        if found:
            listed = ", ".join(found[:MAX_LISTED]) + (", ..." if len(found) > MAX_LISTED else "")
            raise UsageError(f"-P {name}: {len(found)} parameters of the scene end so ({listed}); "
                             f"give more of the key{self._no_id(found)}")
        raise UsageError(f"-P {name}: not a parameter of the scene (see mi.traverse){self._hint(name)}")

    def _generated(self, key: str) -> bool:
        return is_generated_name(key.split(".", 1)[0])

    def readable(self, key: str) -> str:
        """``key``, or for an object without an id the rest of it when that names it alone."""
        rest = key.split(".", 1)[-1]
        return rest if self._generated(key) and self.owners.get(rest) == {key} else key

    def _no_id(self, keys: Sequence[str]) -> str:
        """What to say when the first of ``keys`` whose object has no id names the
        object by Mitsuba's made-up name (nothing when every object has an id)."""
        key = next((k for k in keys if self._generated(k)), None)
        if key is None:
            return ""
        first, _, rest = key.partition(".")
        what, tag = self.holders.get(first, ("object", "..."))
        return (f" ({first} is a {what} without an id, named anew at every load: give it one in the "
                f"scene's XML, <{tag} ... id=\"NAME\">, and name the parameter NAME.{rest})")

    def _hint(self, name: str) -> str:
        """What comes close to a ``name`` that names nothing."""
        first, _, rest = name.partition(".")
        near = sorted(self.owners.get(rest, ())) if rest else []
        if near and first not in self.objects:
            meant = rest if len(near) == 1 else ", ".join(near[:MAX_LISTED])
            return f": no object has the id {first!r}; did you mean {meant}?{self._no_id(near)}"
        depth = name.count(".") + 1
        shown = {**{self.readable(k): k for k in self.keys}, **self.aliases}
        for end, keys in self.owners.items():
            if end.count(".") + 1 == depth and len(keys) == 1:
                shown.setdefault(end, next(iter(keys)))
        close = difflib.get_close_matches(name, list(shown), n=3, cutoff=0.6)
        return f"; did you mean {', '.join(close)}?{self._no_id([shown[c] for c in close])}" if close else ""


def parameter_names(scene, params) -> ParameterNames:
    """The :class:`ParameterNames` of a loaded scene and its ``mi.traverse`` parameters."""
    shapes = [(s.id(), s.bsdf().id()) for s in scene.shapes() if s.bsdf() is not None]
    holders = {}
    for key in params.keys():
        first = key.split(".", 1)[0]
        if first not in holders and is_generated_name(first):
            holders[first] = _holder(params, key)
    return ParameterNames(params.keys(), shapes, holders)


#: the XML element of each kind of scene object (for the messages)
_ELEMENTS = ("Shape", "BSDF", "Emitter", "Sensor", "Texture", "Medium", "Integrator", "Film", "Sampler")


def _holder(params, key: str) -> tuple[str, str]:
    """The class and the XML element of the scene's child that holds ``key``
    (``("PLYMesh", "shape")``), from the traversal's record of each object's parent."""
    import mitsuba as mi

    node = params.properties[key][2]
    parent, depth = params.hierarchy.get(node, (None, 0))
    while depth > 1 and parent is not None:
        node = parent
        parent, depth = params.hierarchy.get(node, (None, 0))
    tag = next((t.lower() for t in _ELEMENTS if isinstance(node, getattr(mi, t))), "...")
    return node.class_name(), tag


def resolve_all(names: ParameterNames, given: Sequence[str]) -> tuple[dict[str, str], list[str]]:
    """Each ``-P`` name's key, and the lines saying which were not keys themselves;
    two names that stand for one key are a :class:`UsageError`."""
    keys, notes, by_key = {}, [], {}
    for name in given:
        key, note = names.resolve(name)
        if key in by_key:
            raise UsageError(f"-P {by_key[key]} and -P {name} both name {key}")
        keys[name], by_key[key] = key, name
        if note:
            notes.append(note)
    return keys, notes
