"""One planned side of a stack at a hit (no plugin classes here): unpolarized ``R``
[and ``T``] of a :class:`~thinfilm_mi.render.stack_plan.SidePlan` on ``mi.Spectrum`` (all
wavelengths of a path at once) in float32, from its table, or exactly: from its
films' buffers (:class:`~thinfilm_mi.render.loop.LoopFilms`), else unrolled film by
film from the films' index textures (gradients, incoherent films). Which side is
evaluated, and how both sides of a stack combine, is
:mod:`thinfilm_mi.render.stack_eval`'s (and :mod:`thinfilm_mi.render.mirror`'s).
"""
from __future__ import annotations

from thinfilm_mi.optics.core import Cx
from thinfilm_mi.optics.unpolarized import unpolarized_rt
from thinfilm_mi.render.colour_variants import index_on_wavelengths
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["exact_rt", "side_at_wavelengths", "side_response"]


def side_response(side, si, cos_theta, active, transmission: bool, thickness_scale):
    """``R`` [, ``T``] of the planned ``side`` at the hit: its table, else its films
    exactly. ``cos_theta`` is the (positive) cosine of incidence on the side the
    light comes from; ``thickness_scale``: the thickness texture's value, or ``None``."""
    mi = mitsuba_module()
    # RGB/mono variants come here only for a side without films: any wavelength will do
    wl = si.wavelengths if mi.is_spectral else mi.Spectrum(550.0)
    n0 = side.n0.eval_real(si, active)
    table = side.table
    if table is not None and thickness_scale is None and (
            not transmission or side.opaque or table.channels > 1 or side.lossless):
        n_exit = side.exit.eval_real(si, active) if table.axis.needs_n_exit else None
        res = table.lookup(cos_theta, n0, n_exit, wl, active)
        if not transmission:
            return res[0]
        if side.lossless and table.channels == 1:
            return res[0], 1.0 - res[0]
        return res[0], (mi.UnpolarizedSpectrum(0.0) if side.opaque else res[1])
    exit_ = Cx(side.exit.eval_real(si, active), 0.0) if side.exit_real \
        else side.exit.eval(si, active)
    if side.loop is not None:
        out = side.loop.rt(n0, cos_theta, exit_, wl, transmission, thickness_scale)
    else:
        films = [(ix.eval(si, active), d if thickness_scale is None else d * thickness_scale)
                 for ix, d, _ in side.films]
        out = exact_rt(n0, cos_theta, films, exit_, wl, side.incoherent, transmission)
    if transmission and side.opaque:
        return out[0], mi.UnpolarizedSpectrum(0.0)
    return out


def side_at_wavelengths(side, si, cos_theta, active, transmission: bool, thickness_scale, wl):
    """Exact ``R`` [, ``T``] of ``side`` (every film: no skips, no table) at the
    wavelengths ``wl`` (``mi.Spectrum``) in an RGB/mono variant (the colour gradients)."""
    mi = mitsuba_module()

    def index(ix):
        return Cx(*index_on_wavelengths(ix, si, wl, active))
    n0 = index(side.n0).re
    exit_ = index(side.exit)
    if side.exit_real:
        exit_ = Cx(exit_.re, 0.0)
    films = [(index(ix), d if thickness_scale is None else d * thickness_scale)
             for ix, d, _ in side.films]
    out = exact_rt(n0, cos_theta, films, exit_, wl, side.incoherent, transmission)
    if transmission and side.opaque:
        return out[0], mi.Spectrum(0.0)
    return out


def exact_rt(n0, cos0, films, n_exit, wl, incoherent, transmission):
    """Coherent :func:`~thinfilm_mi.optics.unpolarized.unpolarized_rt`, or the
    incoherent-aware evaluator when some film is beyond the coherence thickness."""
    if any(incoherent):
        from thinfilm_mi.optics.incoherent import incoherent_rt
        return incoherent_rt(n0, cos0, films, n_exit, wl, incoherent, transmission=transmission)
    return unpolarized_rt(n0, cos0, films, n_exit, wl, transmission)
