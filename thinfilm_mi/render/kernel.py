"""Mitsuba-side plumbing shared by the thin-film BSDFs (no plugin classes here).

* :class:`SpectralIndex` — a complex index ``n + ik`` as two Mitsuba textures
  evaluated at ``si.wavelengths`` (a ``uniform`` spectrum for a constant, a
  ``irregular`` spectrum on the dataset's knots and a 1 nm grid for a dataset,
  or the user's own ``eta``/``k`` textures). Evaluation is Mitsuba's C++
  texture code: no Python per call in LLVM variants, and the values are opaque
  kernel inputs, so editing them through ``mi.traverse`` does not recompile.
* :class:`KernelStack` — films (index and opaque thickness) between an ambient
  index and a substrate index, evaluated with the optics core on ``mi.Spectrum``
  (all wavelengths of a path at once) in float32 inside the render kernel:
  from a table, unrolled film by film (fewer than :data:`LOOP_MIN_FILMS`), or
  as a loop over buffers of the films (:class:`_LoopFilms`; at any depth when
  every film has a real index above the ambient's, :data:`REAL_LOOP_MIN_FILMS`).
* :func:`stack_from_props` — reads ``layers`` / ``thin_film_ior`` +
  ``thin_film_thickness`` / ``ext_ior`` from a plugin's ``mi.Properties`` and
  validates them at scene load time.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import drjit as dr
import numpy as np

from thinfilm_mi.optics.unpolarised import LOOP_MIN_FILMS, unpolarised_rt, unpolarised_rt_loop
from thinfilm_mi.materials import catalog as _materials
from thinfilm_mi.tabulate import band as _band_tables
from thinfilm_mi.tabulate import base as tabulate_base
from thinfilm_mi.llvm import require_llvm
from thinfilm_mi.render.colour import (GradientSampler, attach_gradient, channel_mean_texture,
                            colour_channels, colour_table, index_on_wavelengths,
                            prepare_gradients, with_absorbing)
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.core import (Cx, real_loop_applies)
from thinfilm_mi.materials.stack import AMBIENT_K_TOL, check_thickness, parse_layers
from thinfilm_mi.render.textures import (GRID, mitsuba_module, check_texture_range, irregular, scalar, texture_on_grid,
                       uniform)

#: Mitsuba's default exterior index (air at standard conditions), as in ``conductor``.
DEFAULT_EXT_IOR = 1.000277


def check_variant(plugin: str) -> None:
    """Raise if the current Mitsuba variant cannot run the thin-film plugins.

    ``*_spectral`` variants return spectra, ``*_spectral_polarized`` ones
    Mueller matrices, RGB and mono variants colours integrated against colour
    matching (:mod:`thinfilm_mi.render.modes`). Polarized RGB or mono variants are
    refused: a Mueller matrix integrated over wavelengths is not the product of
    integrated amplitudes. LLVM variants, and every variant that builds colour
    tables (float64 on the LLVM backend), pass through :func:`require_llvm`.
    """
    mi = mitsuba_module()
    variant = mi.variant()
    if variant is None or (mi.is_polarized and not mi.is_spectral):
        raise ThinFilmError(
            f"{plugin}: the Mitsuba variant {variant!r} is not supported; polarized "
            "thin films need wavelengths: use a *_spectral_polarized variant such as "
            "'llvm_ad_spectral_polarized' (or an unpolarized RGB, mono or spectral one)"
        )
    if variant.startswith("llvm") or not mi.is_spectral:
        require_llvm()


def opaque_float(value: float):
    """``value`` as a ``mi.Float`` that is an opaque kernel input (a scalar in
    scalar variants), so that changing it never recompiles a kernel."""
    mi = mitsuba_module()
    x = mi.Float(value)
    if dr.is_jit_v(x):
        dr.make_opaque(x)
    return x


def _same_variables(a, b) -> bool:
    """Whether two Dr.Jit arrays refer to the same JIT variables (no evaluation);
    other values are compared by value."""
    if dr.is_jit_v(a) and dr.is_jit_v(b):
        return (dr.detail.collect_indices(dr.detach(a))
                == dr.detail.collect_indices(dr.detach(b)))
    return bool(np.array_equal(np.asarray(a, np.float64), np.asarray(b, np.float64)))


class SpectralIndex:
    """A complex refractive index as textures ``eta(λ)`` and ``k(λ)``."""

    def __init__(self, eta_tex, k_tex, label: str, constant: complex | None = None,
                 material=None, knots: np.ndarray | None = None):
        self.eta = eta_tex
        self.k = k_tex
        self.label = label
        self.constant = constant
        self.material = material
        #: Wavelengths (nm) on which the textures are piecewise linear: empty for
        #: a constant, the 1 nm grid plus the dataset's knots for a dataset,
        #: ``None`` for textures given by the user (unknown).
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
        for part, tex in (("eta", eta_tex), ("k", k_tex)):
            if tex.class_name() == "IrregularSpectrum":
                tp = mitsuba_module().traverse(tex)
                self.arrays[part] = {name: type(tp[name])(tp[name])
                                     for name in ("wavelengths", "values")}

    @classmethod
    def from_material(cls, spec: Any, name: str) -> "SpectralIndex":
        """Build from anything :func:`thinfilm_mi.materials.catalog.resolve` accepts.

        Constant indices become ``uniform`` spectra (their ``value`` is exposed
        to ``mi.traverse``); datasets become ``irregular`` spectra (linear
        interpolation, Mitsuba's C++ code) on a 1 nm grid over 360-830 nm merged
        with the dataset's own knots: tabulated data are reproduced exactly and
        formulas to better than 1e-7.
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

        def spectrum(v):
            if np.all(v == v[0]):  # e.g. k = 0 everywhere (Mitsuba's spectra need mass)
                return uniform(v[0])
            if channels is not None:
                # RGB/mono variants: the colour tables read the material itself
                # (spectral_values); the textures hold its channel means, for the
                # plugins' per-channel evaluation (no films over an rgb eta/k)
                return channel_mean_texture(grid, v, channels)
            return irregular(grid, v)

        return cls(spectrum(values.real), spectrum(values.imag), mat.name, None, mat, grid)

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
        render kernel of a spectral variant reads it: through the textures (so
        ``mi.traverse`` edits are seen), except a dataset's in RGB and mono variants,
        whose textures hold channel means (read from the material). ``None`` for
        textures given per channel (an ``rgb`` ``eta``/``k`` in an RGB variant)."""
        wl = np.asarray(wavelengths, np.float64)
        channels = colour_channels()

        def part(tex, name):
            if (channels is not None and self.material is not None
                    and self.material.constant is None):
                # a dataset (its textures hold channel means: a uniform one in mono)
                v = self.material.index(np.clip(wl, GRID[0], GRID[-1]))
                return v.real if name == "eta" else v.imag
            if channels is None or tex.class_name() == "UniformSpectrum":
                return texture_on_grid(tex, wl)
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
            if _same_variables(tp["wavelengths"], wl) and _same_variables(tp["values"], values):
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
            tp["wavelengths"] = wl
            tp["values"] = values
            tp.update()
            edited = True
        if edited:
            self._arrays_edited = True
            self.knots = np.unique(np.concatenate(
                [np.asarray(dr.detach(a["wavelengths"]), np.float64).ravel()
                 for a in self.arrays.values()]))


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


#: Default coherence thickness (nm): thicker films are averaged incoherently.
DEFAULT_COHERENCE_THICKNESS = 5000.0
#: Default target for the tables: max abs error in R and T.
DEFAULT_TABLE_ERROR = 1e-3
#: ``tabulate="auto"`` uses a table for stacks of at least this many films (after
#: the skips). A single film stays exact: a lookup is ~2x cheaper per call (3-4
#: against 5-8 ns per point), but a render only ~5 % faster (1.05-1.10x against
#: 0.99-1.05x ``conductor``), while the exact recursion is ~100x more accurate
#: (max error 4e-6, a 1e-3 table's ~3e-4) and needs no build (benchmarks/SPEED.md).
AUTO_MIN_FILMS = 2
#: ``tabulate="auto"`` keeps tables of at most this many texels (over all
#: channels, 2 MiB of float32): a cubic lookup in a table that fits the cache
#: costs 3-4.6 ns per point, beyond it 7-12 ns, as much as the exact recursion
#: of 3-10 films (benchmarks/SPEED.md). ``tabulate=true`` allows
#: :data:`tables.MAX_TEXELS` per channel.
AUTO_MAX_TEXELS = 1 << 19
#: Default ``spectral_resolution`` (nm): a stack whose exact ``R`` and ``T`` no
#: table resolves (10 films or more on a metal: cavity resonances ~0.1 nm wide)
#: gets a table of them convolved with a Gaussian in wavenumber of this standard
#: deviation at 560 nm (:mod:`thinfilm_mi.tabulate.band`; ``0``: exact values
#: only). 1 nm changes the colour of the 30-film benchmark stack by ΔE2000 <=
#: 0.009 under D65 (0.2 under the line spectrum F11) and makes its table
#: 385x824 texels, built in 1-1.6 s; a render of it then costs 1.09x Mitsuba's
#: ``conductor`` instead of 1.35x (benchmarks/SPEED.md, issue 21).
DEFAULT_SPECTRAL_RESOLUTION = 1.0
#: A film is optically opaque when the amplitude of light crossing it once,
#: ``exp(-2 pi Im(q) d / lambda)`` at normal incidence and the worst wavelength,
#: is below this: what lies beneath then changes r by less than ~1e-9.
OPAQUE_AMPLITUDE = 1e-9


#: The same for sides whose films all have a real index above the ambient's
#: (:data:`optics.REAL_LOOP_MARGIN`): their loop takes real Fresnel amplitudes
#: (``optics.stack_rt_loop_real``) and is faster than the unrolled films from
#: one film on (benchmarks/SPEED.md).
REAL_LOOP_MIN_FILMS = 1


class _LoopFilms:
    """The films of one side as kernel buffers for :func:`optics.stack_rt_loop`.

    Every film's ``eta`` and ``k`` are evaluated through its textures on the
    union of the films' knots (:attr:`SpectralIndex.knots`: the 1 nm grid and
    the datasets' own knots), where each texture is piecewise linear, so linear
    interpolation on that grid reproduces the texture up to float32 rounding.
    One buffer holds, per film and grid cell, ``(eta_i, eta_i+1)`` or, where
    some film absorbs, ``(eta_i, k_i, eta_i+1, k_i+1)``: one gather per film and
    wavelength. The cell and weight of each wavelength are found once, before
    the loop. Thicknesses are a buffer and the film count an opaque integer, so
    neither a thickness sweep nor another depth of stack recompiles the kernel;
    the grid size and whether the films absorb are baked in.
    """

    def __init__(self, films: list, n0: SpectralIndex):
        mi = mitsuba_module()
        from thinfilm_mi.optics.backend import aligned_array
        grid = np.unique(np.concatenate([GRID[[0, -1]]] + [ix.knots for ix, _, _ in films]))
        self.g0 = float(grid[0])
        self.cells = grid.size - 1
        self.uniform = bool(np.array_equal(grid, GRID))
        eta = np.stack([texture_on_grid(ix.eta, grid) for ix, _, _ in films])
        k = np.stack([texture_on_grid(ix.k, grid) for ix, _, _ in films])
        self.real = bool(np.all(k == 0))
        #: Trace-time bounds (see optics.stack_rt_loop): films' smallest real
        #: index (where none absorbs) and the ambient's largest index.
        self.film_n_min = float(eta.min()) if self.real else None
        self.film_n_max = float(eta.max())
        self.n0_max = float(np.max(texture_on_grid(n0.eta)))
        #: The ambient's index does not depend on the wavelength: with constant
        #: films, ``q`` and the Fresnel amplitudes are then one per lane.
        self.n0_constant = n0.knots is not None and n0.knots.size == 0
        #: The loop will run optics.stack_rt_loop_real (real amplitudes).
        self.real_steps = real_loop_applies(self.n0_max, self.film_n_min)
        #: Every film's index is one constant (no knots: a single grid cell): one
        #: real per film, gathered once per lane for all the wavelengths.
        self.constant = self.real and self.cells == 1
        if self.constant:
            cols = [eta[:, 0]]
        elif self.real:
            cols = [eta[:, :-1], eta[:, 1:]]
        else:
            cols = [eta[:, :-1], k[:, :-1], eta[:, 1:], k[:, 1:]]
        self.buffer = aligned_array(np.stack(cols, axis=-1), np.float32, mi.Float)
        self.grid = aligned_array(grid, np.float32, mi.Float)
        self.thickness = aligned_array([scalar(d) for _, d, _ in films], np.float32, mi.Float)
        self.n_films = len(films)
        self.count = mi.UInt32(len(films))
        for v in (self.buffer, self.grid, self.thickness, self.count):
            dr.make_opaque(v)

    def _cell(self, w):
        """The grid cell holding wavelength ``w`` (an ``mi.Float``) and the weight of its
        upper knot."""
        mi = mitsuba_module()
        if self.uniform:   # knots 1 nm apart from an integer start: exact arithmetic
            i = mi.UInt32(dr.clip(dr.floor(w - self.g0), 0.0, float(self.cells - 1)))
            return i, dr.clip(w - (self.g0 + mi.Float(i)), 0.0, 1.0)
        i = dr.binary_search(0, self.cells - 1,
                             lambda c: dr.gather(mi.Float, self.grid, c + 1) <= w)
        lo = dr.gather(mi.Float, self.grid, i)
        hi = dr.gather(mi.Float, self.grid, i + 1)
        return i, dr.clip((w - lo) / (hi - lo), 0.0, 1.0)

    def rt(self, n0, cos_theta, exit_: Cx, wl, transmission: bool, thickness_scale):
        mi = mitsuba_module()
        if self.constant:
            if self.n0_constant:
                n0 = n0[0]

            def film(j):
                d = dr.gather(mi.Float, self.thickness, j)
                return (Cx(dr.gather(mi.Float, self.buffer, j), 0.0),
                        d if thickness_scale is None else d * thickness_scale)
            return self._rt(film, n0, cos_theta, exit_, wl, transmission)

        cells = [self._cell(wl[c]) for c in range(len(wl))]
        vec = mi.Vector2f if self.real else mi.Vector4f

        def film(j):
            base = j * self.cells
            eta, k = [], []
            for i, t in cells:
                v = dr.gather(vec, self.buffer, base + i)
                if self.real:
                    eta.append(dr.lerp(v[0], v[1], t))
                else:
                    eta.append(dr.lerp(v[0], v[2], t))
                    k.append(dr.lerp(v[1], v[3], t))
            U = mi.UnpolarizedSpectrum
            index = Cx(U(*eta), 0.0 if self.real else U(*k))
            d = dr.gather(mi.Float, self.thickness, j)
            return index, (d if thickness_scale is None else d * thickness_scale)

        return self._rt(film, n0, cos_theta, exit_, wl, transmission)

    def _rt(self, film, n0, cos_theta, exit_: Cx, wl, transmission: bool):
        return unpolarised_rt_loop(n0, cos_theta, self.count, film, exit_, wl, transmission,
                                   n0_max=self.n0_max, film_n_min=self.film_n_min,
                                   film_n_max=self.film_n_max, films_max=self.n_films)


class _Side:
    """How one lighting side of a stack is evaluated, after the skips.

    ``films`` are ``(SpectralIndex, thickness, incoherent)`` from the side the
    light comes from; ``exit`` is the exit medium (the substrate, the ambient,
    or the first optically opaque film, in which case ``opaque`` is true and
    ``T = 0``); ``table`` is a :class:`~thinfilm_mi.tabulate.exact.Table` or ``None``.
    """

    def __init__(self, n0: SpectralIndex, films, exit_: SpectralIndex, exit_real: bool,
                 opaque: bool, transmission: bool):
        self.n0 = n0
        self.films = films
        self.exit = exit_
        self.exit_real = exit_real
        self.opaque = opaque
        self.transmission = transmission
        self.table = None
        self.loop = None   # a _LoopFilms where the films are evaluated in a loop
        #: RGB/mono variants: the side's integrated.ColourTable, or None where the
        #: plugin evaluates per channel (no films over an index given per channel)
        self.colour = None

    @property
    def incoherent(self) -> list[bool]:
        return [f[2] for f in self.films]


class KernelStack:
    """Films between an ambient medium and a substrate, for evaluation in kernels.

    ``films`` is a list of ``(SpectralIndex, thickness_nm)``; thicknesses are
    stored as opaque ``mi.Float`` so a sweep never recompiles. ``ambient`` must
    be non-absorbing. ``sides`` maps ``inside`` (False: lit from the ambient,
    True: from the substrate) to whether ``T`` is needed there; it decides what
    is tabulated. Other combinations are still evaluated, exactly.

    What a scene does not need is skipped (re-decided in
    :meth:`parameters_changed`): films of zero thickness are dropped; below an
    optically opaque film (:data:`OPAQUE_AMPLITUDE`) nothing is evaluated and
    ``T = 0``; films thicker than ``coherence_thickness`` are averaged
    incoherently; with ``tabulate`` (``"auto"``, ``True``, ``False``) the
    needed sides are read from a verified table (:mod:`thinfilm_mi.tabulate.exact`)
    within ``table_error``; identical stacks share one table. Sides evaluated
    exactly with :data:`LOOP_MIN_FILMS` films or more (any number, for films
    of real index above the ambient's: :data:`REAL_LOOP_MIN_FILMS`) run the
    recursion as a loop over the films in JIT variants (:class:`_LoopFilms`).
    """

    def __init__(self, films: Sequence[tuple[SpectralIndex, float]], ambient: SpectralIndex,
                 substrate: SpectralIndex, thickness_texture=None, *,
                 tabulate: bool | str = "auto", table_error: float = DEFAULT_TABLE_ERROR,
                 spectral_resolution: float = DEFAULT_SPECTRAL_RESOLUTION,
                 coherence_thickness: float = DEFAULT_COHERENCE_THICKNESS,
                 sides: dict | None = None, plugin: str = "thin-film BSDF"):
        self.indices = [f[0] for f in films]
        self.thickness = [opaque_float(f[1]) for f in films]
        self.ambient = ambient
        self.substrate = substrate
        #: Optional Mitsuba texture; every film's thickness is multiplied by its
        #: value at the hit (clamped to >= 0).
        self.thickness_texture = thickness_texture
        self.tabulate = tabulate
        self.table_error = table_error
        self.spectral_resolution = spectral_resolution
        self.coherence_thickness = coherence_thickness
        self.sides = dict(sides) if sides is not None else {False: False}
        self.plugin = plugin
        self._gave_up = set()   # sides whose table could not be built
        if tabulate is True and thickness_texture is not None:
            raise ThinFilmError(f"{plugin}: 'tabulate' is true but a 'thickness' texture is "
                                "given: a table over (angle, wavelength) cannot follow a "
                                "thickness that varies over the surface (use 'auto' or false)")
        self._plan()

    def __len__(self) -> int:
        return len(self.indices)

    # -- planning (load time and after parameter changes) ---------------------
    def _thickness_values(self) -> list[float]:
        return [scalar(d) for d in self.thickness]

    def _opaque(self, index: SpectralIndex, d: float) -> bool:
        if self.thickness_texture is not None or d <= 0:
            return False   # a texture may thin the film anywhere
        n = index.spectral_values(GRID)
        k = n.imag if n is not None else texture_on_grid(index.k)
        return bool(np.max(np.exp(-2.0 * math.pi * k * d / GRID)) < OPAQUE_AMPLITUDE)

    def _side(self, inside: bool, transmission: bool, films: list, opaque: list) -> _Side:
        """The plan of one side from the non-zero ``films`` ``(index, thickness,
        incoherent)`` and their ``opaque`` flags, both listed from the ambient."""
        if inside:
            films, opaque = films[::-1], opaque[::-1]
            n0, exit_, exit_real = self.substrate, self.ambient, True
        else:
            n0, exit_, exit_real = self.ambient, self.substrate, False
        if any(opaque):
            j = opaque.index(True)
            return _Side(n0, films[:j], films[j][0], False, True, transmission)
        return _Side(n0, films, exit_, exit_real, False, transmission)

    def _plan(self) -> None:
        # Zero-thickness films dropped; opacity decided once per film for all sides.
        kept = [(ix, d, dv) for ix, d, dv in
                zip(self.indices, self.thickness, self._thickness_values()) if dv > 0]
        films = [(ix, d, dv > self.coherence_thickness) for ix, d, dv in kept]
        opaque = [self._opaque(ix, dv) for ix, _, dv in kept]
        self.plan = {inside: self._side(inside, t, films, opaque)
                     for inside, t in self.sides.items()}
        self.table_failed = []
        if colour_channels() is not None:
            # RGB and mono variants read integrated colour tables (thinfilm_mi.tabulate.colour)
            for side in self.plan.values():
                side.colour = colour_table(self, side, side_data)
            if dr.is_diff_v(mitsuba_module().Float):
                prepare_gradients([self.ambient, self.substrate] + list(self.indices))
            return
        if mitsuba_module().is_polarized:
            # Polarized variants evaluate the amplitudes exactly (thinfilm_mi.render.amplitudes);
            # tables and film loops hold powers only: none is built.
            return
        self._plan_tables()
        if dr.is_jit_v(mitsuba_module().Float):
            for side in self.plan.values():
                # A side whose table serves the calls its plan is for (R, and T
                # where the plan asks for it) does not evaluate its films: no
                # buffers for it (other calls fall back to the unrolled films).
                served = side.table is not None and (side.table.channels > 1 or side.opaque
                                                     or not side.transmission)
                if (not served and len(side.films) >= min(LOOP_MIN_FILMS, REAL_LOOP_MIN_FILMS)
                        and not any(side.incoherent)
                        and all(ix.knots is not None for ix, _, _ in side.films)):
                    loop = _LoopFilms(side.films, side.n0)
                    if len(side.films) >= (REAL_LOOP_MIN_FILMS if loop.real_steps
                                           else LOOP_MIN_FILMS):
                        side.loop = loop

    def _plan_tables(self) -> None:
        # "auto" tabulates in vectorised variants only: in scalar variants every
        # call is Python anyway and the load-time build would dominate.
        want = self.tabulate is True or (
            self.tabulate == "auto" and self.thickness_texture is None
            and dr.is_jit_v(mitsuba_module().Float)
            and max((len(s.films) for s in self.plan.values()), default=0) >= AUTO_MIN_FILMS)
        self.table_failed = []
        if not want:
            return
        for inside, side in self.plan.items():
            if side.films and not (self.tabulate == "auto" and inside in self._gave_up):
                side.table = _tables_cache(self, side)
                if side.table is None:
                    self.table_failed.append(inside)
                    # "auto" does not retry after every parameter edit: a failed
                    # build costs up to ~1 s (tables.MAX_BUILD_POINTS), a failed
                    # band-limited one ~2 s more (band_tables.MAX_BUILD_POINTS).
                    self._gave_up.add(inside)
        if self.tabulate is True and self.table_failed:
            import warnings
            warnings.warn(f"{self.plugin}: the stack {self.describe()} cannot be tabulated "
                          f"within table_error={self.table_error:g} in {tabulate_base.MAX_TEXELS} "
                          "texels; it is evaluated exactly", stacklevel=3)

    def mode(self) -> str:
        """``"table"`` if every planned side reads a table, ``"exact"`` if none, else ``"mixed"``."""
        tabled = [s.table is not None for s in self.plan.values() if s.films]
        if tabled and all(tabled):
            return "table"
        return "mixed" if any(tabled) else "exact"

    def describe(self) -> str:
        films = "; ".join(f"{ix.label} {scalar(d):g} nm"
                          for ix, d in zip(self.indices, self.thickness))
        return f"[{films}]" if films else "[no films]"

    def traverse(self, callback) -> None:
        mi = mitsuba_module()
        for i, (ix, d) in enumerate(zip(self.indices, self.thickness)):
            callback.put(f"layers.{i}.thickness", d, mi.ParamFlags.Differentiable)
            ix.traverse(callback, f"layers.{i}.")
        if self.thickness_texture is not None:
            callback.put("thickness", self.thickness_texture, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys=None) -> None:
        """Refresh after an edit (``keys``, the changed keys, are not needed:
        the plan and its tables are rebuilt from the current values)."""
        for i, ix in enumerate(self.indices):
            ix.parameters_changed(self.plugin, f"layers.{i}.")
        for i, d in enumerate(self.thickness):
            if dr.is_jit_v(d):
                dr.make_opaque(d)
            if not math.isfinite(scalar(d)) or scalar(d) < 0:
                raise ThinFilmError(f"{self.plugin}: layers.{i}.thickness must be a finite "
                                    f"number >= 0 (nm), got {scalar(d)!r}")
        self._plan()

    def thickness_scale_at(self, si, active=True):
        """The thickness texture's value at the hit (>= 0), or ``None`` without one."""
        if self.thickness_texture is None:
            return None
        return dr.maximum(self.thickness_texture.eval_1(si, active), 0.0)

    # -- evaluation -------------------------------------------------------------
    def _differentiating(self) -> bool:
        return any(dr.grad_enabled(d) for d in self.thickness if dr.is_diff_v(d))

    def _full_side(self, inside: bool, transmission: bool) -> _Side:
        """Every film, no skips, no table (for gradients through every film)."""
        films = [(ix, d, False) for ix, d in zip(self.indices, self.thickness)]
        return self._side(inside, transmission, films, [False] * len(films))

    def _index_gradients(self, si, active=True) -> bool:
        """Whether an index of this stack (ambient, films, substrate) carries
        gradients at the hit (AD variants; decided when the kernel is traced: one
        texture evaluation per medium, dropped unless used)."""
        if not dr.is_diff_v(mitsuba_module().Float):
            return False
        media = [self.ambient, self.substrate] + list(self.indices)
        return any(ix.carries_gradients(si, active) for ix in media)

    def evaluation_side(self, inside: bool, transmission: bool,
                        index_gradients: bool = False) -> _Side:
        """The plan of the side lit from the ambient (``inside`` false) or the
        substrate, as evaluated now: every film, without skips or table, when a
        thickness (or, with ``index_gradients``, an index) carries gradients or the
        side was not planned (a table and the film loop's buffers hold numbers, not
        derivatives)."""
        side = self.plan.get(inside)
        if side is None or self._differentiating() or index_gradients:
            side = self._full_side(inside, transmission)
        return side

    def _eval_side(self, inside: bool, si, cos_theta, active, transmission: bool,
                   thickness_scale):
        mi = mitsuba_module()
        # RGB/mono variants come here only for a side without films (no phase):
        # any wavelength will do for the Fresnel terms
        wl = si.wavelengths if mi.is_spectral else mi.Spectrum(550.0)
        side = self.evaluation_side(inside, transmission, self._index_gradients(si, active))
        n0 = side.n0.eval_real(si, active)
        table = side.table
        if table is not None and thickness_scale is None and (
                not transmission or side.opaque or table.channels > 1):
            n_exit = side.exit.eval_real(si, active) if table.kind == "tir" else None
            res = table.lookup(cos_theta, n0, n_exit, wl, active)
            if not transmission:
                return res[0]
            return res[0], (mi.UnpolarizedSpectrum(0.0) if side.opaque else res[1])
        exit_ = Cx(side.exit.eval_real(si, active), 0.0) if side.exit_real \
            else side.exit.eval(si, active)
        if side.loop is not None:
            out = side.loop.rt(n0, cos_theta, exit_, wl, transmission, thickness_scale)
        else:
            films = [(ix.eval(si, active), d if thickness_scale is None else d * thickness_scale)
                     for ix, d, _ in side.films]
            out = _rt(n0, cos_theta, films, exit_, wl, side.incoherent, transmission)
        if transmission and side.opaque:
            return out[0], mi.UnpolarizedSpectrum(0.0)
        return out

    def at_wavelengths(self, inside: bool, si, cos_theta, active, transmission: bool,
                       thickness_scale, wl):
        """Exact ``R`` [, ``T``] at the wavelengths ``wl`` (``mi.Spectrum``) in an
        RGB/mono variant, through every film (the colour gradients)."""
        mi = mitsuba_module()
        side = self._full_side(inside, transmission)

        def index(ix):
            return Cx(*index_on_wavelengths(ix, si, wl, active))
        n0 = index(side.n0).re
        exit_ = index(side.exit)
        if side.exit_real:
            exit_ = Cx(exit_.re, 0.0)
        films = [(index(ix), d if thickness_scale is None else d * thickness_scale)
                 for ix, d, _ in side.films]
        out = _rt(n0, cos_theta, films, exit_, wl, side.incoherent, transmission)
        if transmission and side.opaque:
            return out[0], mi.Spectrum(0.0)
        return out

    def colour(self, si, cos_theta, active=True, *, inside: bool | Any = False,
               transmission: bool = False):
        """RGB/mono variants: ``R`` (and ``T`` if asked) as ``mi.Spectrum`` colours,
        the spectral values integrated against colour matching
        (:mod:`thinfilm_mi.tabulate.colour`), read from the side's colour table; a side
        with no films over an index given per channel is evaluated per channel
        (Fresnel), as Mitsuba's ``conductor`` does. Where a thickness or an index
        carries gradients, they come from an unbiased estimate of the integral
        (:class:`~thinfilm_mi.render.colour.GradientSampler`); the value stays the
        table's. Arguments as :meth:`reflectance`."""
        scale = self.thickness_scale_at(si, active)

        def side(flag: bool):
            plan = self.plan.get(flag)
            if plan is None:
                raise ThinFilmError(f"{self.plugin}: internal error: the side lit from the "
                                    f"{'substrate' if flag else 'ambient'} was not planned")
            if plan.colour is None:
                return self._eval_side(flag, si, cos_theta, active, transmission, None)
            R, T = plan.colour.lookup(cos_theta, scale, active)
            if transmission and T is None:
                T = mitsuba_module().Spectrum(0.0)
            if self.colour_gradients(si, active):
                sampler = GradientSampler.get()
                wl = sampler.wavelengths(si)
                exact = self.at_wavelengths(flag, si, cos_theta, active, transmission, scale,
                                            wl)
                if transmission:
                    R = attach_gradient(R, sampler.estimate(wl, exact[0]))
                    T = attach_gradient(T, sampler.estimate(wl, exact[1]))
                else:
                    R = attach_gradient(R, sampler.estimate(wl, exact))
            return (R, T) if transmission else R

        return _either_side(side, inside, transmission)

    def colour_gradients(self, si, active=True) -> bool:
        """Whether a film thickness or an index of this stack carries gradients
        (RGB/mono AD variants; decided when the kernel is traced)."""
        if not dr.is_diff_v(mitsuba_module().Float):
            return False
        return self._differentiating() or self._index_gradients(si, active)

    def reflectance(self, si, cos_theta, active=True, *, inside: bool | Any = False,
                    transmission: bool = False, thickness_scale=None):
        """Unpolarised ``R`` (and ``T`` if asked) as ``mi.Spectrum`` at ``si.wavelengths``.

        ``cos_theta`` is the (positive) cosine of incidence measured on the side
        the light comes from. ``inside`` (a Python bool or a mask) selects the
        reversed stack lit from the substrate; the substrate must then be a
        non-absorbing medium. Where ``inside`` is a mask both directions are
        evaluated and blended with ``dr.select``.
        """
        if thickness_scale is None:
            thickness_scale = self.thickness_scale_at(si, active)

        def side(flag: bool):
            return self._eval_side(flag, si, cos_theta, active, transmission, thickness_scale)

        return _either_side(side, inside, transmission)


def _either_side(side, inside, transmission: bool):
    """``side(inside)`` for a Python bool; for a mask both sides, blended."""
    if isinstance(inside, bool):
        return side(inside)
    out_r, in_r = side(False), side(True)
    if transmission:
        return (dr.select(inside, in_r[0], out_r[0]), dr.select(inside, in_r[1], out_r[1]))
    return dr.select(inside, in_r, out_r)


def _rt(n0, cos0, films, n_exit, wl, incoherent, transmission):
    """Coherent :func:`unpolarised_rt`, or the incoherent-aware evaluator when
    some film is beyond the coherence thickness."""
    if any(incoherent):
        from thinfilm_mi.optics.incoherent import incoherent_rt
        return incoherent_rt(n0, cos0, films, n_exit, wl, incoherent, transmission=transmission)
    return unpolarised_rt(n0, cos0, films, n_exit, wl, transmission)


#: Tables shared between stacks with identical optics (bounded: 32 MiB of texture data).
TABLE_CACHE = tabulate_base.TableCache()


def _tables_cache(stack: KernelStack, side: _Side):
    """The table of ``side``, shared between stacks with identical optics.

    The key is the stack's numbers (every index on the 1 nm grid, thicknesses,
    incoherent flags, what is tabulated, the target, the texel cap), so two
    BSDFs with the same films share one texture. Tables are never modified in
    place.
    """
    import hashlib

    mi = mitsuba_module()
    h = hashlib.sha1()
    media = [side.n0] + [f[0] for f in side.films] + [side.exit]
    values = {}
    for ix in media:
        if id(ix) not in values:
            if ix.eta.is_spatially_varying() or ix.k.is_spatially_varying():
                return None   # an index that varies over the surface: not tabulable
            values[id(ix)] = (texture_on_grid(ix.eta), texture_on_grid(ix.k))
        for v in values[id(ix)]:
            h.update(v.tobytes())
    h.update(repr([(scalar(d), inc) for _, d, inc in side.films]).encode())
    transmission = side.transmission and not side.opaque
    max_texels = (AUTO_MAX_TEXELS // (2 if transmission else 1) if stack.tabulate == "auto"
                  else tabulate_base.MAX_TEXELS)
    h.update(repr((mi.variant(), side.transmission, side.exit_real, side.opaque,
                   stack.table_error, stack.spectral_resolution, max_texels)).encode())
    key = h.hexdigest()
    found, table = TABLE_CACHE.get(key)
    if found:
        return table

    data = side_data(side, transmission)
    table = _band_tables.build_table(data, stack.table_error, GRID, max_texels,
                                     stack.spectral_resolution)
    TABLE_CACHE.put(key, table)
    return table


def _index_function(ix: SpectralIndex, real: bool = False, channel: complex | None = None):
    """``wl -> index`` (float64 numpy) of a medium for the table builds: its spectral
    values (:meth:`SpectralIndex.spectral_values`), or the constant ``channel``."""
    memo = {}

    def f(wl):   # the build asks for the same wavelengths several times
        wl = np.asarray(wl, np.float64)
        if channel is not None:
            return np.full(wl.shape, channel.real if real else channel)
        key = wl.tobytes()
        if key not in memo:
            memo.clear()
            memo[key] = ix.spectral_values(wl, real)
        return memo[key]
    return f


def side_data(side: _Side, transmission: bool, channel: dict | None = None) -> tabulate_base.SideData:
    """The float64 build data (:class:`tables.SideData`) of ``side``; ``channel`` maps
    media (by ``id``) given per channel to their index in the channel built."""
    channel = channel or {}

    def on(ix, real=False):
        return _index_function(ix, real, channel.get(id(ix)))

    incoherent = side.incoherent

    def rt(n0_, cos0, films, n_exit, wl, transmission):
        return _rt(n0_, cos0, films, n_exit, wl, incoherent, transmission)

    media = [side.n0] + [f[0] for f in side.films] + [side.exit]
    return tabulate_base.SideData(
        n0=on(side.n0, real=True), films=[(on(ix), scalar(d)) for ix, d, _ in side.films],
        n_exit=on(side.exit, real=True) if side.exit_real else on(side.exit),
        transmission=transmission, rt=rt,
        rt_loop=None if any(incoherent) else unpolarised_rt_loop,
        kinks=np.unique(np.concatenate([ix.kinks for ix in media])),
        fringe_films=[j for j, f in enumerate(side.films) if not f[2]])


def side_rt(stack: KernelStack, inside: bool, cos: np.ndarray, wavelengths: np.ndarray):
    """Exact float64 ``(R, T)`` of the planned side ``inside`` of ``stack`` at every
    angle ``cos`` and wavelength (shape ``(len cos, len wavelengths)`` each), as
    the colour tables see it (spectral values of every medium)."""
    side = stack.plan[inside]
    data = with_absorbing(side_data(side, True))
    wl = np.asarray(wavelengths, np.float64)
    rows = np.tile(np.arange(wl.size), cos.size)
    out = tabulate_base.evaluate_side(data, np.repeat(cos, wl.size), rows, wl, tabulate_base.side_indices(data, wl))
    out = out.reshape(cos.size, wl.size, 2)
    T = np.zeros_like(out[..., 0]) if side.opaque else out[..., 1]
    return out[..., 0], T


def spectral_mean(x):
    """Average of a spectrum over its wavelengths (a Float), in every variant (a
    scalar variant's spectrum is one array of four numbers)."""
    return sum(x[i] for i in range(len(x))) * (1.0 / len(x))


def optional_texture(props, name: str, plugin: str):
    """The factor texture ``name`` of a plugin's properties (``specular_reflectance``,
    ``specular_transmittance``), or ``None`` if it was not given. Its values must be
    finite and >= 0 (a negative or infinite factor renders black or NaN)."""
    if name not in props:
        return None
    value = props.get(name)
    try:
        tex = props.get_texture(name)
    except Exception as e:  # noqa: BLE001 - Mitsuba raises RuntimeError/TypeError
        raise ThinFilmError(f"{plugin}: '{name}' must be a number, a spectrum or a texture, "
                            f"got {value!r} ({e})") from None
    check_texture_range(tex, f"{plugin}: '{name}'", 0.0)
    return tex


def films_from_props(props, plugin: str) -> list[tuple[SpectralIndex, float]]:
    """The film list of a plugin: ``layers`` or ``thin_film_ior`` + ``thin_film_thickness``."""
    has_layers = ("layers" in props)
    has_ior = ("thin_film_ior" in props)
    has_thk = ("thin_film_thickness" in props)
    if has_layers and (has_ior or has_thk):
        raise ThinFilmError(f"{plugin}: give either 'layers' or 'thin_film_ior' + "
                            "'thin_film_thickness', not both")
    if has_ior != has_thk:
        missing = "thin_film_thickness" if has_ior else "thin_film_ior"
        raise ThinFilmError(f"{plugin}: '{missing}' is missing (the single-film shorthand needs "
                            "both 'thin_film_ior' and 'thin_film_thickness')")
    if has_ior:
        spec = props.get("thin_film_ior")
        thk = check_thickness(props.get("thin_film_thickness"), "thin_film_thickness")
        return [(SpectralIndex.from_material(spec, "thin_film_ior"), thk)]
    text = props.get("layers", "")
    try:
        parsed = parse_layers(text)
    except ThinFilmError as e:
        raise ThinFilmError(f"{plugin}: {e}") from None
    return [(SpectralIndex.from_material(m, f"layers[{i}] material"), d)
            for i, (m, d) in enumerate(parsed)]


def thickness_texture_from_props(props, plugin: str):
    """The optional ``thickness`` scale texture (any Mitsuba texture, or a number)."""
    if "thickness" not in props:
        return None
    value = props.get("thickness")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if not math.isfinite(value) or value < 0:
            raise ThinFilmError(f"{plugin}: 'thickness' (a scale on every film's thickness) "
                                f"must be a finite number >= 0 or a texture, got {value!r}")
    try:
        tex = props.get_texture("thickness")
    except Exception as e:  # noqa: BLE001 - Mitsuba raises RuntimeError/TypeError
        raise ThinFilmError(f"{plugin}: 'thickness' must be a number or a texture, "
                            f"got {value!r} ({e})") from None
    check_texture_range(tex, f"{plugin}: 'thickness' (a scale on every film's thickness)", 0.0,
                        mono=True)
    return tex


def tabulate_from_props(props, plugin: str) -> bool | str:
    """``tabulate``: ``"auto"`` (default), ``true`` or ``false`` (bool or string)."""
    value = props.get("tabulate", "auto")
    if isinstance(value, str) and value.strip().lower() in ("auto", "true", "false"):
        value = value.strip().lower()
        return "auto" if value == "auto" else value == "true"
    if isinstance(value, bool):
        return value
    raise ThinFilmError(f"{plugin}: 'tabulate' must be \"auto\", true or false, got {value!r}")


def _positive_float(props, name: str, default: float, plugin: str, upper: float = math.inf) -> float:
    value = props.get(name, default)
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or not math.isfinite(value) or not 0 < value <= upper):
        bound = f" and <= {upper:g}" if math.isfinite(upper) else ""
        raise ThinFilmError(f"{plugin}: '{name}' must be a number > 0{bound}, got {value!r}")
    return float(value)


#: Largest ``spectral_resolution`` (nm) accepted: a Gaussian wider than this
#: would wash out the colours of single films.
MAX_SPECTRAL_RESOLUTION = 20.0


def _nonnegative_float(props, name: str, default: float, plugin: str, upper: float) -> float:
    value = props.get(name, default)
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or not math.isfinite(value) or not 0 <= value <= upper):
        raise ThinFilmError(f"{plugin}: '{name}' must be a number >= 0 and <= {upper:g}, "
                            f"got {value!r}")
    return float(value)


