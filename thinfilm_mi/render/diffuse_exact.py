"""``thinfilm_diffuse``'s exact model and its ``thickness`` texture (no plugin classes here).

* :class:`ExactFactors` — the spectral factors of model ``"exact"`` (the whole stack,
  coherent, over a base medium of index ``base_ior``) for the colour tables and the
  load-time terms, as :class:`~thinfilm_mi.render.diffuse.DiffuseFactors` gives them
  for the paper's models. The radiance factor ``(n_0/n_b)²`` of a base medium that
  differs from the ambient is split evenly between the two crossings: ``t = T n_0/n_b``
  and ``T_hemi`` (the base's escape fraction) divided by ``n_0/n_b``, so that
  ``k_d t_i t_o S`` is the diffuse term and ``t_i k_d T_hemi S`` its albedo.
* :class:`SpectralTerms` — ``R_dh`` and ``T_hemi`` in the spectral kernels: ``regular``
  spectra (no texture), or a :class:`~thinfilm_mi.tabulate.diffuse_scale.ScaleTable`
  over the thickness scale with ``∂R_dh/∂s`` for the texture's gradients.
* :func:`scale_bounds` — the largest value of a ``thickness`` texture, read at load.
* :func:`absorbs`, :func:`reflectance_from_props`, :func:`constant_albedo` — the
  plugin's reading of its films and base albedo.
"""
from __future__ import annotations

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import GRID
from thinfilm_mi.render.diffuse import DiffuseFactors
from thinfilm_mi.render.params import ALBEDO_SLACK
from thinfilm_mi.render.textures import (
    check_texture_range,
    mitsuba_module,
    regular,
    scalar,
    texture_range,
    uniform,
)
from thinfilm_mi.tabulate.diffuse_scale import ScaleTable, exact_hemispherical

__all__ = ["ExactFactors", "SpectralTerms", "scale_bounds", "spectrum_on_grid", "absorbs",
           "reflectance_from_props", "constant_albedo", "texture_gradients_refused"]

class ExactFactors(DiffuseFactors):
    """The factors of model ``"exact"`` for the stack ``coating`` (a
    :class:`~thinfilm_mi.render.kernel.KernelStack` of every film over the base
    medium, its substrate), every thickness times ``scale``."""

    def __init__(self, coating, scale: float = 1.0):
        super().__init__(coating, None, None, scale)

    def at_scale(self, scale: float) -> "ExactFactors":
        return ExactFactors(self.coating, scale)

    def _ratio(self, wl):
        """``n_0 / n_b`` at ``wl``."""
        c = self.coating
        return (c.ambient.spectral_values(wl, real=True)
                / c.substrate.spectral_values(wl, real=True))

    def t(self, cos, wl):
        return super().t(cos, wl) * self._ratio(wl)[None, :]

    def hemispherical(self, wl):
        r, t = self.hemispherical_scales(wl, [self.scale])
        return r[0], t[0]

    def hemispherical_scales(self, wl, scales):
        c = self.coating
        films = [(ix.spectral_values(wl), scalar(d)) for ix, d in zip(c.indices, c.thickness)]
        R_dh, T_hemi = exact_hemispherical(c.ambient.spectral_values(wl, real=True), films,
                                           c.substrate.spectral_values(wl, real=True), wl,
                                           scales)
        return R_dh, T_hemi / self._ratio(wl)[None, :]

    def r_dh_partials(self, wl):
        if not np.allclose(self._ratio(wl), 1.0, rtol=0, atol=1e-12):
            raise ThinFilmError(
                f"{self.coating.plugin}: gradients of the films' parameters with model 'exact' "
                "need 'base_ior' equal to 'ext_ior' (R_dh's derivatives are computed for a base "
                "medium matched to the ambient)")
        return super().r_dh_partials(wl)


def scale_bounds(tex, plugin: str) -> float:
    """The largest value (>= 0) of the ``thickness`` texture ``tex``, read at load."""
    rng = texture_range(tex, mono=True)
    if rng is None:
        raise ThinFilmError(f"{plugin}: 'thickness': its range cannot be evaluated at load "
                            "time, which the hemispherical terms need (a table over the "
                            "thickness scale)")
    return max(float(rng[1]), 0.0)


