"""What a stack is, as the render kernels read it (no plugin classes here):
:class:`FilmStack`, films (an index and an opaque thickness each) between an ambient
index and a substrate index (:class:`~thinfilm_mi.render.media.SpectralIndex`), with an
optional thickness texture; its parameters as ``mi.traverse`` shows them, their
checks after an edit, what it is at the moment it is planned (:class:`StackFacts`: the
films' thicknesses, each medium on Mitsuba's 1 nm grid, which absorb, which films are
optically opaque), and what a hit asks of it (the texture's scale, whether a parameter
carries gradients). How the stack is planned, built and evaluated:
:mod:`~thinfilm_mi.render.stack_plan`, :mod:`~thinfilm_mi.render.stack_build`,
:mod:`~thinfilm_mi.render.stack_eval`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.textures import GRID, mitsuba_module, scalar
from thinfilm_mi.tabulate.base import opaque_float

__all__ = ["FilmStack", "OPAQUE_AMPLITUDE", "StackFacts", "on_grid", "optically_opaque",
           "stack_facts"]

#: A film is optically opaque when the amplitude of light crossing it once,
#: ``exp(-2 pi Im(q) d / lambda)`` at normal incidence and the worst wavelength,
#: is below this: what lies beneath then changes r by less than ~1e-9.
OPAQUE_AMPLITUDE = 1e-9


@dataclass(frozen=True, eq=False)
class StackFacts:
    """What a :class:`FilmStack` is at the moment it is planned (read once per plan, so
    after every edit): ``stack`` itself; ``thickness``, its films' thicknesses (nm);
    ``grid``, each medium's index on Mitsuba's 1 nm grid by ``id`` (:func:`on_grid`);
    ``real``, whether a medium absorbs nowhere on that grid, by ``id``; ``opaque``,
    per film, whether it is optically opaque (:func:`optically_opaque`);
    ``differentiating``, whether a film thickness carries gradients (:func:`stack_facts`)."""

    stack: "FilmStack"
    thickness: list
    grid: dict
    real: dict
    opaque: list
    differentiating: bool


class FilmStack:
    """Films between an ambient medium and a substrate.

    ``films`` is a list of ``(SpectralIndex, thickness_nm)`` from the ambient;
    thicknesses are kept as opaque ``mi.Float`` so that a sweep never recompiles.
    ``thickness_texture`` (a Mitsuba texture or ``None``) multiplies every film's
    thickness by its value at the hit (clamped to >= 0). ``plugin`` names the BSDF
    in error messages."""

    def __init__(self, films: Sequence[tuple[SpectralIndex, float]], ambient: SpectralIndex,
                 substrate: SpectralIndex, thickness_texture=None,
                 plugin: str = "thin-film BSDF"):
        self.indices = [f[0] for f in films]
        self.thickness = [opaque_float(f[1]) for f in films]
        self.ambient = ambient
        self.substrate = substrate
        self.thickness_texture = thickness_texture
        self.plugin = plugin

    def __len__(self) -> int:
        return len(self.indices)

    def describe(self) -> str:
        """The films as ``to_string`` shows them: ``[label thickness nm; ...]``."""
        films = "; ".join(f"{ix.label} {scalar(d):g} nm"
                          for ix, d in zip(self.indices, self.thickness))
        return f"[{films}]" if films else "[no films]"

    def media(self) -> list[SpectralIndex]:
        """Every index of the stack: the ambient, the substrate, then the films'."""
        return [self.ambient, self.substrate] + list(self.indices)

    def thickness_values(self) -> list[float]:
        """The films' thicknesses (nm) as Python numbers."""
        return [scalar(d) for d in self.thickness]

    def traverse(self, callback) -> None:
        mi = mitsuba_module()
        for i, (ix, d) in enumerate(zip(self.indices, self.thickness)):
            callback.put(f"layers.{i}.thickness", d, mi.ParamFlags.Differentiable)
            ix.traverse(callback, f"layers.{i}.")
        if self.thickness_texture is not None:
            callback.put("thickness", self.thickness_texture, mi.ParamFlags.Differentiable)

    def parameters_changed(self) -> None:
        """Check the films after an edit (an error names the parameter and the value)
        and keep every thickness opaque, so that no edit recompiles the kernel."""
        for i, ix in enumerate(self.indices):
            ix.parameters_changed(self.plugin, f"layers.{i}.")
        for i, d in enumerate(self.thickness):
            if dr.is_jit_v(d):
                dr.make_opaque(d)
            if not math.isfinite(scalar(d)) or scalar(d) < 0:
                raise ThinFilmError(f"{self.plugin}: layers.{i}.thickness must be a finite "
                                    f"number >= 0 (nm), got {scalar(d)!r}")

    def thickness_scale_at(self, si, active=True):
        """The thickness texture's value at the hit (>= 0), or ``None`` without one."""
        if self.thickness_texture is None:
            return None
        return dr.maximum(self.thickness_texture.eval_1(si, active), 0.0)

    def differentiating(self) -> bool:
        """Whether a film thickness carries gradients."""
        return any(dr.grad_enabled(d) for d in self.thickness if dr.is_diff_v(d))

    def index_gradients(self, si, active=True) -> bool:
        """Whether an index of this stack (ambient, films, substrate) carries
        gradients at the hit (AD variants; decided when the kernel is traced: one
        texture evaluation per medium, dropped unless used)."""
        if not dr.is_diff_v(mitsuba_module().Float):
            return False
        return any(ix.carries_gradients(si, active) for ix in self.media())

    def colour_gradients(self, si, active=True) -> bool:
        """Whether a film thickness or an index of this stack carries gradients
        (RGB/mono AD variants; decided when the kernel is traced)."""
        if not dr.is_diff_v(mitsuba_module().Float):
            return False
        return self.differentiating() or self.index_gradients(si, active)


def stack_facts(stack: FilmStack) -> StackFacts:
    """What ``stack`` is now (:class:`StackFacts`): each medium read on the grid once,
    for the plan and the build that follow."""
    grid = {id(ix): on_grid(ix) for ix in stack.media()}
    thickness = stack.thickness_values()
    textured = stack.thickness_texture is not None
    opaque = [optically_opaque(grid[id(ix)], d, textured)
              for ix, d in zip(stack.indices, thickness)]
    real = {key: n is not None and not np.any(n.imag) for key, n in grid.items()}
    return StackFacts(stack, thickness, grid, real, opaque, stack.differentiating())


def on_grid(index: SpectralIndex) -> np.ndarray | None:
    """``index`` on Mitsuba's 1 nm grid (complex float64, as the render kernel of a
    spectral variant reads it: :meth:`SpectralIndex.spectral_values`), or ``None``
    where it varies over the surface or is given per channel (an RGB variant's ``rgb``
    ``eta``/``k``): no one spectrum describes it then."""
    if index.eta.is_spatially_varying() or index.k.is_spatially_varying():
        return None
    return index.spectral_values(GRID)


def optically_opaque(n: np.ndarray | None, d: float, textured: bool) -> bool:
    """Whether a film ``d`` nm thick of the index ``n`` on the grid (:func:`on_grid`)
    hides what lies beneath it (:data:`OPAQUE_AMPLITUDE`); never under a thickness
    texture (``textured``), which may thin the film anywhere."""
    if textured or d <= 0 or n is None:
        return False
    return bool(np.max(np.exp(-2.0 * math.pi * n.imag * d / GRID)) < OPAQUE_AMPLITUDE)
