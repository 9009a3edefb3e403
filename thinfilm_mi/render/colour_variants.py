"""Colour tables for the RGB and mono variants: what a planned side of a
:class:`~thinfilm_mi.render.kernel.KernelStack` returns there, and how its gradients are
obtained (no plugin classes here; below :mod:`~thinfilm_mi.render.stack_build` and
:mod:`~thinfilm_mi.render.stack_eval`, which call it).

* :func:`colour_channels` — ``"rgb"``, ``"mono"`` or ``None`` (spectral variants).
* :func:`colour_table` — a side's ``R`` [and ``T``] integrated against colour
  matching over the angle (:mod:`thinfilm_mi.tabulate.integrated` builds it), cached by
  the side's optics.
* :func:`channel_mean_texture` — the colour-weighted means of a dataset's index,
  the texture a plugin reads where it evaluates per channel.
* :class:`GradientSampler` — gradients in RGB/mono AD variants. The table holds
  numbers, not derivatives; where a film thickness or index carries gradients
  the kernel adds ``X - detach(X)`` to the table's value, with ``X`` an unbiased
  estimate of the same integral, ``X_c = (470 nm / m) Σ_k ŵ_c(λ_k) R(λ_k)`` at
  ``m`` stratified wavelengths (3 in RGB, 1 in mono) from a hash of the hit,
  evaluated exactly with the recursion on every film. The value is the table's
  (unchanged); the gradient is an unbiased estimate of the derivative of the
  integral (noisier than a spectral render's, which samples 4 wavelengths).
"""
from __future__ import annotations

import threading
from dataclasses import replace

import drjit as dr
import numpy as np

from thinfilm_mi.colour import cie
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import SPECTRAL_RANGE
from thinfilm_mi.render.tabulation import table_key
from thinfilm_mi.render.textures import GRID, mitsuba_module, new_object, scalar, texture_range, uniform
from thinfilm_mi.tabulate import integrated
from thinfilm_mi.tabulate.axes import TIR
from thinfilm_mi.tabulate.base import (
    SideData,
    TableCache,
    evaluate_side,
    grid_coordinate,
    linear_texture,
    side_indices,
    unique_wavelengths,
)
from thinfilm_mi.tabulate.refine import LinearAxis

__all__ = ["COLOUR_CACHE", "GradientSampler", "attach_gradient", "channel_mean_texture",
           "colour_channels", "colour_table", "index_on_wavelengths", "prepare_gradients",
           "with_absorbing"]


def colour_channels() -> str | None:
    """``"rgb"`` or ``"mono"`` in the RGB and mono variants (whose plugins read
    integrated colour tables, :mod:`thinfilm_mi.tabulate.integrated`), ``None`` in the
    spectral ones."""
    mi = mitsuba_module()
    if mi.is_spectral:
        return None
    return "mono" if mi.is_monochromatic else "rgb"


def channel_mean_texture(wavelengths: np.ndarray, values: np.ndarray, channels: str):
    """A constant texture holding the colour-weighted means of ``values`` (the
    index of a dataset on ``wavelengths``): per sRGB channel, or Y in mono."""
    w = cie.channel_weights(channels, wavelengths) * np.gradient(wavelengths)[None, :]
    means = (w @ values) / w.sum(axis=1)
    if means.size == 1:     # mono: Y
        return uniform(float(means[0]))
    mi = mitsuba_module()
    return new_object("srgb", color=mi.ScalarColor3f(*[float(x) for x in means]),
                      unbounded=True)


def with_absorbing(data: SideData) -> SideData:
    """``data`` with ``absorbing`` set from the 1 nm grid (one kernel per build)."""
    return data.set_absorbing(GRID)


#: Colour tables shared between stacks with identical optics (RGB/mono variants).
COLOUR_CACHE = TableCache()


