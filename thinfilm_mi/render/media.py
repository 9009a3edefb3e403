"""A stack's media in the render kernel: :class:`SpectralIndex`, a complex index
``eta + i k`` as two Mitsuba textures (uniform; a dataset's regular spectrum on a
uniform grid, or its irregular one on its own knots; or the user's textures), with what
the plans and tables read from it (its values on a wavelength grid, its knots and
kinks), and :func:`real_index` for the non-absorbing media (``ext_ior``, ``int_ior``).
"""
from __future__ import annotations

import math
from typing import Any

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials import catalog as _materials
from thinfilm_mi.materials.stack import AMBIENT_K_TOL
from thinfilm_mi.optics.core import Cx
from thinfilm_mi.render.colour_variants import channel_mean_texture, colour_channels
from thinfilm_mi.render.params import unchanged
from thinfilm_mi.render.textures import (
    GRID,
    irregular,
    mitsuba_module,
    regular,
    texture_on_grid,
    uniform,
)

__all__ = ["DEFAULT_EXT_IOR", "DEFAULT_INT_IOR", "SpectralIndex", "real_index"]

#: Mitsuba's default exterior index (air at standard conditions), as in ``conductor``.
DEFAULT_EXT_IOR = 1.000277

#: Mitsuba's default interior index of ``dielectric`` and ``roughdielectric`` (BK7 at 589 nm).
DEFAULT_INT_IOR = 1.5046


