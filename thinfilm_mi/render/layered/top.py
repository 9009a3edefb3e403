r"""The top interface of a layered BSDF (no plugin classes here): :class:`Top`, what the
engine (:mod:`thinfilm_mi.render.layered.engine`) and its estimators read of it, and
:class:`SmoothTop`, a smooth thin-film stack (a
:class:`~thinfilm_mi.render.kernel.KernelStack`) whose reflection and transmission are
delta lobes.

Geometry (local shading frame, ``z`` up): the top lies between the ambient (index
``η_e``) and the medium above the bottom (``η_c``). A direction ``w`` outside has the inner
direction ``w'`` of Snell's law (:func:`inward`: ``w'_xy = w_xy / η``, ``η = η_c/η_e``,
the mean indices: a path has one direction for all its wavelengths), on the same (upper)
hemisphere; :func:`outward` is its inverse.
"""
from __future__ import annotations

from abc import ABC, abstractmethod

import drjit as dr
import numpy as np

from thinfilm_mi.render.textures import GRID, mitsuba_module
from thinfilm_mi.tabulate.base import opaque_float

__all__ = ["Top", "SmoothTop", "inward", "outward"]


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
    deterministically (next-event estimation through the top). A rough top (a microfacet
    distribution on the interface) is not smooth: it adds the sampling and evaluation of
    its reflection and transmission from both sides (Guo et al. 2018), which an estimator
    that accepts it reads."""
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
