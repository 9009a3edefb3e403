"""Validation of edits made through ``mi.traverse`` (no plugin classes here).

A thin-film BSDF's parameters can be changed after load (``params[key] = v;
params.update()``); Mitsuba writes the new values into the objects first and then
calls ``parameters_changed``. :class:`ParameterGuard` checks there every traversed
value of the BSDF that changed since its last valid state (found by comparing JIT
variables, :func:`unchanged`, so that an edit through ``mi.traverse(scene)`` is
checked as one through ``mi.traverse(bsdf)``), with the same ranges the plugins
enforce at load time (:data:`RULES`). On a bad value it writes the last valid values back (the
BSDF's textures are notified again) and raises :class:`ThinFilmError` naming the
key and the value, so a rejected edit never leaves a black or NaN BSDF behind.
"""
from __future__ import annotations

import math
import re

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError, plugin_boundary
from thinfilm_mi.materials.model import MAX_INDEX, MIN_INDEX
from thinfilm_mi.render.textures import mitsuba_module, texture_range

__all__ = ["ALBEDO_SLACK", "MAX_ALPHA", "MAX_ROUGHNESS", "ParameterGuard", "RULES", "check_value",
           "unchanged"]

#: Largest microfacet roughness accepted (``alpha``, ``alpha_u``, ``alpha_v``):
#: beyond ~1 a Beckmann/GGX surface is already near-uniform; 100 leaves room
#: while keeping the distribution's terms in float32 range.
MAX_ALPHA = 100.0
#: Largest Oren-Nayar ``roughness`` accepted (radians): a slope angle's standard deviation
#: beyond 90° means nothing, and larger values are most likely degrees given by mistake.
MAX_ROUGHNESS = math.pi / 2
#: Tolerance on a diffuse albedo's upper bound of 1 (sRGB white upsampled to a
#: spectrum peaks a hair above 1).
ALBEDO_SLACK = 1e-3

