"""What the rough thin-film BSDFs share, as Mitsuba's rough BSDFs share
``microfacet.h``: :class:`Microfacet` (the ``distribution``, roughness and
``sample_visible`` properties, and ``mi.MicrofacetDistribution`` at a hit) and
:func:`rough_bsdf_base` (a base class on the current variant's ``mi.BSDF`` with the
methods ``thinfilm_roughconductor`` and ``thinfilm_roughdielectric`` share).

:class:`Microfacet` reads ``mi`` when it is called, so one class serves every
variant; the class :func:`rough_bsdf_base` returns derives from the variant's
``mi.BSDF``, so a plugin module calls it when it is (re)imported for a variant.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.params import MAX_ALPHA
from thinfilm_mi.render.textures import uniform

__all__ = ["DEFAULT_ALPHA", "DISTRIBUTIONS", "Microfacet", "rough_bsdf_base"]

#: Mitsuba's default roughness of its microfacet BSDFs.
DEFAULT_ALPHA = 0.1


def _alpha_texture(read, name: str):
    """A roughness parameter as a texture: finite and > 0 (a number: a ``uniform`` one)."""
    return read.texture(name, "a number > 0 or a texture", f"'{name}' (roughness)", 0.0, MAX_ALPHA,
                        mono=True, strict=True, uniform_number=True,
                        hint=" (for a smooth surface use the smooth plugin)")


#: ``distribution``'s values: the names of their ``mi.MicrofacetType`` (read in the
#: variant of the call)
DISTRIBUTIONS = {"beckmann": "Beckmann", "ggx": "GGX"}


class Microfacet:
    """The microfacet parameters shared by the rough thin-film BSDFs.

    Reads ``distribution``, ``alpha`` or ``alpha_u`` + ``alpha_v`` and
    ``sample_visible`` from a :class:`~thinfilm_mi.render.reader.PluginProperties`, as
    Mitsuba's ``roughconductor``/``roughdielectric`` do, and builds
    ``mi.MicrofacetDistribution`` at a hit.
    """

    def __init__(self, read):
        kind = read.choice("distribution", DISTRIBUTIONS)
        self.name, self.type = kind.lower(), getattr(mi.MicrofacetType, kind)
        self.sample_visible = read.boolean("sample_visible", True)
        has_u, has_v, has_a = ("alpha_u" in read), ("alpha_v" in read), ("alpha" in read)
        if has_a and (has_u or has_v):
            given = ", ".join(f"{n}={read.value(n)!r}" for n in ("alpha", "alpha_u", "alpha_v")
                              if n in read)
            raise ThinFilmError(f"give either 'alpha' or 'alpha_u' + 'alpha_v', not both (got {given})")
        if has_u != has_v:
            given, missing = ("alpha_u", "alpha_v") if has_u else ("alpha_v", "alpha_u")
            raise ThinFilmError(f"'{missing}' is missing ('{given}' = {read.value(given)!r}; "
                                "an anisotropic roughness needs both)")
        self.anisotropic = has_u
        if has_u:
            self.alpha_u = _alpha_texture(read, "alpha_u")
            self.alpha_v = _alpha_texture(read, "alpha_v")
        elif has_a:
            self.alpha_u = self.alpha_v = _alpha_texture(read, "alpha")
        else:
            self.alpha_u = self.alpha_v = uniform(DEFAULT_ALPHA)

    @property
    def flags(self):
        """Extra BSDF flags of the lobes (``Anisotropic`` or none)."""
        return mi.BSDFFlags.Anisotropic if self.anisotropic else mi.BSDFFlags.Empty

    def distribution(self, si, active, cos_theta_i=None):
        """``mi.MicrofacetDistribution`` at the hit. With ``cos_theta_i`` and
        ``sample_visible = false``, the roughness is widened by
        ``1.2 - 0.2 sqrt(|cos θ_i|)`` (Walter et al.'s trick, as Mitsuba's
        ``roughdielectric`` does for its sampling density)."""
        au = self.alpha_u.eval_1(si, active)
        if self.anisotropic:
            d = mi.MicrofacetDistribution(self.type, au, self.alpha_v.eval_1(si, active),
                                          self.sample_visible)
        else:  # one array for both: Mitsuba then takes its isotropic code paths
            d = mi.MicrofacetDistribution(self.type, au, self.sample_visible)
        if cos_theta_i is not None and not self.sample_visible:
            d.scale_alpha(1.2 - 0.2 * dr.sqrt(dr.abs(cos_theta_i)))
        return d

    def traverse(self, callback) -> None:
        flags = mi.ParamFlags.Differentiable | mi.ParamFlags.Discontinuous
        if self.anisotropic:
            callback.put("alpha_u", self.alpha_u, flags)
            callback.put("alpha_v", self.alpha_v, flags)
        else:
            callback.put("alpha", self.alpha_u, flags)

    def describe(self) -> str:
        if self.anisotropic:
            alpha = f"alpha_u = {self.alpha_u}, alpha_v = {self.alpha_v}"
        else:
            alpha = f"alpha = {self.alpha_u}"
        return (f"  distribution = {self.name},\n  sample_visible = {self.sample_visible},\n"
                f"  {alpha},\n")


def rough_bsdf_base():
    """A base class on the current variant's ``mi.BSDF`` (nanobind allows one base,
    so no mixin) with the methods shared by the rough thin-film BSDFs:
    ``eval``/``pdf``/``eval_pdf`` through the plugin's one ``_eval_pdf(ctx, si, wo,
    active, want_value)``, traversal (stack, roughness, the factor textures named
    in ``TEXTURES``) and parameter updates. Called when a plugin module is
    (re)imported for a variant."""

    class RoughBSDF(mi.BSDF):
        TEXTURES = ("specular_reflectance",)

        def eval(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, True)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, False)[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, True)

        def traverse(self, callback):
            self.stack.traverse(callback)
            self.microfacet.traverse(callback)
            for name in self.TEXTURES:
                tex = getattr(self, name)
                if tex is not None:
                    callback.put(name, tex, mi.ParamFlags.Differentiable)

        def parameters_changed(self, keys):
            self.guard.changed(self, self.stack.parameters_changed, keys)

    return RoughBSDF