def colour_table(facts, side, side_data):
    """The :class:`~thinfilm_mi.tabulate.integrated.ColourTable` of the planned side ``side`` of
    the stack ``facts`` describe (:class:`~thinfilm_mi.render.film_stack.StackFacts`: each
    medium on the grid) in RGB/mono variants, shared between stacks with identical optics;
    ``None`` where the plugin evaluates per channel (no films over an index given per
    channel). ``side_data(side, transmission, channel)`` gives the side's float64 build data
    (:class:`~thinfilm_mi.tabulate.base.SideData`; ``channel`` maps media given per channel, by
    ``id``, to the index of the channel built)."""
    channels = colour_channels()
    media = [side.n0] + [f[0] for f in side.films] + [side.exit]
    arrays, per_channel = [], {}
    for ix in media:
        v = facts.grid[id(ix)]
        if v is None:
            per_channel[id(ix)] = ix.channel_values()
            v = per_channel[id(ix)]
            if v is None:
                if not side.films:
                    return None   # per-channel Fresnel of a spatially varying eta/k
                where = "the substrate" if ix is side.exit else "a medium"
                raise ThinFilmError(
                    f"{facts.stack.plugin}: 'eta'/'k' ({where}) vary over the surface, and films "
                    f"lie on it: in the {mitsuba_module().variant()!r} variant a spectrum or a "
                    "constant (number, rgb) is required there, so that the films can "
                    "be integrated over wavelengths at load time (or use a spectral "
                    "variant)")
        arrays.append(np.asarray(v))
    if per_channel and not side.films:
        return None   # per-channel Fresnel, exactly as Mitsuba's conductor
    transmission = side.transmission and not side.opaque
    axis = LinearAxis()
    n0 = facts.grid[id(side.n0)].real
    if side.exit_real and not per_channel:
        n_exit = facts.grid[id(side.exit)].real
        if (np.all(n0 == n0[0]) and np.all(n_exit == n_exit[0]) and n_exit[0] < n0[0]):
            axis = LinearAxis(TIR, float(n0[0]), float(n_exit[0]))
    tex = facts.stack.thickness_texture
    scale_max, fixed_scale = _thickness_scale(facts.stack)
    key = table_key(arrays, side.films, (mitsuba_module().variant(), channels, transmission,
                                         side.exit_real, side.opaque, axis, scale_max, fixed_scale,
                                         integrated.settings()))
    found, table = COLOUR_CACHE.get(key)
    if found:
        return table
    # the films' optical thickness Σ max_λ Re n_j d_j (nm) from the values read above, at
    # its thickest (the largest scale)
    optical = max(scale_max or 0.0, fixed_scale or 0.0, 1.0 if tex is None else 0.0) * sum(
        float(np.max(n.real)) * scalar(d) for n, (_, d, _) in zip(arrays[1:-1], side.films))

    def source(data, chans):
        data = with_absorbing(data)

        def evaluate(cos, scale, wl):
            per_point = isinstance(scale, np.ndarray)   # a scale per point (2-D tables)
            d = data if scale is None or per_point else replace(
                data, films=[(f, t * scale) for f, t in data.films])
            # the points' wavelengths repeat (one per angle node): indices per unique one
            uniq, rows = unique_wavelengths(wl)
            return evaluate_side(d, cos, rows, uniq, side_indices(d, uniq),
                                     scale if per_point else None)
        return integrated.Source(evaluate, chans, integrated.first_wavelength_step(optical))

    C = integrated.channel_count(channels)
    if per_channel:
        sources = [source(side_data(side, transmission,
                                     {k: v[c] for k, v in per_channel.items()}), [c])
                   for c in range(C)]
    else:
        sources = [source(side_data(side, transmission), list(range(C)))]
    table = integrated.build(sources, channels, transmission, axis, scale_max, fixed_scale)
    COLOUR_CACHE.put(key, table)
    return table


def _thickness_scale(stack) -> tuple[float | None, float | None]:
    """``(scale_max, fixed_scale)`` of ``stack``'s thickness texture for its colour tables:
    the top of its range (>= 0; a table over the scale up to it) where it varies over the
    surface, else its one value (>= 0); ``(None, None)`` without one."""
    tex = stack.thickness_texture
    if tex is None:
        return None, None
    if not tex.is_spatially_varying():
        return None, max(scalar(tex.eval_1(dr.zeros(mitsuba_module().SurfaceInteraction3f))), 0.0)
    rng = texture_range(tex, mono=True)
    if rng is None:
        raise ThinFilmError(f"{stack.plugin}: 'thickness': its range cannot be evaluated "
                            f"at load time, which the {mitsuba_module().variant()!r} variant needs "
                            "(a table over the thickness scale)")
    return max(rng[1], 0.0), None


