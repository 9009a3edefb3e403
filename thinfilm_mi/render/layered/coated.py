"""What the estimators over a nested BSDF through a coat medium share (no plugin classes
here): :class:`CoatedEstimator`, the base of the smooth top's
(:class:`~thinfilm_mi.render.layered.nested.NestedEstimator`) and the rough top's
(:class:`~thinfilm_mi.render.layered.rough.RoughEstimator`): their parts, the base's delta
reflection, the coat medium's parameters and refresh, whether a parameter carries
gradients, and the description."""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.render.layered.delta import DeltaBase
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["CoatedEstimator"]


class CoatedEstimator:
    """The layered BSDF of ``top`` (a :class:`~thinfilm_mi.render.layered.top.Top`) over
    ``bottom`` (a :class:`~thinfilm_mi.render.layered.bottom.NestedBottom`) through
    ``medium`` (a :class:`~thinfilm_mi.render.layered.coat.CoatMedium`); ``mode``:
    :func:`thinfilm_mi.render.modes.current`; ``plugin`` names the BSDF in errors; at most
    ``max_bounces`` base vertices a path."""

    def __init__(self, top, bottom, medium, mode, plugin: str, max_bounces: int):
        self.top, self.bottom, self.medium = top, bottom, medium
        self.mode = mode
        self.max_bounces = int(max_bounces)
        self.plugin = plugin
        #: the base's delta reflection (:class:`~thinfilm_mi.render.layered.delta.DeltaBase`),
        #: or ``None`` where it has none
        self.delta = DeltaBase(self) if bottom.has_delta else None
        self.refresh()

    stack = property(lambda self: self.top.stack, doc="The top's ``KernelStack``.")
    base = property(lambda self: self.bottom.bsdf, doc="The nested BSDF.")

    def refresh(self) -> None:
        """Re-derive the load-time quantities after an edit (the top refreshed first)."""
        self.medium.refresh()

    def traverse(self, callback) -> None:
        """The coat medium's parameters (the top and the bottom expose their own)."""
        self.medium.traverse(callback)

    def parameters_changed(self, keys) -> None:
        """:meth:`refresh` after an edit of ``keys`` (the top refreshed first)."""
        self.refresh()

    def describe(self) -> str:
        """The stack, the media and the base, for ``to_string``."""
        stack = self.top.stack
        return (f"  layers = {stack.describe()},\n  int_ior = {stack.substrate.label},\n"
                f"  ext_ior = {stack.ambient.label},\n  bsdf = {self.bottom.describe()}\n")

    def tracks_gradients(self, si, active) -> bool:
        """Whether a parameter of the top, the coat medium or the nested BSDF carries
        gradients (AD variants; decided when the kernel is traced)."""
        mi = mitsuba_module()
        if not dr.is_diff_v(mi.Float):
            return False
        own = self.medium.values(si, active)
        if self.top.carries_gradients(si, active) or any(dr.grad_enabled(v) for v in own):
            return True
        return self.bottom.carries_gradients()
