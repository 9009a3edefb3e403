"""The medium between the top and the bottom of a layered BSDF (no plugin classes here):
:class:`CoatMedium`, a Beer–Lambert absorber along every refracted crossing,
``A(w') = exp(-σ_a d / cos θ')``, as Mitsuba 0.6's ``coating``."""
from __future__ import annotations

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.textures import mitsuba_module, scalar, texture_range
from thinfilm_mi.tabulate.base import opaque_float

__all__ = ["CoatMedium", "check_coat_medium"]


def check_coat_medium(sigma_a, thickness: float, plugin: str) -> None:
    """``coat_thickness`` and ``coat_sigma_a`` finite and >= 0 (load and edits)."""
    if not np.isfinite(thickness) or thickness < 0:
        raise ThinFilmError(f"{plugin}: 'coat_thickness' must be a finite number >= 0, "
                            f"got {thickness!r}")
    if sigma_a is None:
        return
    rng = texture_range(sigma_a)
    if rng is None:
        return
    lo, hi = (float(v) for v in rng)
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0:
        bad = lo if (not np.isfinite(lo) or lo < 0) else hi
        raise ThinFilmError(f"{plugin}: 'coat_sigma_a' (an absorption coefficient per unit of "
                            f"'coat_thickness') must be finite and >= 0, got {bad!r}")


class CoatMedium:
    """The coat medium: the absorption coefficient ``sigma_a`` (a texture, or ``None``: a
    clear coat) over ``thickness`` (in its unit); ``plugin`` names the BSDF in errors."""

    def __init__(self, sigma_a, thickness: float, plugin: str):
        self.sigma_a = sigma_a
        self.thickness = opaque_float(thickness)
        self.plugin = plugin
        check_coat_medium(sigma_a, thickness, plugin)

    def refresh(self) -> None:
        """Check the edited values and keep the thickness opaque."""
        check_coat_medium(self.sigma_a, scalar(self.thickness), self.plugin)
        if dr.is_jit_v(self.thickness):
            dr.make_opaque(self.thickness)

    def attenuation(self, si, cos, active):
        """Beer–Lambert along one crossing of the coat at ``cos`` (``None``: no medium)."""
        if self.sigma_a is None:
            return None
        mi = mitsuba_module()
        sigma = mi.UnpolarizedSpectrum(self.sigma_a.eval(si, active))
        # a spectrum (diagonal Mueller matrix in polarized variants)
        return mi.Spectrum(dr.exp(-sigma * self.thickness / dr.maximum(cos, 1e-6)))

    def values(self, si, active) -> list:
        """Its values that may carry gradients: the thickness, ``σ_a`` at the hit."""
        return [self.thickness] + ([self.sigma_a.eval(si, active)] if self.sigma_a else [])

    def traverse(self, callback) -> None:
        """``coat_sigma_a`` (if any) and ``coat_thickness``."""
        mi = mitsuba_module()
        if self.sigma_a is not None:
            callback.put("coat_sigma_a", self.sigma_a, mi.ParamFlags.Differentiable)
        callback.put("coat_thickness", self.thickness, mi.ParamFlags.Differentiable)