class GradientSampler:
    """In-kernel pieces of the colour gradients (see the module docstring): the
    normalised channel weights ``ŵ_c(λ)`` as a float texture over 360-830 nm
    (1 nm, linear), and stratified wavelengths from a hash of the hit. One per
    variant, built on first use (a small texture; no kernel launch)."""

    _lock = threading.Lock()
    _by_variant: dict = {}

    def __init__(self, channels: str):
        w = cie.normalised_weights(channels)       # on GRID, the 1 nm grid
        self.C = w.shape[0]
        self.texture = linear_texture(w.T)

    @classmethod
    def get(cls) -> "GradientSampler":
        mi = mitsuba_module()
        with cls._lock:
            key = mi.variant()
            if key not in cls._by_variant:
                cls._by_variant[key] = cls(colour_channels())
            return cls._by_variant[key]

    def wavelengths(self, si):
        """``m`` stratified wavelengths (``mi.Spectrum``, nm) from a hash of the hit."""
        mi = mitsuba_module()

        def bits(x):
            return dr.reinterpret_array(mi.UInt32, x)
        v0 = bits(si.p.x) ^ (bits(si.p.y) * 0x9E3779B1)
        v1 = bits(si.p.z) ^ (bits(si.wi.x) * 0x85EBCA77) ^ (bits(si.wi.y) * 0xC2B2AE3D)
        u = mi.sample_tea_float32(v0, v1, 4)
        lo, hi = SPECTRAL_RANGE
        m = dr.size_v(mi.Spectrum)
        return mi.Spectrum(*[lo + (hi - lo) * (k + u) / m for k in range(m)])

    def estimate(self, wavelengths, values):
        """``X_c = (470 nm / m) Σ_k ŵ_c(λ_k) values_k`` (``mi.Spectrum`` colours) of
        spectral ``values`` at the :meth:`wavelengths`."""
        mi = mitsuba_module()
        lo, hi = SPECTRAL_RANGE
        m = dr.size_v(mi.Spectrum)
        out = [0.0] * self.C
        for k in range(m):
            w = self.texture.eval(mi.Point1f(grid_coordinate(wavelengths[k])))
            for c in range(self.C):
                out[c] = out[c] + w[c] * values[k]
        return mi.Spectrum(*[(hi - lo) / m * x for x in out])


def attach_gradient(value, estimate):
    """``value`` with the gradients of ``estimate``: ``value + X - detach(X)``."""
    return dr.detach(value) + (estimate - dr.detach(estimate))


def prepare_gradients(media) -> None:
    """Build, at scene load, what :class:`GradientSampler` and
    :func:`index_on_wavelengths` read in the kernel for these media (the render
    kernel is traced inside Mitsuba's symbolic loops, where no array may be
    evaluated, so nothing can be built lazily there)."""
    GradientSampler.get()
    for ix in media:
        _wavelength_texture(ix)


def _wavelength_texture(ix):
    """A dataset index's 1 nm values (re, im) as a float texture over 360-830 nm,
    built once per index; ``None`` for anything else."""
    if ix.material is None or ix.material.constant is not None:
        return None
    tex = getattr(ix, "_wl_texture", None)
    if tex is None:
        v = ix.material.index(GRID)
        tex = linear_texture(np.stack([v.real, v.imag], axis=1))
        ix._wl_texture = tex
    return tex


def index_on_wavelengths(ix, si, wavelengths, active=True):
    """The :class:`~thinfilm_mi.render.media.SpectralIndex` ``ix`` at ``wavelengths``
    (``mi.Spectrum``, nm) in RGB/mono variants, as ``(re, im)``: a dataset's from
    a float texture of its 1 nm values (built once per index), anything else
    (numbers: ``uniform``, differentiable) as its textures evaluate."""
    mi = mitsuba_module()
    tex = _wavelength_texture(ix)
    if tex is None:
        n = ix.eval(si, active)
        return n.re, n.im
    re, im = [], []
    for k in range(dr.size_v(mi.Spectrum)):
        v = tex.eval(mi.Point1f(grid_coordinate(wavelengths[k])), active)
        re.append(v[0])
        im.append(v[1])
    return mi.Spectrum(*re), mi.Spectrum(*im)