def stack_from_props(props, plugin: str, substrate: SpectralIndex,
                     ambient: SpectralIndex | None = None, *,
                     sides: dict | None = None) -> KernelStack:
    """The :class:`KernelStack` of a thin-film BSDF from its properties.

    Reads ``layers`` (or ``thin_film_ior`` + ``thin_film_thickness``),
    ``ext_ior`` (unless ``ambient`` is given), the optional ``thickness``
    texture, ``tabulate``, ``table_error`` and ``coherence_thickness``.
    ``sides`` (``{inside: needs_T}``) says what the BSDF evaluates, hence what
    is tabulated (default: reflectance from the ambient side only). Every
    thin-film BSDF builds its stack here, so the stack options are the same for
    all of them.
    """
    films = films_from_props(props, plugin)
    if ambient is None:
        ambient = ext_ior_from_props(props)
    return KernelStack(films, ambient, substrate, sides=sides,
                       **stack_options_from_props(props, plugin))


def stack_options_from_props(props, plugin: str, thickness_texture: bool = True) -> dict:
    """The :class:`KernelStack` keyword options every thin-film BSDF accepts."""
    options = dict(
        tabulate=tabulate_from_props(props, plugin),
        table_error=_positive_float(props, "table_error", DEFAULT_TABLE_ERROR, plugin, 0.5),
        spectral_resolution=_nonnegative_float(props, "spectral_resolution",
                                               DEFAULT_SPECTRAL_RESOLUTION, plugin,
                                               MAX_SPECTRAL_RESOLUTION),
        coherence_thickness=_positive_float(props, "coherence_thickness",
                                            DEFAULT_COHERENCE_THICKNESS, plugin),
        plugin=plugin)
    if thickness_texture:
        options["thickness_texture"] = thickness_texture_from_props(props, plugin)
    return options


def ext_ior_from_props(props) -> SpectralIndex:
    return real_index(props.get("ext_ior", DEFAULT_EXT_IOR), "ext_ior")


def check_unqueried(props, plugin: str) -> None:
    """Report parameters the plugin did not read, as Mitsuba does for its own plugins."""
    left = [k for k in props.unqueried()]
    if left:
        def shown(k):
            try:
                v = props.get(k)
            except Exception:  # noqa: BLE001 - e.g. nested objects Python cannot read
                return repr(k)
            text = repr(v) if isinstance(v, (str, int, float, bool)) else type(v).__name__
            return f"{k!r} = {text}"
        raise ThinFilmError(
            f"{plugin}: unreferenced propert{'y' if len(left) == 1 else 'ies'} "
            + ", ".join(shown(k) for k in left)
            + " (misspelled? see the plugin's parameter table)"
        )
