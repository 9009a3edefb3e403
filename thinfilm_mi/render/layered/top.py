r"""The top interface of a layered BSDF (no plugin classes here): :class:`Top`, what the
engine (:mod:`thinfilm_mi.render.layered.engine`) and its estimators read of it,
:class:`SmoothTop`, a smooth thin-film stack (a
:class:`~thinfilm_mi.render.kernel.KernelStack`) whose reflection and transmission are
delta lobes, and :class:`RoughTop`, the same stack on the microfacets of a rough interface
(``thinfilm_roughdielectric``'s model), whose lobes are glossy.

Geometry (local shading frame, ``z`` up): the top lies between the ambient (index
``η_e``) and the medium above the bottom (``η_c``). A direction ``w`` outside has the inner
direction ``w'`` of Snell's law (:func:`inward`: ``w'_xy = w_xy / η``, ``η = η_c/η_e``,
the mean indices: a path has one direction for all its wavelengths), on the same (upper)
hemisphere; :func:`outward` is its inverse.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from functools import reduce
from operator import or_

import drjit as dr
import numpy as np

from thinfilm_mi.render.textures import GRID, mitsuba_module
from thinfilm_mi.tabulate.base import opaque_float

__all__ = ["Top", "SmoothTop", "RoughTop", "inward", "outward"]


def inward(w, eta):
    """The inner direction (upper hemisphere) of an outer direction ``w`` for the relative
    index ``eta = η_c/η_e``, and whether it exists (``eta < 1`` can reflect totally)."""
    mi = mitsuba_module()
    inv = 1.0 / eta
    c2 = 1.0 - dr.square(inv) * (dr.square(w.x) + dr.square(w.y))
    return mi.Vector3f(w.x * inv, w.y * inv, dr.safe_sqrt(c2)), c2 > 0


def outward(w, eta):
    """The outer direction of an inner direction ``w`` (upper hemisphere), and whether it
    leaves (not beyond the critical angle)."""
    mi = mitsuba_module()
    c2 = 1.0 - dr.square(eta) * (dr.square(w.x) + dr.square(w.y))
    return mi.Vector3f(w.x * eta, w.y * eta, dr.safe_sqrt(c2)), c2 > 0


class Top(ABC):
    """The top interface of a layered BSDF, as the engine and its estimators read it.

    A top answers, at a hit, for light on either side (``inside``: lit from the medium
    above the bottom), its reflectance and transmittance (:meth:`response`), maps outer
    directions to inner ones and back (:meth:`inward`, :meth:`outward`), turns an
    unpolarised weight of one of its lobes into the variant's value (:meth:`crossing`),
    says whether its parameters carry gradients, and exposes and refreshes them.
    :attr:`smooth` says whether its lobes are deltas: the estimators then refract
    deterministically (next-event estimation through the top). A rough top
    (:class:`RoughTop`: a microfacet distribution on the interface) is not smooth: it adds
    the sampling and evaluation of its reflection and transmission from both sides (Guo et
    al. 2018), which its own estimator
    (:class:`~thinfilm_mi.render.layered.rough.RoughEstimator`) reads."""
    #: whether reflection and transmission are delta lobes
    smooth = True

    @abstractmethod
    def response(self, si, cos, active, inside=False, transmission: bool = False):
        """The top's :class:`~thinfilm_mi.render.modes.Response` at the cosine ``cos`` on the
        side ``inside`` (``R``, and ``T`` if ``transmission``; each lobe's polarisation in
        polarized variants)."""

    def unpolarized(self, si, cos, active, inside, transmission: bool):
        """:meth:`response` with ``R`` (and ``T``) as ``mi.UnpolarizedSpectrum``."""
        mi = mitsuba_module()
        resp = self.response(si, cos, active, inside=inside, transmission=transmission)
        resp.R = mi.UnpolarizedSpectrum(resp.R)
        if transmission:
            resp.T = mi.UnpolarizedSpectrum(resp.T)
        return resp

    @abstractmethod
    def inward(self, w):
        """The inner direction of the outer direction ``w``, and whether it exists."""

    @abstractmethod
    def outward(self, w):
        """The outer direction of the inner direction ``w``, and whether it leaves."""

    @abstractmethod
    def crossing(self, weight, lobe, arrive, leave):
        """A crossing of (or reflection at) the top as the variant's value."""

    @abstractmethod
    def carries_gradients(self, si, active) -> bool:
        """Whether a parameter of the top carries gradients at the hit."""

    @abstractmethod
    def traverse(self, callback) -> None:
        """Expose the top's parameters."""

    @abstractmethod
    def parameters_changed(self) -> None:
        """Refresh after an edit of its parameters."""

    @abstractmethod
    def describe(self) -> str:
        """The top, for ``to_string``."""

    @abstractmethod
    def reflection_lobe(self):
        """The ``BSDFFlags`` lobe of the top's reflection (the engine's component 0)."""

    @abstractmethod
    def crossed_lobes(self, bottom) -> tuple:
        """The lobes of the light that crosses the top to ``bottom`` and back (the engine's
        component 1; none: no such component)."""

    @abstractmethod
    def side_flags(self):
        """The ``BSDFFlags`` every component carries besides its lobes."""

    def components(self, bottom) -> list:
        """The engine's components' flags over ``bottom``: 0 the top's reflection, 1 the
        light that crosses it (absent where :meth:`crossed_lobes` has none)."""
        side = self.side_flags()
        components = [self.reflection_lobe() | side]
        lobes = self.crossed_lobes(bottom)
        if lobes:
            components.append(reduce(or_, lobes) | side)
        return components

    def enabled(self, ctx, bottom):
        """``(has_top, has_base)``: whether ``ctx`` enables component 0, resp. one of the
        lobes of component 1."""
        return (ctx.is_enabled(self.reflection_lobe(), 0),
                any(ctx.is_enabled(lobe, 1) for lobe in self.crossed_lobes(bottom)))


