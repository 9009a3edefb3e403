"""Mitsuba textures made and read by the thin-film plugins (no plugin classes here).

* Making: :func:`uniform`, :func:`irregular`, :func:`regular` build Mitsuba's
  spectra through ``mi.PluginManager.create_object`` and never through
  ``mi.load_dict``. ``load_dict`` installs a copy of the global FileResolver
  for its duration and frees it when it returns; under Mitsuba's parallel
  scene loading, plugin constructors run on several threads, and a C++
  plugin (``bitmap``, ``ply``, ``hdrfilm``, or the loading of a plugin
  library) resolving a file name on another thread at that moment reads the
  freed copy: ``std::bad_alloc``, ``basic_string::_M_create`` or a crash.
  ``create_object`` touches no resolver (``tests/cross/test_parallel_load.py``).
* Reading: :func:`texture_on_grid` (a spectrum on a wavelength grid) and
  :func:`texture_range` (smallest and largest value over a texture's spectral
  and spatial domain) at load time; :func:`check_texture_range` turns the
  latter into an error naming the parameter; :func:`property_texture` makes a plugin
  property into a texture.
"""
from __future__ import annotations

import math
import re

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import GRID, SPECTRAL_RANGE

__all__ = ["GRID", "LUMINANCE", "bounds", "check_texture_range", "irregular",
           "mitsuba_module", "new_object", "property_texture", "regular", "scalar", "texture_on_grid",
           "texture_range", "uniform"]


def mitsuba_module():
    import mitsuba as mi
    return mi


def scalar(d) -> float:
    """The first entry of a Dr.Jit value (or a Python number) as a float."""
    return float(dr.ravel(d)[0]) if dr.is_array_v(d) else float(d)


def new_object(plugin: str, **props):
    """A Mitsuba object of the current variant from plain properties, made by the
    plugin manager directly (thread-safe under parallel loading; see the module
    docstring for why not ``mi.load_dict``)."""
    mi = mitsuba_module()
    p = mi.Properties(plugin)
    for k, v in props.items():
        p[k] = v
    return mi.PluginManager.instance().create_object(p)


def uniform(value: float):
    """A ``uniform`` spectrum (its ``value`` is exposed to ``mi.traverse``)."""
    return new_object("uniform", value=float(value))


def irregular(wavelengths, values):
    """An ``irregular`` spectrum: linear interpolation of ``values`` at ``wavelengths``."""
    return new_object("irregular", wavelengths=", ".join(f"{x:.12g}" for x in wavelengths),
                      values=", ".join(f"{x:.9g}" for x in values))


def regular(values, lo: float = GRID[0], hi: float = GRID[-1]):
    """A ``regular`` spectrum: ``values`` equally spaced over ``[lo, hi]`` nm, rounded to
    float32 first, as Mitsuba stores them. (Nine digits of a float64 value parse to the
    float32 next to it only most of the time; written from the float32 value they are that
    value, so a spectrum built here and one updated through ``mi.traverse`` with the same
    values hold the same floats.)"""
    return new_object("regular", wavelength_min=float(lo), wavelength_max=float(hi),
                      values=", ".join(f"{v:.9g}" for v in np.asarray(values, np.float64)
                                       .astype(np.float32)))


def texture_on_grid(tex, wavelengths: np.ndarray = GRID) -> np.ndarray:
    """A Mitsuba spectral texture evaluated at ``wavelengths`` (float64 numpy).

    Evaluated through the texture itself (not its source data), so values edited
    through ``mi.traverse`` are seen exactly as the render kernel sees them. A
    uniform spectrum's one value is read as its mean, without a kernel launch
    (~40 us each; a stack's constant films have two such textures apiece).
    """
    mi = mitsuba_module()
    wl = np.asarray(wavelengths, dtype=np.float64).ravel()
    n = wl.size
    if tex.class_name() == "UniformSpectrum":
        return np.full(n, scalar(tex.mean()))
    if not dr.is_jit_v(mi.Float):   # scalar variants: four wavelengths per call
        si = dr.zeros(mi.SurfaceInteraction3f)
        padded = np.concatenate([wl, np.full((-n) % 4, wl[-1] if n else 500.0)])
        out = []
        for i in range(0, padded.size, 4):
            si.wavelengths = mi.UnpolarizedSpectrum(*[float(x) for x in padded[i:i + 4]])
            out.extend(float(v) for v in tex.eval(si))
        return np.asarray(out[:n], dtype=np.float64)
    from thinfilm_mi.optics.backend import aligned_array

    si = dr.zeros(mi.SurfaceInteraction3f, n)
    # an aligned buffer: Dr.Jit compiles a kernel per alignment of its inputs
    w = aligned_array(wl, np.float32, mi.Float)
    si.wavelengths = mi.UnpolarizedSpectrum(w, w, w, w)
    value = tex.eval(si)
    return np.broadcast_to(np.array(value[0], dtype=np.float64).ravel(), (n,)).copy()


