"""The optics layer: the exact Rouard recursion over Dr.Jit types, incoherent
(thick) films, and the float64 backend. It imports nothing else of the package.

* :mod:`thinfilm_mi.optics.core` -- complex Fresnel coefficients and the recursion
  (``stack_amplitudes``, ``stack_rt``, ``stack_rt_loop``), generic over Dr.Jit types.
* :mod:`thinfilm_mi.optics.incoherent` -- films averaged incoherently (as tmm's ``inc_tmm``).
* :mod:`thinfilm_mi.optics.backend` -- the float64 LLVM backend: numpy in, numpy out.
"""
from thinfilm_mi.optics.core import (
                                     Cx,
                                     StackAmplitudes,
                                     film_attenuation,
                                     fresnel_p,
                                     fresnel_s,
                                     real_loop_applies,
                                     sqrt_decaying,
                                     stack_amplitudes,
                                     stack_rt,
                                     stack_rt_loop,
                                     transmittance_factor_p,
                                     transmittance_factor_s,
)
from thinfilm_mi.optics.incoherent import incoherent_rt

__all__ = ["Cx", "StackAmplitudes", "film_attenuation", "fresnel_p", "fresnel_s",
           "incoherent_rt", "real_loop_applies", "sqrt_decaying", "stack_amplitudes",
           "stack_rt", "stack_rt_loop", "transmittance_factor_p", "transmittance_factor_s"]
