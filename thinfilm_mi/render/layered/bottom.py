"""The bottoms of a layered BSDF (no plugin classes here): what lies under the top.

* :class:`DiffuseBottom` — a diffuse base of an albedo texture, Lambertian or Oren–Nayar
  (:class:`~thinfilm_mi.render.orennayar.OrenNayar`): ``thinfilm_diffuse``'s, summed by the
  closed forms of :mod:`thinfilm_mi.render.layered.series`.
* :class:`NestedBottom` — any nested Mitsuba BSDF (ours included), evaluated in the medium
  under the top: ``thinfilm_coating``'s, summed by :mod:`thinfilm_mi.render.layered.walk`
  (or a closed form of :mod:`thinfilm_mi.render.layered.forms`).

Each names its reflection :attr:`lobes` (the engine's component 1) and its parameters.
:func:`base_context`, :func:`base_interaction` and :func:`intensity` are the helpers that
call a nested BSDF as a bottom.
"""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.params import ALBEDO_SLACK
from thinfilm_mi.render.textures import mitsuba_module, uniform

__all__ = ["DiffuseBottom", "NestedBottom", "nested_bsdf", "albedo",
           "base_context", "base_interaction", "intensity"]


def base_context(mode, lobes):
    """A ``BSDFContext`` for the base enabling only ``lobes`` (``BSDFFlags``: the delta
    reflection, or the non-delta lobes ``BSDFFlags.Smooth``), all its components."""
    mi = mitsuba_module()
    return mi.BSDFContext(mode, int(lobes), 0xFFFFFFFF)


def base_interaction(si, w):
    """A copy of ``si`` whose ``wi`` is the base's direction ``w``."""
    mi = mitsuba_module()
    si_b = mi.SurfaceInteraction3f(si)
    si_b.wi = w
    return si_b


def intensity(x, polarized: bool):
    """The unpolarised part of a value: ``M00`` of a Mueller matrix, else the spectrum."""
    mi = mitsuba_module()
    return mi.UnpolarizedSpectrum(x[0][0] if polarized else x)


def albedo(read):
    """The base albedo ``reflectance`` read by ``read`` (a
    :class:`~thinfilm_mi.render.reader.PluginProperties`; default 0.5): finite and in [0, 1]
    (a texture up to :data:`ALBEDO_SLACK`: sRGB white upsampled to a spectrum peaks a hair
    above 1; anything larger would let ``1 - k_d R_dh`` approach 0)."""
    if "reflectance" not in read:
        return uniform(0.5)
    value = read.value("reflectance")
    if isinstance(value, (int, float)) and not isinstance(value, bool) and not 0.0 <= value <= 1.0:
        raise ThinFilmError(f"'reflectance' must be in [0, 1] (an albedo), got {value!r}")
    return read.texture("reflectance", "a number, a spectrum or a texture",
                        "'reflectance' (an albedo, energy conservation)", 0.0, 1.0 + ALBEDO_SLACK)


def nested_bsdf(props, plugin: str):
    """The one nested BSDF of a layered plugin's properties: named ``bsdf``, or the one
    nested BSDF of another name (XML's unnamed child). Refused where there is none or
    more than one."""
    mi = mitsuba_module()
    if "bsdf" in props:
        base = props.get("bsdf")
        if not isinstance(base, mi.BSDF):
            raise ThinFilmError(f"{plugin}: 'bsdf' must be a nested BSDF, got {base!r}")
        return base
    found = [obj for _, obj in props.objects() if isinstance(obj, mi.BSDF)]
    if len(found) != 1:
        raise ThinFilmError(f"{plugin}: needs exactly one nested BSDF (the base under the "
                            f"coat), got {len(found)}")
    return found[0]


class DiffuseBottom:
    """A diffuse base: the albedo ``reflectance`` (a texture) with the roughness
    ``roughness`` (:class:`~thinfilm_mi.render.orennayar.OrenNayar`; Lambertian while it is
    0 everywhere)."""

    def __init__(self, reflectance, roughness):
        self.reflectance = reflectance
        self.roughness = roughness
        #: its reflection lobes (the engine's component 1)
        self.lobes = (mitsuba_module().BSDFFlags.DiffuseReflection,)

    @property
    def rough(self) -> bool:
        """Whether the kernel needs the Oren–Nayar terms (:attr:`OrenNayar.rough`)."""
        return self.roughness.rough

    def terms(self, si, kd, wo, active):
        """The Oren–Nayar :class:`~thinfilm_mi.render.orennayar.BaseTerms` towards ``wo``."""
        return self.roughness.terms(si, kd, wo, active)

    def bare_value(self, si, wo, active):
        """``π f`` alone (no top): ``k_d`` (exactly Mitsuba's ``diffuse``) or the rough base's."""
        kd = self.reflectance.eval(si, active)
        return self.roughness.terms(si, kd, wo, active).pi_f if self.roughness.rough else kd

    def check(self) -> None:
        """Refuse a render that would take the Lambertian code while the roughness carries
        gradients (:meth:`OrenNayar.check_lambertian`)."""
        self.roughness.check_lambertian()

    def refresh(self) -> bool:
        """After an edit: whether the kernel's choice of the rough terms changed."""
        return self.roughness.refresh()

    def traverse(self, callback) -> None:
        """``reflectance`` and ``roughness``."""
        callback.put("reflectance", self.reflectance, mitsuba_module().ParamFlags.Differentiable)
        self.roughness.traverse(callback)

    def describe(self) -> str:
        return self.roughness.describe()


class NestedBottom:
    """A nested Mitsuba BSDF ``bsdf`` as the base, evaluated in the medium under the top."""

    def __init__(self, bsdf):
        mi = mitsuba_module()
        self.bsdf = bsdf
        #: whether it has a delta reflection (the delta-base chain,
        #: :mod:`thinfilm_mi.render.layered.delta`)
        self.has_delta = bool(bsdf.flags() & mi.BSDFFlags.DeltaReflection)
        #: its non-delta reflection lobes (the engine's component 1; none over a pure-delta base)
        self.lobes = tuple(lobe for lobe in (mi.BSDFFlags.DiffuseReflection,
                                             mi.BSDFFlags.GlossyReflection)
                           if bsdf.flags() & lobe)

    def smooth_context(self, mode):
        """The context of its non-delta lobes where it has delta ones, else Mitsuba's
        default context."""
        mi = mitsuba_module()
        return base_context(mode, mi.BSDFFlags.Smooth) if self.has_delta else mi.BSDFContext(mode)

    def carries_gradients(self) -> bool:
        """Whether one of its own parameters carries gradients."""
        mi = mitsuba_module()
        params = mi.traverse(self.bsdf)
        return any(dr.is_array_v(params[k]) and dr.grad_enabled(params[k]) for k in params.keys())

    def traverse(self, callback) -> None:
        """The nested BSDF under ``bsdf``."""
        callback.put("bsdf", self.bsdf, mitsuba_module().ParamFlags.Differentiable)

    def describe(self) -> str:
        return self.bsdf.class_name()