#: Mitsuba's ``luminance()`` of a linear sRGB colour (the Y row of its sRGB-to-XYZ matrix)
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


def _bitmap(tex):
    """``(texels, raw)`` of a ``bitmap`` texture (H x W x C, float32, the values its
    lookups return: an 8- or 16-bit image, which Mitsuba keeps as integers, divided by
    its largest code and, unless ``raw``, taken from sRGB to linear), or ``None`` for
    any other texture."""
    if not tex.class_name().startswith("BitmapTextureImpl"):
        return None
    try:
        data = mitsuba_module().traverse(tex)["data"]
    except Exception:  # noqa: BLE001 - not the bitmap we know
        return None
    stored = np.array(data)
    if stored.ndim != 3:
        return None
    found = re.search(r"\braw = (\d)", str(tex))
    raw = None if found is None else found.group(1) == "1"
    arr = np.asarray(stored, dtype=np.float32)
    if np.issubdtype(stored.dtype, np.integer):
        arr = arr / np.float32(np.iinfo(stored.dtype).max)
        if not raw:
            arr = np.where(arr <= 0.04045, arr / 12.92, ((arr + 0.055) / 1.055) ** 2.4).astype(np.float32)
    return arr, raw


def _texel_range(tex, mono: bool):
    """The range of a ``bitmap`` texture's values read from its texels, exact for
    any ``to_uv``, filter or wrap mode (what it returns is a convex combination of
    texels: bilinear or nearest interpolation), or ``None`` where the texels are not
    the values: another texture, or RGB in spectral variants (stored as coefficients
    of Mitsuba's sRGB upsampling model unless ``raw``; a raw one has no spectrum)."""
    mi = mitsuba_module()
    found = _bitmap(tex)
    if found is None:
        return None
    texels, raw = found
    if texels.shape[2] == 3:
        if mi.is_spectral and not (mono and raw):
            return None
        if mono or mi.is_monochromatic:   # eval_1, and mono variants, read luminance
            texels = texels @ LUMINANCE.astype(np.float32)
    elif texels.shape[2] != 1:
        return None
    if not texels.size:
        return None
    if np.any(np.isnan(texels)):
        return math.nan, math.nan
    return float(np.min(texels)), float(np.max(texels))


