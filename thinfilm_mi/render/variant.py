"""The variant the plugins run in: :func:`check_variant` refuses the ones a plugin
cannot serve, and :func:`spectral_mean` averages a spectrum in every variant. (A kernel
input that never recompiles: :func:`thinfilm_mi.tabulate.base.opaque_float`.)
"""
from __future__ import annotations

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.llvm import require_llvm
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["check_variant", "spectral_mean"]


def check_variant(plugin: str) -> None:
    """Raise if the current Mitsuba variant cannot run the thin-film plugins.

    ``*_spectral`` variants return spectra, ``*_spectral_polarized`` ones
    Mueller matrices, RGB and mono variants colours integrated against colour
    matching (:mod:`thinfilm_mi.render.modes`). Polarized RGB or mono variants are
    refused: a Mueller matrix integrated over wavelengths is not the product of
    integrated amplitudes. LLVM variants, and every variant that builds colour
    tables (float64 on the LLVM backend), pass through :func:`require_llvm`.
    """
    mi = mitsuba_module()
    variant = mi.variant()
    if variant is None or (mi.is_polarized and not mi.is_spectral):
        raise ThinFilmError(
            f"{plugin}: the Mitsuba variant {variant!r} is not supported; polarized "
            "thin films need wavelengths: use a *_spectral_polarized variant such as "
            "'llvm_ad_spectral_polarized' (or an unpolarized RGB, mono or spectral one)"
        )
    if variant.startswith("llvm") or not mi.is_spectral:
        require_llvm()


def spectral_mean(x):
    """Average of a spectrum over its wavelengths (a Float), in every variant (a
    scalar variant's spectrum is one array of four numbers)."""
    return sum(x[i] for i in range(len(x))) * (1.0 / len(x))
