"""What a stack is, as the render kernels read it (no plugin classes here):
:class:`FilmStack`, films (an index and an opaque thickness each) between an ambient
index and a substrate index (:class:`~thinfilm_mi.render.media.SpectralIndex`), with an
optional thickness texture; its parameters as ``mi.traverse`` shows them, their
checks after an edit, and what a hit asks of them (the texture's scale, whether a
parameter carries gradients). How the stack is planned, built and evaluated:
:mod:`~thinfilm_mi.render.stack_plan`, :mod:`~thinfilm_mi.render.stack_build`,
:mod:`~thinfilm_mi.render.stack_eval`.
"""
from __future__ import annotations

import math
from typing import Sequence

import drjit as dr

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.textures import mitsuba_module, scalar
from thinfilm_mi.tabulate.base import opaque_float

__all__ = ["FilmStack"]


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