def _centred(res: int, at_least: int) -> int:
    """A number of UV samples per axis that hits every texel centre of ``res``
    texels: ``res`` times the smallest odd factor reaching ``at_least``."""
    k = max(1, -(-at_least // res))
    return res * (k + 1 - k % 2)


def texture_range(tex, mono: bool = False):
    """The smallest and largest value of a texture at load time (NaN where some
    value is NaN), or ``None`` if it cannot be evaluated without a shape (e.g.
    ``mesh_attribute``).

    A ``bitmap`` is read from its texels (exact; :func:`_texel_range`) except for
    RGB in spectral variants. Others are evaluated on Mitsuba's spectral grid
    (360-830 nm, 1 nm) and, for a spatially varying texture, at every texel
    centre of its resolution (an odd multiple of it, at least 64 per axis, at
    most 4096; 16 x 16 and a 10 nm grid in scalar variants): exact for a
    spectrally upsampled RGB bitmap with the identity ``to_uv`` and for uniform or
    tabulated spectra, a dense sample for procedural textures. ``mono``:
    evaluate ``eval_1`` (as a scale texture is read) instead of ``eval``.
    """
    mi = mitsuba_module()
    if tex.class_name() == "UniformSpectrum":
        v = scalar(tex.mean())
        return v, v
    texels = _texel_range(tex, mono)
    if texels is not None:
        return texels
    jit = dr.is_jit_v(mi.Float)
    wl = GRID if jit else GRID[::10]
    if tex.is_spatially_varying():
        res = [int(r) for r in tex.resolution()]
        nu, nv = (_centred(res[0], 64), _centred(res[1], 64)) if jit else (16, 16)
        nu, nv = min(nu, 4096), min(nv, 4096)
        u, v = np.meshgrid((np.arange(nu) + 0.5) / nu, (np.arange(nv) + 0.5) / nv)
        u, v = u.ravel(), v.ravel()
    else:
        u = v = np.full(1, 0.5)
    if not mi.is_spectral:   # RGB/mono variants: no wavelengths (Color0f)
        wl = wl[:1]
    nw = dr.size_v(mi.UnpolarizedSpectrum) if mi.is_spectral else 1   # per sample
    n = max(u.size, -(-wl.size // nw))
    i = np.arange(n)
    uu, vv = u[i % u.size], v[i % v.size]
    lam = [wl[(nw * i + c) % wl.size] for c in range(nw)]
    try:
        if jit:
            si = dr.zeros(mi.SurfaceInteraction3f, n)
            si.uv = mi.Point2f(mi.Float(uu), mi.Float(vv))
            if mi.is_spectral:
                si.wavelengths = mi.UnpolarizedSpectrum(*[mi.Float(x) for x in lam])
            val = tex.eval_1(si) if mono else tex.eval(si)
            arr = np.array(val, dtype=np.float64)
        else:
            vals = []
            for j in range(n):
                si = dr.zeros(mi.SurfaceInteraction3f)
                si.uv = mi.Point2f(float(uu[j]), float(vv[j]))
                if mi.is_spectral:
                    si.wavelengths = mi.UnpolarizedSpectrum(*[float(x[j]) for x in lam])
                val = tex.eval_1(si) if mono else tex.eval(si)
                vals.extend([float(val)] if mono else list(np.ravel(val)))
            arr = np.asarray(vals)
    except Exception:  # noqa: BLE001 - textures that need a shape cannot be checked here
        return None
    if not arr.size:
        return None
    if np.any(np.isnan(arr)):
        return math.nan, math.nan
    return float(np.min(arr)), float(np.max(arr))


def property_texture(props, name: str, want: str, *, unbounded: bool = False):
    """The property ``name`` of a plugin's ``mi.Properties`` as a Mitsuba texture
    (``get_unbounded_texture`` with ``unbounded``: RGB values above 1 kept as given), or a
    :class:`ThinFilmError` saying it must be ``want`` where Mitsuba cannot make one of it."""
    try:
        return props.get_unbounded_texture(name) if unbounded else props.get_texture(name)
    except Exception as e:  # noqa: BLE001 - Mitsuba raises RuntimeError/TypeError
        raise ThinFilmError(f"'{name}' must be {want}, got {props.get(name)!r} ({e})") from None


def bounds(lo: float = -math.inf, hi: float = math.inf, strict: bool = False) -> str:
    """``">= lo and <= hi"`` (``>`` with ``strict``; an infinite bound left out; ``""``
    with none)."""
    low = f"{'>' if strict else '>='} {lo:g}" if math.isfinite(lo) else ""
    high = f"<= {hi:g}" if math.isfinite(hi) else ""
    return " and ".join(x for x in (low, high) if x)


def _spectrum_span(tex):
    """In a spectral variant, the wavelengths (nm) a spectrum is given over where they
    do not cover Mitsuba's :data:`SPECTRAL_RANGE` (Mitsuba's ``irregular`` and
    ``regular`` spectra are 0 outside theirs), else ``None``."""
    if not mitsuba_module().is_spectral:
        return None
    try:
        lo, hi = (float(x) for x in tex.wavelength_range())
    except Exception:  # noqa: BLE001 - a texture without a wavelength range
        return None
    return (lo, hi) if lo > SPECTRAL_RANGE[0] or hi < SPECTRAL_RANGE[1] else None


def _uncovered(what: str, span) -> str:
    return (f"{what} is a spectrum over {span[0]:g}-{span[1]:g} nm, which does not cover Mitsuba's "
            f"{SPECTRAL_RANGE[0]:g}-{SPECTRAL_RANGE[1]:g} nm (outside its range it is 0)")


def check_texture_range(tex, what: str, lo: float = -math.inf, hi: float = math.inf, *,
                        mono: bool = False, strict: bool = False, cover: bool = False) -> None:
    """Raise :class:`ThinFilmError` naming ``what`` unless the texture's values
    (:func:`texture_range`) are finite and within ``[lo, hi]`` (``lo`` excluded
    with ``strict``). With ``cover`` (an optical constant, which has no sensible
    value of 0 outside the data) a spectrum must also be given over all of
    Mitsuba's 360-830 nm; a spectrum refused for its values that does not cover
    them is said to."""
    span = _spectrum_span(tex)
    if cover and span is not None:
        raise ThinFilmError(f"{_uncovered(what, span)}; give its values over "
                            f"{SPECTRAL_RANGE[0]:g}-{SPECTRAL_RANGE[1]:g} nm")
    rng = texture_range(tex, mono)
    if rng is None:
        found = _bitmap(tex)
        if found is not None and not mono and found[0].shape[2] == 3 and mitsuba_module().is_spectral:
            raise ThinFilmError(f"{what}: an RGB bitmap with raw=true has no spectrum in the "
                                f"{mitsuba_module().variant()!r} variant (Mitsuba refuses to evaluate it "
                                "when rendering); drop raw, or give a one-channel bitmap")
        return
    vmin, vmax = rng
    bad = (not (math.isfinite(vmin) and math.isfinite(vmax)) or vmin < lo or vmax > hi
           or (strict and vmin <= lo))
    if bad:
        want = bounds(lo, hi, strict) or "finite"
        raise ThinFilmError(f"{what} must be finite and {want} everywhere, got a texture with "
                            f"values in [{vmin!r}, {vmax!r}]"
                            + (f" ({_uncovered('it', span)})" if span is not None else ""))