def spectrum_on_grid(tex, values):
    """``values`` on the 1 nm grid as a ``regular`` spectrum, updating ``tex`` in place
    when it already is one (a ``uniform`` 0 when all values vanish: Mitsuba's
    ``regular`` spectrum refuses a zero integral). In scalar variants a new one is
    made (their ``mi.Float`` holds one number, not the values)."""
    mi = mitsuba_module()
    values = np.asarray(values, dtype=np.float64)
    if not np.any(values.astype(np.float32) > 0):  # Mitsuba stores float32
        return uniform(0.0)
    params = mi.traverse(tex) if tex is not None and dr.is_jit_v(mi.Float) else None
    if params is not None and "values" in params:
        params["values"] = mi.Float(values.astype(np.float32))
        params.update()
        return tex
    return regular(values, GRID[0], GRID[-1])


class SpectralTerms:
    """``R_dh`` and ``T_hemi`` of a ``thinfilm_diffuse`` in spectral variants, from
    ``factors`` (``None``: no films, ``R_dh = 0``, ``T_hemi = 1``). ``texture``: the
    ``thickness`` texture or ``None``; with one, a table over the scale in ``[0,
    max]`` (:class:`ScaleTable`), whose lookup carries ``∂R_dh/∂s`` in AD variants."""

    def __init__(self, factors, texture=None, plugin: str = "thinfilm_diffuse", old=None):
        self.table = None
        self.r_dh = self.t_hemi = None
        if factors is not None and texture is not None:
            s_max = scale_bounds(texture, plugin)
            self.table = ScaleTable(lambda s: factors.hemispherical_scales(GRID, s), s_max)
            return
        if factors is None:
            t_hemi, r_dh = np.ones(len(GRID)), np.zeros(len(GRID))
        else:
            r_dh, t_hemi = factors.hemispherical(GRID)
        self.t_hemi = spectrum_on_grid(None if old is None else old.t_hemi, t_hemi)
        self.r_dh = spectrum_on_grid(None if old is None else old.r_dh, r_dh)

    def lookup(self, si, stack, active=True):
        """``(R_dh, T_hemi)`` at the hit's wavelengths and the thickness scale of the
        :class:`~thinfilm_mi.render.kernel.KernelStack` ``stack`` there (its texture's
        gradient reaches ``R_dh`` through ``∂R_dh/∂s``)."""
        if self.table is None:
            return self.r_dh.eval(si, active), self.t_hemi.eval(si, active)
        scale = stack.thickness_scale_at(si, active)
        out = self.table.lookup(si.wavelengths, scale, active)
        r_dh = out[0]
        if dr.grad_enabled(scale):
            r_dh = r_dh + out[2] * (scale - dr.detach(scale))
        return r_dh, out[1]


def absorbs(index) -> bool:
    """Whether the film index ``index`` absorbs (``k > 0``) somewhere in 360-830 nm."""
    mat = index.material
    if mat is None:
        return True
    if mat.constant is not None:
        return mat.constant.imag > 0
    return bool(np.any(mat.index(GRID).imag > 0))


def reflectance_from_props(props, plugin: str):
    """The base albedo ``reflectance``: finite and in [0, 1] (up to :data:`ALBEDO_SLACK`:
    sRGB white upsampled to a spectrum peaks a hair above 1; anything larger would let
    ``1 - k_d R_dh`` approach 0)."""
    if "reflectance" not in props:
        return uniform(0.5)
    value = props.get("reflectance")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if not (0.0 <= value <= 1.0):
            raise ThinFilmError(f"{plugin}: 'reflectance' must be in [0, 1] (an albedo), "
                                f"got {value!r}")
    try:
        tex = props.get_texture("reflectance")
    except Exception as e:  # noqa: BLE001 - Mitsuba raises RuntimeError/TypeError
        raise ThinFilmError(f"{plugin}: 'reflectance' must be a number, a spectrum or a texture, "
                            f"got {value!r} ({e})") from None
    check_texture_range(tex, f"{plugin}: 'reflectance' (an albedo, energy conservation)", 0.0,
                        1.0 + ALBEDO_SLACK)
    return tex


def constant_albedo(reflectance) -> np.ndarray | None:
    """The base albedo per colour channel where it does not vary over the surface
    (the colour tables then integrate the series with it), else ``None``."""
    if reflectance.is_spatially_varying():
        return None
    mi = mitsuba_module()
    si = dr.zeros(mi.SurfaceInteraction3f)
    return np.array(dr.ravel(reflectance.eval(si)), np.float64).reshape(-1)


def texture_gradients_refused(plugin: str, model: str) -> str:
    """Why film-parameter gradients are refused together with a ``thickness`` texture
    (models with ``R_dh``: its derivative table holds scale 1 only)."""
    return (f"{plugin}: gradients of the films' parameters together with a 'thickness' "
            f"texture are not supported with model {model!r} (R_dh's derivatives are "
            "tabulated at scale 1); differentiate the texture, or use model 'single'")