class SmoothTop(Top):
    """The smooth thin-film stack ``stack`` (a :class:`~thinfilm_mi.render.kernel.KernelStack`,
    exact or tabulated as its options say) as a top; ``mode``:
    :func:`thinfilm_mi.render.modes.current`."""

    def __init__(self, stack, mode):
        self.stack = stack
        self.mode = mode
        self.refresh()

    def refresh(self) -> None:
        """The relative index ``η`` (:attr:`eta`, and as opaque floats :attr:`eta_f` and
        :attr:`inv_eta2` ``= 1/η²``) and :attr:`invisible`, from the current indices."""
        self.eta = self.stack.substrate.mean_real() / self.stack.ambient.mean_real()
        n_e = self.stack.ambient.spectral_values(GRID, real=True)
        n_c = self.stack.substrate.spectral_values(GRID, real=True)
        #: no films between indices equal on Mitsuba's 1 nm grid: no reflection, no
        #: refraction, the bottom alone
        self.invisible = not self.stack.indices and np.array_equal(n_e, n_c)
        self.inv_eta2 = opaque_float(1.0 / self.eta ** 2)
        self.eta_f = opaque_float(self.eta)

    def parameters_changed(self) -> None:
        """Refresh the stack and :meth:`refresh` after an edit."""
        self.stack.parameters_changed()
        self.refresh()

    def response(self, si, cos, active, inside=False, transmission: bool = False):
        return self.mode.response(self.stack, si, cos, active, inside=inside,
                                  transmission=transmission)

    def inward(self, w):
        """:func:`inward` at this top's :attr:`eta_f`."""
        return inward(w, self.eta_f)

    def outward(self, w):
        """:func:`outward` at this top's :attr:`eta_f`."""
        return outward(w, self.eta_f)

    def crossing(self, weight, lobe, arrive, leave):
        """``weight`` (unpolarised) as a spectrum, or in polarized variants the Mueller
        matrix of ``lobe`` for light travelling along ``arrive`` and then along ``leave``, in
        Mitsuba's implicit Stokes bases of those directions (:meth:`modes.PolarizedMode.value`,
        radiance transport: it arrives along ``-wo`` and leaves along ``wi``), so that the
        products along a path chain bases that agree."""
        mi = mitsuba_module()
        if not self.mode.polarized:
            return mi.Spectrum(weight)
        return self.mode.value(weight, lobe, mi.BSDFContext(mi.TransportMode.Radiance),
                               leave, -arrive)

    def carries_gradients(self, si, active) -> bool:
        """Whether a film's thickness or index carries gradients at the hit."""
        return self.stack.colour_gradients(si, active)

    def traverse(self, callback) -> None:
        """The stack's parameters (``layers.N.*``, ``thickness``)."""
        self.stack.traverse(callback)

    def describe(self) -> str:
        """The stack, for ``to_string``."""
        return self.stack.describe()

    def reflection_lobe(self):
        """A delta reflection."""
        return mitsuba_module().BSDFFlags.DeltaReflection

    def crossed_lobes(self, bottom) -> tuple:
        """The bottom's own lobes (its delta reflection joins component 0)."""
        return tuple(bottom.lobes)

    def side_flags(self):
        """The front side."""
        return mitsuba_module().BSDFFlags.FrontSide


