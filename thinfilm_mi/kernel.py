"""Mitsuba-side plumbing shared by the thin-film BSDFs (no plugin classes here).

* :class:`SpectralIndex` — a complex index ``n + ik`` as two Mitsuba textures
  evaluated at ``si.wavelengths`` (a ``uniform`` spectrum for a constant, a
  ``irregular`` spectrum on the dataset's knots and a 1 nm grid for a dataset,
  or the user's own ``eta``/``k`` textures). Evaluation is Mitsuba's C++
  texture code: no Python per call in LLVM variants, and the values are opaque
  kernel inputs, so editing them through ``mi.traverse`` does not recompile.
* :class:`KernelStack` — films (index and opaque thickness) between an ambient
  index and a substrate index, evaluated with the optics core on ``mi.Spectrum``
  (all wavelengths of a path at once) in float32 inside the render kernel.
* :func:`stack_from_props` — reads ``layers`` / ``thin_film_ior`` +
  ``thin_film_thickness`` / ``ext_ior`` from a plugin's ``mi.Properties`` and
  validates them at scene load time.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import drjit as dr
import numpy as np

from . import materials as _materials
from ._llvm import require_llvm
from .errors import ThinFilmError
from .optics import Cx, stack_amplitudes, transmittance_factor_p, transmittance_factor_s
from .stack import AMBIENT_K_TOL, SPECTRAL_RANGE, check_thickness, parse_layers

#: Mitsuba's default exterior index (air at standard conditions), as in ``conductor``.
DEFAULT_EXT_IOR = 1.000277

_GRID = np.linspace(SPECTRAL_RANGE[0], SPECTRAL_RANGE[1],
                    int(SPECTRAL_RANGE[1] - SPECTRAL_RANGE[0]) + 1)


def _mi():
    import mitsuba as mi
    return mi


def check_variant(plugin: str) -> None:
    """Raise if the current Mitsuba variant cannot run the thin-film plugins.

    Interference needs wavelengths: RGB and monochrome variants are refused,
    and so are polarised ones (the plugins return unpolarised Mueller weights
    only). LLVM variants also pass through :func:`require_llvm`.
    """
    mi = _mi()
    variant = mi.variant()
    if variant is None or "spectral" not in variant or "polarized" in variant:
        raise ThinFilmError(
            f"{plugin}: the Mitsuba variant {variant!r} is not supported; thin-film "
            "interference needs wavelengths and unpolarised transport: use a *_spectral "
            "variant such as 'llvm_ad_spectral' or 'scalar_spectral' (RGB, mono and "
            "polarized variants are not supported yet)"
        )
    if variant.startswith("llvm"):
        require_llvm()


def opaque_float(value: float):
    """``value`` as a ``mi.Float`` that is an opaque kernel input (a scalar in
    scalar variants), so that changing it never recompiles a kernel."""
    mi = _mi()
    x = mi.Float(value)
    if dr.is_jit_v(x):
        dr.make_opaque(x)
    return x


class SpectralIndex:
    """A complex refractive index as textures ``eta(λ)`` and ``k(λ)``."""

    def __init__(self, eta_tex, k_tex, label: str, constant: complex | None = None,
                 material=None):
        self.eta = eta_tex
        self.k = k_tex
        self.label = label
        self.constant = constant
        self.material = material

    @classmethod
    def from_material(cls, spec: Any, name: str) -> "SpectralIndex":
        """Build from anything :func:`thinfilm_mi.materials.resolve` accepts.

        Constant indices become ``uniform`` spectra (their ``value`` is exposed
        to ``mi.traverse``); datasets become ``irregular`` spectra (linear
        interpolation, Mitsuba's C++ code) on a 1 nm grid over 360-830 nm merged
        with the dataset's own knots: tabulated data are reproduced exactly and
        formulas to better than 1e-7.
        """
        mi = _mi()
        try:
            mat = _materials.resolve(spec)
        except ValueError as e:
            msg = str(e)
            if msg.startswith("material: "):
                msg = msg[len("material: "):]
            raise ThinFilmError(msg if msg.startswith(name) else f"{name}: {msg}") from None
        if mat.constant is not None:
            c = mat.constant
            return cls(mi.load_dict({"type": "uniform", "value": float(c.real)}),
                       mi.load_dict({"type": "uniform", "value": float(c.imag)}),
                       mat.name, c, mat)
        # A 1 nm grid (enough for formulas: error ~ h^2 n''/8 < 1e-7) plus the
        # dataset's own knots, so tabulated data are reproduced exactly.
        knots = getattr(mat, "knots", lambda: np.empty(0))()
        grid = np.unique(np.concatenate(
            [_GRID, knots[(knots > _GRID[0]) & (knots < _GRID[-1])]]))
        try:
            values = mat.index(grid)
        except ValueError as e:
            raise ThinFilmError(f"{name}: {e}") from None
        if not np.all(np.isfinite(values)) or np.any(values.imag < 0) or np.any(values.real <= 0):
            raise ThinFilmError(f"{name}: material {mat.name!r} has non-finite, n <= 0 or k < 0 "
                                "values in 360-830 nm")

        def spectrum(v):
            if np.all(v == v[0]):  # e.g. k = 0 everywhere (Mitsuba's spectra need mass)
                return mi.load_dict({"type": "uniform", "value": float(v[0])})
            return mi.load_dict({"type": "irregular",
                                 "wavelengths": ", ".join(f"{x:.12g}" for x in grid),
                                 "values": ", ".join(f"{x:.9g}" for x in v)})

        return cls(spectrum(values.real), spectrum(values.imag), mat.name, None, mat)

    @classmethod
    def from_textures(cls, eta_tex, k_tex, label: str) -> "SpectralIndex":
        return cls(eta_tex, k_tex, label)

    def eval(self, si, active=True) -> Cx:
        return Cx(self.eta.eval(si, active), self.k.eval(si, active))

    def eval_real(self, si, active=True):
        return self.eta.eval(si, active)

    def mean_real(self) -> float:
        """A representative real index (mean over 360-830 nm) for ray directions."""
        if self.constant is not None:
            return float(self.constant.real)
        if self.material is not None:
            return float(np.mean(self.material.index(_GRID).real))
        return float(self.eta.mean())

    def traverse(self, callback, prefix: str) -> None:
        mi = _mi()
        callback.put(prefix + "eta", self.eta, mi.ParamFlags.Differentiable)
        callback.put(prefix + "k", self.k, mi.ParamFlags.Differentiable)


def _check_real_medium(index: SpectralIndex, name: str) -> SpectralIndex:
    mat = index.material
    if mat is None:
        return index
    if mat.constant is not None:
        c = mat.constant
        if c.imag > AMBIENT_K_TOL or c.real <= 0:
            raise ThinFilmError(f"{name}: must be a real index > 0 (a non-absorbing medium), got {c!r}")
        return index
    k = mat.index(_GRID).imag
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


class KernelStack:
    """Films between an ambient medium and a substrate, for evaluation in kernels.

    ``films`` is a list of ``(SpectralIndex, thickness_nm)``; thicknesses are
    stored as opaque ``mi.Float`` so a sweep never recompiles. ``ambient`` must
    be non-absorbing.
    """

    def __init__(self, films: Sequence[tuple[SpectralIndex, float]], ambient: SpectralIndex,
                 substrate: SpectralIndex, thickness_texture=None):
        self.indices = [f[0] for f in films]
        self.thickness = [opaque_float(f[1]) for f in films]
        self.ambient = ambient
        self.substrate = substrate
        #: Optional Mitsuba texture; every film's thickness is multiplied by its
        #: value at the hit (clamped to >= 0).
        self.thickness_texture = thickness_texture

    def __len__(self) -> int:
        return len(self.indices)

    def describe(self) -> str:
        films = "; ".join(f"{ix.label} {float(dr.ravel(d)[0]) if dr.is_array_v(d) else d:g} nm"
                          for ix, d in zip(self.indices, self.thickness))
        return f"[{films}]" if films else "[no films]"

    def traverse(self, callback) -> None:
        mi = _mi()
        for i, (ix, d) in enumerate(zip(self.indices, self.thickness)):
            callback.put(f"layers.{i}.thickness", d, mi.ParamFlags.Differentiable)
            ix.traverse(callback, f"layers.{i}.")
        if self.thickness_texture is not None:
            callback.put("thickness", self.thickness_texture, mi.ParamFlags.Differentiable)

    def thickness_scale_at(self, si, active=True):
        """The thickness texture's value at the hit (>= 0), or ``None`` without one."""
        if self.thickness_texture is None:
            return None
        return dr.maximum(self.thickness_texture.eval_1(si, active), 0.0)

    def parameters_changed(self) -> None:
        for i, d in enumerate(self.thickness):
            if dr.is_jit_v(d):
                dr.make_opaque(d)

    def films_at(self, si, active=True, reverse: bool = False, thickness_scale=None):
        films = [(ix.eval(si, active), d if thickness_scale is None else d * thickness_scale)
                 for ix, d in zip(self.indices, self.thickness)]
        return films[::-1] if reverse else films

    def reflectance(self, si, cos_theta, active=True, *, inside: bool | Any = False,
                    transmission: bool = False, thickness_scale=None):
        """Unpolarised ``R`` (and ``T`` if asked) as ``mi.Spectrum`` at ``si.wavelengths``.

        ``cos_theta`` is the (positive) cosine of incidence measured on the side
        the light comes from. ``inside`` (a Python bool or a mask) selects the
        reversed stack lit from the substrate; the substrate must then be a
        non-absorbing medium. Where ``inside`` is a mask both directions are
        evaluated and blended with ``dr.select``.
        """
        wl = si.wavelengths
        if thickness_scale is None:
            thickness_scale = self.thickness_scale_at(si, active)
        n_amb = self.ambient.eval_real(si, active)
        n_sub = self.substrate.eval(si, active)
        if isinstance(inside, bool):
            films = self.films_at(si, active, reverse=inside, thickness_scale=thickness_scale)
            if inside:
                return unpolarised_rt(n_sub.re, cos_theta, films, Cx(n_amb, 0.0), wl, transmission)
            return unpolarised_rt(n_amb, cos_theta, films, n_sub, wl, transmission)
        films = self.films_at(si, active, thickness_scale=thickness_scale)
        out_r = unpolarised_rt(n_amb, cos_theta, films, n_sub, wl, transmission)
        in_r = unpolarised_rt(n_sub.re, cos_theta, films[::-1], Cx(n_amb, 0.0), wl, transmission)
        if transmission:
            return (dr.select(inside, in_r[0], out_r[0]), dr.select(inside, in_r[1], out_r[1]))
        return dr.select(inside, in_r, out_r)


def unpolarised_rt(n0, cos0, films, n_exit, wl, transmission: bool = True):
    """Unpolarised ``R`` (and ``T``, the power entering ``n_exit``), any array type.

    ``R = (Rs + Rp) / 2`` clamped to 1; ``T`` clipped to ``[0, 1 - R]``; at grazing
    incidence ``T = 0``. Shared by the kernels and the float64 hemispherical terms.
    """
    a = stack_amplitudes(n0, cos0, films, n_exit, wl, transmission=transmission)
    R = dr.minimum(0.5 * (a.rs.abs2() + a.rp.abs2()), 1.0)
    if not transmission:
        return R
    q0 = dr.select(a.grazing, 1.0, a.q0)
    T = 0.5 * (a.ts.abs2() * transmittance_factor_s(a.q_exit, q0)
               + a.tp.abs2() * transmittance_factor_p(a.n_exit, a.q_exit, q0))
    T = dr.select(a.grazing, 0.0, dr.clip(T, 0.0, 1.0 - R))
    return R, T


def optional_texture(props, name: str):
    """The texture ``name`` of a plugin's properties, or ``None`` if it was not given."""
    return props.get_texture(name) if name in props else None


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
        return props.get_texture("thickness")
    except Exception as e:  # noqa: BLE001 - Mitsuba raises RuntimeError/TypeError
        raise ThinFilmError(f"{plugin}: 'thickness' must be a number or a texture, "
                            f"got {value!r} ({e})") from None


def stack_from_props(props, plugin: str, substrate: SpectralIndex,
                     ambient: SpectralIndex | None = None) -> KernelStack:
    """The :class:`KernelStack` of a thin-film BSDF from its properties.

    Reads ``layers`` (or ``thin_film_ior`` + ``thin_film_thickness``),
    ``ext_ior`` (unless ``ambient`` is given) and the optional ``thickness``
    texture. Every thin-film BSDF builds its stack here, so the stack options
    are the same for all of them.
    """
    films = films_from_props(props, plugin)
    if ambient is None:
        ambient = ext_ior_from_props(props)
    return KernelStack(films, ambient, substrate,
                       thickness_texture=thickness_texture_from_props(props, plugin))


def ext_ior_from_props(props) -> SpectralIndex:
    return real_index(props.get("ext_ior", DEFAULT_EXT_IOR), "ext_ior")


def check_unqueried(props, plugin: str) -> None:
    """Report parameters the plugin did not read, as Mitsuba does for its own plugins."""
    left = [k for k in props.unqueried()]
    if left:
        raise ThinFilmError(
            f"{plugin}: unreferenced propert{'y' if len(left) == 1 else 'ies'} "
            + ", ".join(repr(k) for k in left)
            + " (misspelled? see the plugin's parameter table)"
        )