class SpectralIndex:
    """A complex refractive index as textures ``eta(λ)`` and ``k(λ)``."""

    def __init__(self, eta_tex, k_tex, label: str, constant: complex | None = None,
                 material=None, knots: np.ndarray | None = None):
        self.eta = eta_tex
        self.k = k_tex
        self.label = label
        self.constant = constant
        self.material = material
        #: Wavelengths (nm) on which the index's data are piecewise linear
        #: (:meth:`data_on`): empty for a constant, the 1 nm grid plus the dataset's
        #: knots for a dataset, ``None`` for textures given by the user (unknown).
        self.knots = knots
        #: The arrays of the ``irregular`` spectra among the two textures (a
        #: dataset's, or the user's), ``"eta"``/``"k"`` -> ``{"wavelengths": Float,
        #: "values": Float}``. :meth:`traverse` exposes them as the BSDF's own
        #: parameters rather than the spectrum's, so that an edit reaches the BSDF's
        #: validation (:class:`thinfilm_mi.render.params.ParameterGuard`) before the
        #: spectrum rebuilds its distribution (:meth:`parameters_changed`): a
        #: spectrum notified directly raises Mitsuba's own error on a negative value
        #: and is left broken for every later ``params.update()``.
        self.arrays = {}
        self._arrays_edited = False
        #: where the textures are resampled: per part, the arrays last written into them
        self._written = {}
        for part, tex in (("eta", eta_tex), ("k", k_tex)):
            if tex.class_name() == "IrregularSpectrum":
                tp = mitsuba_module().traverse(tex)
                self.arrays[part] = {name: type(tp[name])(tp[name])
                                     for name in ("wavelengths", "values")}
        #: The uniform grid (nm) the textures hold a dataset on
        #: (:meth:`~thinfilm_mi.materials.model.DispersiveMaterial.uniform_resampling`),
        #: ``None`` where they hold its own knots.
        self.uniform_grid = None

    def _resampled(self, resampling, data_grid: np.ndarray, data: np.ndarray) -> None:
        """Hold the dataset on ``resampling``'s uniform grid: ``regular`` spectra (a
        wavelength's cell is one multiply), while the data (``data`` on ``data_grid``)
        stay the arrays :meth:`traverse` exposes and an edit resamples."""
        mi = mitsuba_module()
        self.uniform_grid = resampling.grid
        for part, values, data_values in (("eta", resampling.values.real, data.real),
                                          ("k", resampling.values.imag, data.imag)):
            if getattr(self, part).class_name() != "RegularSpectrum":
                continue   # a uniform k = 0
            # a new spectrum, not an update through mi.traverse: this runs in plugin
            # constructors, which Mitsuba runs on its loader threads, where an update's
            # evaluation waits on the pool that runs the loader (a deadlock)
            setattr(self, part, regular(values))
            self.arrays[part] = {"wavelengths": mi.Float(data_grid.astype(np.float32)),
                                 "values": mi.Float(data_values.astype(np.float32))}
            self._written[part] = _snapshot(self.arrays[part])

    @classmethod
    def from_material(cls, spec: Any, name: str) -> "SpectralIndex":
        """Build from anything :func:`thinfilm_mi.materials.catalog.resolve` accepts.

        Constant indices become ``uniform`` spectra (their ``value`` is exposed
        to ``mi.traverse``). In spectral JIT variants a dataset becomes ``regular``
        spectra on the coarsest uniform grid that reproduces its interpolation
        within :data:`~thinfilm_mi.materials.model.RESAMPLE_TOL` in n and in k
        (:meth:`~thinfilm_mi.materials.model.DispersiveMaterial.uniform_resampling`:
        a wavelength's cell is one multiply, where an irregular spectrum searches);
        a dataset no grid reproduces so (and every dataset in other variants) becomes
        ``irregular`` spectra (linear interpolation, Mitsuba's C++ code) on a 1 nm grid
        over 360-830 nm merged with its own knots: tabulated data are reproduced
        exactly and formulas to better than 1e-7. Either way the 1 nm grid and the
        knots are :attr:`knots` and :attr:`arrays` (what ``mi.traverse`` edits).
        """
        try:
            mat = _materials.resolve(spec)
        except ValueError as e:
            msg = str(e)
            if msg.startswith("material: "):
                msg = msg[len("material: "):]
            raise ThinFilmError(msg if msg.startswith(name) else f"{name}: {msg}") from None
        if mat.constant is not None:
            c = mat.constant
            return cls(uniform(c.real), uniform(c.imag),
                       mat.name, c, mat, np.empty(0))
        # A 1 nm grid (enough for formulas: error ~ h^2 n''/8 < 1e-7) plus the
        # dataset's own knots, so tabulated data are reproduced exactly.
        knots = getattr(mat, "knots", lambda: np.empty(0))()
        grid = np.unique(np.concatenate(
            [GRID, knots[(knots > GRID[0]) & (knots < GRID[-1])]]))
        try:
            values = mat.index(grid)
        except ValueError as e:
            raise ThinFilmError(f"{name}: {e}") from None
        if not np.all(np.isfinite(values)) or np.any(values.imag < 0) or np.any(values.real <= 0):
            raise ThinFilmError(f"{name}: material {mat.name!r} has non-finite, n <= 0 or k < 0 "
                                "values in 360-830 nm")

        channels = colour_channels()
        # JIT variants only: a scalar variant evaluates one lane at a time, where
        # Mitsuba's search over the knots costs next to the Python around it
        resampling = (mat.uniform_resampling()
                      if channels is None and dr.is_jit_v(mitsuba_module().Float) else None)

        def spectrum(v):
            if np.all(v == v[0]):  # e.g. k = 0 everywhere (Mitsuba's spectra need mass)
                return uniform(v[0])
            if channels is not None:
                # RGB/mono variants: the colour tables read the material itself
                # (spectral_values); the textures hold its channel means, for the
                # plugins' per-channel evaluation (no films over an rgb eta/k)
                return channel_mean_texture(grid, v, channels)
            if resampling is not None:   # its values are written by _resampled
                return regular(v[[0, -1]])
            return irregular(grid, v)

        index = cls(spectrum(values.real), spectrum(values.imag), mat.name, None, mat, grid)
        if resampling is not None:
            index._resampled(resampling, grid, values)
        return index

    @property
    def kinks(self) -> np.ndarray:
        """Wavelengths inside 360-830 nm where the index's slope may jump: a
        dataset's own knots (it is interpolated linearly between them). Empty
        for constants and formulas (their 1 nm sampling bends the slope by
        ~1e-7) and for textures given by the user (unknown)."""
        if self._arrays_edited:   # edited through mi.traverse: every node may be a kink
            knots = self.knots
        elif self.material is None:
            return np.empty(0)
        else:
            knots = getattr(self.material, "knots", lambda: np.empty(0))()
        return knots[(knots > GRID[0]) & (knots < GRID[-1])]

    def data_on(self, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``eta`` and ``k`` (float64) at ``grid``: the data's own linear interpolation
        (the :attr:`arrays` as last edited) where the textures hold a resampling of
        it, else what the textures give. On :attr:`knots` it is piecewise linear."""
        return self._data_part("eta", grid), self._data_part("k", grid)

    def _data_part(self, name: str, wl: np.ndarray) -> np.ndarray:
        arrays = self.arrays.get(name) if self.uniform_grid is not None else None
        if arrays is None:
            return texture_on_grid(getattr(self, name), wl)
        return np.interp(wl, *(np.asarray(dr.detach(arrays[a]), np.float64).ravel()
                               for a in ("wavelengths", "values")))

    @classmethod
    def from_textures(cls, eta_tex, k_tex, label: str) -> "SpectralIndex":
        return cls(eta_tex, k_tex, label)

    def eval(self, si, active=True) -> Cx:
        return Cx(self.eta.eval(si, active), self.k.eval(si, active))

    def eval_real(self, si, active=True):
        return self.eta.eval(si, active)

    def carries_gradients(self, si, active=True) -> bool:
        """Whether ``eta`` or ``k`` carries gradients at the hit (decided when a kernel
        is traced: one texture evaluation each, dropped unless used)."""
        return (dr.grad_enabled(self.eta.eval(si, active))
                or dr.grad_enabled(self.k.eval(si, active)))

    def mean_real(self) -> float:
        """A representative real index (mean over 360-830 nm) for ray directions."""
        if self.constant is not None:
            return float(self.constant.real)
        if self.material is not None:
            return float(np.mean(self.material.index(GRID).real))
        return float(self.eta.mean())

    def spectral_values(self, wavelengths: np.ndarray, real: bool = False) -> np.ndarray | None:
        """The index at ``wavelengths`` (float64; complex unless ``real``), read as the
        films' buffers of a spectral variant read it (:meth:`data_on`: a dataset's own
        interpolation, as last edited through ``mi.traverse``; other textures through
        themselves), except a dataset's in RGB and mono variants, whose textures hold
        channel means (read from the material). ``None`` for textures given per channel
        (an ``rgb`` ``eta``/``k`` in an RGB variant). Tables are built from it: a dataset's
        resampling (within 1e-4) moves a thick film's phase by ~1e-3 rad, the budget of a
        table's error."""
        wl = np.asarray(wavelengths, np.float64)
        channels = colour_channels()

        def part(tex, name):
            if (channels is not None and self.material is not None
                    and self.material.constant is None):
                # a dataset (its textures hold channel means: a uniform one in mono)
                v = self.material.index(np.clip(wl, GRID[0], GRID[-1]))
                return v.real if name == "eta" else v.imag
            if channels is None or tex.class_name() == "UniformSpectrum":
                return self._data_part(name, wl)
            return None
        eta = part(self.eta, "eta")
        if real or eta is None:
            return eta
        k = part(self.k, "k")
        return None if k is None else eta + 1j * k

    def channel_values(self) -> np.ndarray | None:
        """RGB/mono variants: the index per channel (complex, one per channel) of
        textures given per channel that do not vary over the surface; else ``None``."""
        mi = mitsuba_module()
        if self.eta.is_spatially_varying() or self.k.is_spatially_varying():
            return None
        si = dr.zeros(mi.SurfaceInteraction3f)

        def channels(tex):
            return np.array(dr.ravel(tex.eval(si)), np.float64).reshape(-1)
        eta, k = channels(self.eta), channels(self.k)
        n = max(eta.size, k.size)
        return np.broadcast_to(eta, (n,)) + 1j * np.broadcast_to(k, (n,))

    def traverse(self, callback, prefix: str) -> None:
        """Expose ``eta`` and ``k`` as ``<prefix>eta.*`` and ``<prefix>k.*``: a
        texture's own parameters, or an ``irregular`` spectrum's arrays
        (``wavelengths``, ``values``) as values of the calling object (see
        :attr:`arrays`)."""
        mi = mitsuba_module()
        for part in ("eta", "k"):
            arrays = self.arrays.get(part)
            if arrays is None:
                callback.put(prefix + part, getattr(self, part), mi.ParamFlags.Differentiable)
                continue
            for name, value in arrays.items():
                callback.put(f"{prefix}{part}.{name}", value, mi.ParamFlags.Differentiable)

    def parameters_changed(self, plugin: str, prefix: str) -> None:
        """Write edited :attr:`arrays` into their spectra, after checking that each
        spectrum's wavelengths are strictly increasing and as many as its values
        (:class:`ThinFilmError` naming the key otherwise; their ranges are checked
        by the BSDF's guard before this runs)."""
        if not self.arrays:
            return
        mi = mitsuba_module()
        edited = False
        for part, arrays in self.arrays.items():
            tex = getattr(self, part)
            tp = mi.traverse(tex)
            wl, values = arrays["wavelengths"], arrays["values"]
            written = self._written[part] if part in self._written else (
                tp["wavelengths"], tp["values"])
            if unchanged(written[0], wl) and unchanged(written[1], values):
                continue
            w = np.asarray(dr.detach(wl), np.float64).ravel()
            n = dr.width(values)
            key = f"{prefix}{part}"
            if w.size != n:
                raise ThinFilmError(f"{plugin}: '{key}.values' must hold one value per entry of "
                                    f"'{key}.wavelengths' ({w.size}), got {n} values")
            if w.size < 2 or not np.all(np.diff(w) > 0):
                raise ThinFilmError(f"{plugin}: '{key}.wavelengths' must be at least 2 strictly "
                                    f"increasing wavelengths (nm), got {w.size} values "
                                    f"in [{w.min() if w.size else math.nan:.7g}, "
                                    f"{w.max() if w.size else math.nan:.7g}]")
            if self.uniform_grid is None:
                tp["wavelengths"] = wl
                tp["values"] = values
            else:
                tp["values"] = resample_linear(w, values, self.uniform_grid)
                self._written[part] = _snapshot(arrays)
            tp.update()
            edited = True
        if edited:
            self._arrays_edited = True
            self.knots = np.unique(np.concatenate(
                [np.asarray(dr.detach(a["wavelengths"]), np.float64).ravel()
                 for a in self.arrays.values()]))


