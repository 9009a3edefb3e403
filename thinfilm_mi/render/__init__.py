"""The render layer: what the Mitsuba plugins share.

* :mod:`thinfilm_mi.render.kernel` -- ``KernelStack``, the stack a plugin evaluates: the
  composition of what a stack is (:mod:`~thinfilm_mi.render.film_stack`: its films and
  media as textures), how it is planned (:mod:`~thinfilm_mi.render.stack_plan`), built
  (:mod:`~thinfilm_mi.render.stack_build`: its tables and film buffers) and evaluated
  (:mod:`~thinfilm_mi.render.stack_eval`; one side: :mod:`~thinfilm_mi.render.side_eval`;
  both sides of a lossless stack from one: :mod:`~thinfilm_mi.render.mirror`).
* :mod:`thinfilm_mi.render.modes` -- the one place that decides what a plugin returns in
  each variant family (spectral, polarized, RGB/mono).
* :mod:`thinfilm_mi.render.amplitudes` -- Mueller matrices from complex amplitudes.
* :mod:`thinfilm_mi.render.colour_variants` -- colour tables and gradients in RGB/mono variants.
* :mod:`thinfilm_mi.render.textures` -- Mitsuba textures made and read by the plugins.
* :mod:`thinfilm_mi.render.params` -- validation of ``mi.traverse`` edits.
* :mod:`thinfilm_mi.render.reader` -- the one reader of a plugin's properties.
* :mod:`thinfilm_mi.render.microfacet` -- the microfacet pieces the rough plugins share.
"""
from thinfilm_mi.render.kernel import KernelStack
from thinfilm_mi.render.media import SpectralIndex, real_index
from thinfilm_mi.render.params import ParameterGuard

__all__ = ["KernelStack", "ParameterGuard", "SpectralIndex", "real_index"]