#: (pattern on the key relative to the BSDF, lower bound, lower bound excluded,
#: upper bound, what the value is, read as one channel). The first match decides;
#: every other key must only be finite. Keys of a texture are checked on the
#: texture's values (:func:`thinfilm_mi.render.textures.texture_range`), not on its raw
#: parameters: an RGB spectrum's or a bitmap's stored coefficients may be negative.
RULES = [
    (r"^layers\.\d+\.thickness$", 0.0, False, math.inf, "a film thickness (nm)", False),
    (r"\.wavelengths$", 0.0, True, math.inf, "a spectrum's wavelengths (nm)", False),
    (r"^(layers\.\d+\.)?eta\.", MIN_INDEX, False, MAX_INDEX, "a refractive index n", False),
    (r"^(layers\.\d+\.)?k\.", 0.0, False, MAX_INDEX, "an extinction coefficient k", False),
    (r"^alpha(_u|_v)?\.", 0.0, True, MAX_ALPHA, "a roughness", True),
    (r"^roughness\.", 0.0, False, MAX_ROUGHNESS, "an Oren-Nayar roughness σ (radians)", True),
    (r"^specular_(reflectance|transmittance)\.", 0.0, False, math.inf, "a factor", False),
    (r"^reflectance\.", 0.0, False, 1.0 + ALBEDO_SLACK, "an albedo", False),
    (r"^thickness\.", 0.0, False, math.inf, "a thickness scale", True),
    (r"^coat_sigma_a\.", 0.0, False, math.inf,
     "an absorption coefficient per unit of 'coat_thickness'", False),
    (r"^coat_thickness$", 0.0, False, math.inf, "the coat medium's thickness", False),
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


def check_value(key: str, value, texture=None) -> None:
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
    raise ThinFilmError(f"'{key}' ({what}) must be {want}, got {shown}; "
                        "the edit was undone and the BSDF keeps its last valid parameters")


def _copy(value):
    """A snapshot of a traversed value that later in-place writes do not change."""
    return type(value)(dr.detach(value)) if dr.is_array_v(value) else value


def _jit_ids(value):
    """The JIT variable indices of a Dr.Jit value (detached), ``None`` for other values."""
    if dr.is_jit_v(value):
        return tuple(dr.detail.collect_indices(dr.detach(value)))
    return None


def unchanged(value, snapshot) -> bool:
    """Whether a traversed value is still its snapshot (:func:`_copy`).

    A JIT array is unchanged when it still refers to the snapshot's variables:
    Dr.Jit never writes into a variable that another reference (the snapshot)
    holds, so every assignment or in-place write gives the value new indices,
    and no other value can reuse indices that the snapshot keeps alive. Other
    values (scalar variants) are compared by value (a NaN never equals)."""
    ids = _jit_ids(value)
    if ids is not None or _jit_ids(snapshot) is not None:
        return ids == _jit_ids(snapshot)
    try:
        return bool(np.array_equal(np.asarray(value, dtype=np.float64),
                                   np.asarray(snapshot, dtype=np.float64)))
    except (TypeError, ValueError):
        return value is snapshot


class ParameterGuard:
    """Keeps the last valid traversed values of a BSDF and checks every edit.

    Create it at the end of the constructor; call :meth:`changed` from
    ``parameters_changed`` with the BSDF and the function that refreshes its
    state (it receives the changed keys, see :meth:`changed`): that call is the
    plugin boundary of an edit (:func:`~thinfilm_mi.errors.plugin_boundary` of
    ``plugin``). It keeps no reference to the BSDF: no reference cycle.
    """

    def __init__(self, bsdf, plugin: str):
        self.plugin = plugin
        #: while :meth:`_restore` writes the last valid values back: whether a refresh ran
        #: on the rejected ones (``None``: not restoring)
        self._restoring: bool | None = None
        params = mitsuba_module().traverse(bsdf)
        self._valid = {k: _copy(params[k]) for k in params.keys()}

    def changed(self, bsdf, refresh, keys=None) -> None:
        """Validate the values of ``bsdf`` that changed since the last valid state
        (every value when ``keys`` is ``None``), then ``refresh(changed)`` with
        the keys (relative to the BSDF) of the values that changed, or ``None``
        for "everything may have changed"; on a bad value (or a failing refresh)
        restore the last valid values and raise.

        The keys ``parameters_changed`` receives are not used to find what changed:
        ``mi.traverse(scene)`` passes a BSDF the wrong ones. Its ``set_dirty``
        strips one dotted part per object level, but a BSDF names its films'
        parameters with several parts, so an edit of ``ball.bsdf.layers.1.eta.value``
        reaches the BSDF as ``['eta']`` and one of ``ball.bsdf.layers.1.thickness``
        as ``['thickness']`` (Mitsuba 3.9). Every traversed value is compared with
        the last valid snapshot instead (:func:`unchanged`: a comparison of JIT
        indices, no evaluation), which is the same through a scene or a BSDF.
        """
        with plugin_boundary(self.plugin):
            self._changed(bsdf, refresh, keys)

    def _changed(self, bsdf, refresh, keys) -> None:
        if self._restoring is not None:
            # writing the last valid values back: the BSDF's state is refreshed
            # only if a refresh ran on the rejected values
            if self._restoring:
                refresh(None)
            return
        mi = mitsuba_module()
        params = mi.traverse(bsdf)
        try:
            changed = [key for key in params.keys()
                       if keys is None or key not in self._valid
                       or not unchanged(params[key], self._valid[key])]
            seen = set()
            for key in changed:
                node = params.properties[key][2]
                texture = node if isinstance(node, mi.Texture) else None
                if texture is not None:
                    if id(texture) in seen:
                        continue
                    seen.add(id(texture))
                check_value(key, params[key], texture)
        except Exception:
            # rejected before the refresh: the BSDF's state is still the last valid one
            self._restore(params, refreshed=False)
            raise
        try:
            refresh(None if keys is None else changed)
        except Exception:
            self._restore(params, refreshed=True)
            raise
        self._valid = {k: _copy(params[k]) for k in params.keys()}

    def _restore(self, params, refreshed: bool) -> None:
        """Write the last valid values back (their textures are notified again);
        the BSDF refreshes its state from them only if ``refreshed``."""
        self._restoring = refreshed
        try:
            for key, value in self._valid.items():
                if key in params.keys():
                    params[key] = value
            params.update()
        finally:
            self._restoring = None
