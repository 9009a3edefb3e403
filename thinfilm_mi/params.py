"""Validation of edits made through ``mi.traverse`` (no plugin classes here).

A thin-film BSDF's parameters can be changed after load (``params[key] = v;
params.update()``); Mitsuba writes the new values into the objects first and then
calls ``parameters_changed``. :class:`ParameterGuard` checks every traversed
value of the BSDF there, with the same ranges the plugins enforce at load time
(:data:`RULES`). On a bad value it writes the last valid values back (the
BSDF's textures are notified again) and raises :class:`ThinFilmError` naming the
key and the value, so a rejected edit never leaves a black or NaN BSDF behind.
"""
from __future__ import annotations

import math
import re

import drjit as dr
import numpy as np

from .errors import ThinFilmError
from .materials import MAX_INDEX, MIN_INDEX
from .textures import _mi, texture_range

#: Largest microfacet roughness accepted (``alpha``, ``alpha_u``, ``alpha_v``):
#: beyond ~1 a Beckmann/GGX surface is already near-uniform; 100 leaves room
#: while keeping the distribution's terms in float32 range.
MAX_ALPHA = 100.0
#: Tolerance on a diffuse albedo's upper bound of 1 (sRGB white upsampled to a
#: spectrum peaks a hair above 1).
ALBEDO_SLACK = 1e-3

#: (pattern on the key relative to the BSDF, lower bound, lower bound excluded,
#: upper bound, what the value is, read as one channel). The first match decides;
#: every other key must only be finite. Keys of a texture are checked on the
#: texture's values (:func:`thinfilm_mi.textures.texture_range`), not on its raw
#: parameters: an RGB spectrum's or a bitmap's stored coefficients may be negative.
RULES = [
    (r"^layers\.\d+\.thickness$", 0.0, False, math.inf, "a film thickness (nm)", False),
    (r"^(layers\.\d+\.)?eta\.", MIN_INDEX, False, MAX_INDEX, "a refractive index n", False),
    (r"^(layers\.\d+\.)?k\.", 0.0, False, MAX_INDEX, "an extinction coefficient k", False),
    (r"^alpha(_u|_v)?\.", 0.0, True, MAX_ALPHA, "a roughness", True),
    (r"^specular_(reflectance|transmittance)\.", 0.0, False, math.inf, "a factor", False),
    (r"^reflectance\.", 0.0, False, 1.0 + ALBEDO_SLACK, "an albedo", False),
    (r"^thickness\.", 0.0, False, math.inf, "a thickness scale", True),
]


def _values(value) -> np.ndarray | None:
    """The numbers of a traversed value as float64, or ``None`` for non-numeric ones."""
    try:
        if dr.is_array_v(value):
            value = dr.detach(value)
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return arr.ravel()


def _shown(arr: np.ndarray, what: str = "an array") -> str:
    """The value(s) as stored (float32: 7 significant digits)."""
    bad = arr[~np.isfinite(arr)]
    if arr.size == 1 or (not bad.size and arr.min() == arr.max()):
        return f"{arr[0]:.7g}"
    if bad.size:
        return f"{what} holding {bad[0]:.7g}"
    return f"{what} with values in [{arr.min():.7g}, {arr.max():.7g}]"


def check_value(key: str, value, plugin: str, texture=None) -> None:
    """:class:`ThinFilmError` naming ``key`` and the value unless it is finite and
    within the range :data:`RULES` gives for ``key``; with ``texture`` (the object
    that owns the key), the texture's values are checked instead of ``value``."""
    lo, lo_open, hi, what, mono = -math.inf, False, math.inf, "a value", False
    for pattern, a, a_open, b, w, m in RULES:
        if re.search(pattern, key):
            lo, lo_open, hi, what, mono = a, a_open, b, w, m
            break
    if texture is not None:
        rng = texture_range(texture, mono)
        arr = None if rng is None else np.asarray(rng, dtype=np.float64)
    else:
        arr = _values(value)
    if arr is None or arr.size == 0:
        return
    finite = bool(np.all(np.isfinite(arr)))
    if finite and arr.min() >= lo and not (lo_open and arr.min() <= lo) and arr.max() <= hi:
        return
    parts = []
    if math.isfinite(lo):
        parts.append(f"{'>' if lo_open else '>='} {lo:g}")
    if math.isfinite(hi):
        parts.append(f"<= {hi:g}")
    want = "finite" + (" and " + " and ".join(parts) if parts else "")
    shown = _shown(arr, "an array" if texture is None else "a texture")
    raise ThinFilmError(f"{plugin}: '{key}' ({what}) must be {want}, got {shown}; "
                        "the edit was undone and the BSDF keeps its last valid parameters")


def _copy(value):
    """A snapshot of a traversed value that later in-place writes do not change."""
    return type(value)(dr.detach(value)) if dr.is_array_v(value) else value


class ParameterGuard:
    """Keeps the last valid traversed values of a BSDF and checks every edit.

    Create it at the end of the constructor; call :meth:`changed` from
    ``parameters_changed`` with the BSDF and the function that refreshes its
    state. (It keeps no reference to the BSDF: no reference cycle.)
    """

    def __init__(self, bsdf, plugin: str):
        self.plugin = plugin
        self._restoring = False
        params = _mi().traverse(bsdf)
        self._valid = {k: _copy(params[k]) for k in params.keys()}

    def changed(self, bsdf, refresh, keys=None) -> None:
        """Validate the current values of ``bsdf`` (those under the changed
        ``keys`` that ``parameters_changed`` received; all without), then
        ``refresh()``; on a bad value (or a failing refresh) restore the last valid
        values and raise."""
        if self._restoring:
            refresh()
            return
        mi = _mi()
        params = mi.traverse(bsdf)
        try:
            seen = set()
            for key in params.keys():
                if keys and not any(key == k or key.startswith(k + ".") for k in keys):
                    continue
                node = params.properties[key][2]
                texture = node if isinstance(node, mi.Texture) else None
                if texture is not None:
                    if id(texture) in seen:
                        continue
                    seen.add(id(texture))
                check_value(key, params[key], self.plugin, texture)
            refresh()
        except Exception:
            self._restore(params)
            raise
        self._valid = {k: _copy(params[k]) for k in params.keys()}

    def _restore(self, params) -> None:
        self._restoring = True
        try:
            for key, value in self._valid.items():
                if key in params.keys():
                    params[key] = value
            params.update()
        finally:
            self._restoring = False