def _snapshot(arrays: dict) -> tuple:
    """``(wavelengths, values)`` as new Python objects holding the same variables: an
    edit through ``mi.traverse`` assigns into the objects :meth:`SpectralIndex.traverse`
    exposed, and the snapshot keeps what they held before it."""
    return tuple(type(arrays[name])(arrays[name]) for name in ("wavelengths", "values"))


def resample_linear(wavelengths: np.ndarray, values, grid: np.ndarray):
    """The linear interpolation of ``values`` (a Dr.Jit array, one per entry of the
    increasing ``wavelengths``) at ``grid``, held constant past the ends: a gather of two
    knots and a lerp per grid wavelength, so gradients reach ``values``."""
    mi = mitsuba_module()
    w = np.asarray(wavelengths, np.float64)
    i = np.clip(np.searchsorted(w, grid, side="right") - 1, 0, w.size - 2)
    t = np.clip((grid - w[i]) / (w[i + 1] - w[i]), 0.0, 1.0)
    lo = dr.gather(mi.Float, values, mi.UInt32(i.astype(np.uint32)))
    hi = dr.gather(mi.Float, values, mi.UInt32((i + 1).astype(np.uint32)))
    return dr.lerp(lo, hi, mi.Float(t.astype(np.float32)))


def _check_real_medium(index: SpectralIndex, name: str) -> SpectralIndex:
    mat = index.material
    if mat is None:
        return index
    if mat.constant is not None:
        c = mat.constant
        if c.imag > AMBIENT_K_TOL or c.real <= 0:
            raise ThinFilmError(f"{name}: must be a real index > 0 (a non-absorbing medium), got {c!r}")
        return index
    k = mat.index(GRID).imag
    if np.any(k > AMBIENT_K_TOL):
        raise ThinFilmError(f"{name}: must be a non-absorbing medium, got {mat.name!r} "
                            f"(k up to {k.max():.3g} in 360-830 nm)")
    return index


def real_index(spec: Any, name: str) -> SpectralIndex:
    """A non-absorbing medium (``ext_ior``, ``int_ior``) as a :class:`SpectralIndex`.

    Media with ``k <= AMBIENT_K_TOL`` (glasses, water) are accepted; where light
    arrives *from* them only their real part is used."""
    if isinstance(spec, (int, float)) and not isinstance(spec, bool):
        if not math.isfinite(spec) or spec <= 0:
            raise ThinFilmError(f"{name}: must be a finite real index > 0, got {spec!r}")
    return _check_real_medium(SpectralIndex.from_material(spec, name), name)