class RoughTop(SmoothTop):
    r"""The thin-film stack ``stack`` on the microfacets of ``microfacet`` (a
    :class:`~thinfilm_mi.render.microfacet.Microfacet`) as a top: Walter et al.'s rough
    dielectric with the stack's ``R`` and ``T`` at the microfacet's local angle, as
    ``thinfilm_roughdielectric``. Directions here are those of the top's own frame: the
    ambient above (``z > 0``), the coat medium below; ``a`` and ``b`` follow Mitsuba's
    BSDF convention (radiance leaves along ``a``, light arrives from ``b``). ``R`` lit from
    the coat medium is the reversed stack's at ``|a·m|``; ``T`` is read from outside at the
    outer direction's ``|w·m|`` (``T`` is reciprocal), so the stack needs what the smooth
    top needs. :meth:`inward` and :meth:`outward` (the mean refraction of the macro
    surface) remain for the estimator's sampling mixture."""
    smooth = False

    def __init__(self, stack, mode, microfacet):
        self.microfacet = microfacet
        super().__init__(stack, mode)

    def half_vector(self, a, b, reflect: bool):
        """The microfacet normal (upper side) of ``a`` and ``b`` and ``η`` seen from ``a``'s
        side (``η_b/η_a``)."""
        eta = dr.select(a.z > 0, self.eta_f, dr.rcp(self.eta_f))
        m = dr.normalize(a + b * (1.0 if reflect else eta))
        return dr.mulsign(m, m.z), eta

    def films(self, si, a, b, m, active, reflect: bool, inside: bool):
        """The stack's weight of the lobe and its :class:`~thinfilm_mi.render.modes.Response`
        lobe: ``R`` at ``|a·m|`` from ``a``'s side (``inside``: the coat medium's), ``T``
        from outside at the outer direction's ``|w·m|``."""
        if reflect:
            resp = self.mode.response(self.stack, si, dr.abs(dr.dot(a, m)), active,
                                      inside=inside, transmission=False)
            return resp.R, resp.reflection
        outer = b if inside else a
        resp = self.mode.response(self.stack, si, dr.abs(dr.dot(outer, m)), active,
                                  inside=False, transmission=True)
        return resp.T, resp.transmission

    def lobe(self, si, a, b, active, reflect: bool, inside: bool, want_value: bool = True,
             ctx=None):
        """``(f(a, b) |cos θ_b|, pdf)`` of the reflection (``reflect``) or the transmission
        lobe for ``a`` on the side ``inside`` (the coat medium's: ``a.z < 0``; radiance:
        ``(η_a/η_b)²`` on a crossing), the value ``None`` without ``want_value``; ``pdf``
        is :meth:`sample`'s density of ``b`` within that lobe. ``ctx`` (radiance by default)
        orients the Mueller matrices."""
        mi = mitsuba_module()
        m, eta = self.half_vector(a, b, reflect)
        dot_a, dot_b = dr.dot(a, m), dr.dot(b, m)
        side = (a.z * b.z > 0) if reflect else (a.z * b.z < 0)
        active = active & side & ((a.z < 0) if inside else (a.z > 0)) & (dot_a * a.z > 0) & (dot_b * b.z > 0)
        jac = dr.rcp(4.0 * dot_b) if reflect \
            else eta * eta * dot_b / dr.square(dot_a + eta * dot_b)
        sample_distr = self.microfacet.distribution(si, active, cos_theta_i=a.z)
        pdf = dr.select(active, sample_distr.pdf(dr.mulsign(a, a.z), m) * dr.abs(jac), 0.0)
        if not want_value:
            return None, pdf
        distr = self.microfacet.distribution(si, active)
        dg = distr.eval(m) * distr.G(a, b, m)
        weight, lobe = self.films(si, a, b, m, active, reflect, inside)
        if reflect:
            value = weight * (dg / (4.0 * dr.abs(a.z)))
        else:
            value = weight * dr.abs(dg * dot_a * dot_b / (a.z * dr.square(dot_a + eta * dot_b)))
        ctx = mi.BSDFContext(mi.TransportMode.Radiance) if ctx is None else ctx
        value = self.mode.value(value, lobe, ctx, a, b, m)
        return dr.select(active, value, dr.zeros(mi.Spectrum)), pdf

    def sample(self, si, a, sample2, active, reflect: bool, inside: bool):
        """``(b, weight, pdf, ok)``: a direction of the reflection (``reflect``) or the
        transmission lobe from ``a`` on the side ``inside`` (a microfacet normal drawn as Mitsuba's
        ``roughdielectric`` draws it), ``weight = f |cos θ_b| / pdf`` (:meth:`lobe`).
        The direction and the density are detached: a sampling decision, the weight
        carries the gradients of ``f`` alone."""
        mi = mitsuba_module()
        with dr.suspend_grad():
            sample_distr = self.microfacet.distribution(si, active, cos_theta_i=a.z)
            m, pdf_m = sample_distr.sample(dr.mulsign(a, a.z), sample2)
            dot_a = dr.dot(a, m)
            ok = active & (pdf_m > 0) & (dot_a * a.z > 0)
            if reflect:
                b = mi.reflect(a, m)
                ok = ok & (a.z * b.z > 0)
            else:
                _, cos_t, _, eta_ti = mi.fresnel(dot_a, self.eta_f)
                b = mi.refract(a, m, cos_t, eta_ti)
                ok = ok & (cos_t != 0) & (a.z * b.z < 0)
        value, pdf = self.lobe(si, a, b, ok, reflect, inside)
        pdf = dr.detach(pdf)
        ok = ok & (pdf > 0)
        weight = dr.select(ok, value / dr.select(ok, pdf, 1.0), dr.zeros(mitsuba_module().Spectrum))
        return b, weight, pdf, ok

    def carries_gradients(self, si, active) -> bool:
        """Whether a film's thickness or index, or the roughness, carries gradients."""
        mi = mitsuba_module()
        if not dr.is_diff_v(mi.Float):
            return False
        alphas = (self.microfacet.alpha_u, self.microfacet.alpha_v)
        return super().carries_gradients(si, active) or any(
            dr.grad_enabled(tex.eval_1(si, active)) for tex in alphas)

    def traverse(self, callback) -> None:
        """The stack's parameters and the roughness (``alpha`` or ``alpha_u``/``alpha_v``)."""
        super().traverse(callback)
        self.microfacet.traverse(callback)

    def describe(self) -> str:
        """The stack and the roughness, for ``to_string``."""
        return f"{self.stack.describe()}, {self.microfacet.describe().strip().rstrip(',')}"

    def reflection_lobe(self):
        """A glossy reflection."""
        return mitsuba_module().BSDFFlags.GlossyReflection

    def crossed_lobes(self, bottom) -> tuple:
        """The bottom's non-delta lobes, and glossy light where it has a delta reflection
        (the rough top spreads it)."""
        mi = mitsuba_module()
        lobes = tuple(bottom.lobes)
        if bottom.has_delta and mi.BSDFFlags.GlossyReflection not in lobes:
            lobes = lobes + (mi.BSDFFlags.GlossyReflection,)
        return lobes

    def side_flags(self):
        """The front side and the roughness's (``Anisotropic`` or none)."""
        return mitsuba_module().BSDFFlags.FrontSide | self.microfacet.flags
