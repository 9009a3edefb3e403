"""Colour tables: a stack's ``R`` and ``T`` integrated against colour matching, for
the RGB and mono variants (no plugin classes here).

Interference needs wavelengths; an RGB or mono render has none. Evaluating the
recursion at three "RGB wavelengths" aliases (a 2 µm film's fringes become false
colour), so in those variants a plugin reads the **spectral quantity integrated
against colour matching**, tabulated at load time with the float64 core:

    R_c(θ) = ∫ w_c(λ) R(λ, θ) dλ / ∫ w_c(λ) dλ

with ``w_c = (M · [x̄, ȳ, z̄])_c · D65`` for ``c`` in linear sRGB (``M``: XYZ to
linear sRGB, Mitsuba's ``xyz_to_srgb``; CIE 1931 2° and D65 from colour-science,
``data/colour_weights.csv``), and ``w = ȳ · D65`` (luminance Y, V(λ) = ȳ) in mono
variants. Each channel is normalised so that a perfect reflector gives exactly 1:
this is what Mitsuba's spectral pipeline does with a white (D65-upsampled)
emitter and an RGB film, so an RGB render and a spectral render of a scene agree.

**Wavelength sampling.** Adaptive Simpson (:func:`integrate`): every node starts
on a :data:`FIRST_STEP` (0.5 nm) grid over 360-830 nm and an interval is halved,
down to 0.5/2^7 nm, until its error estimate is within its share of
:data:`LAMBDA_TOLERANCE` (1e-5 over the range). Why this sampling: measured at
normal incidence, Y of a 30-film 2.3/1.46 stack on Al on uniform grids against a
0.005 nm one differs by 4.1e-5 at 1 nm, 3.2e-8 at 0.2 nm and 2.0e-9 at 0.05 nm
(one 500 nm SiO2 film on Au: 4.8e-6, 1.9e-7, 1.8e-8), so the cavity resonances
(~0.1 nm wide) need steps of ~0.2 nm where they are and nowhere else; the
adaptive rule spends them there. ``tests/render/test_colour_variants.py`` checks the tables against
colour-science's observer and D65 on a 0.01 nm grid: ΔE2000 <= 0.1 (measured
<= 0.03) for 1-30 films up to 89°.

**Angle (and thickness-scale) axis.** Linear interpolation on nodes uniform in
``w = 1 - sqrt(x)``, ``x = (π/2 - θ)/(π/2)`` (:data:`~thinfilm_mi.tabulate.axes.PLAIN`: nodes
quadratically closer towards grazing incidence); a side that totally reflects
at one critical angle (non-dispersive media) is split there. From
:data:`FIRST_NODES` per segment, each interval gets its exact midpoint; where
the 4-point rule predicted it within :data:`TOLERANCE_DE` and
:data:`TOLERANCE_ABS` the interval is done (finer nodes are the rule's), else
both halves are checked again, up to :data:`MAX_NODES` per segment (:func:`build`).
The texels are then subdivided by the same rule until linear interpolation is
within :data:`LINEAR_DE` and :data:`LINEAR_ABS` of it. With a ``thickness``
texture the table is 2-D, over the angle and the thickness scale ``s`` in
``[0, max of the texture]``, refined on both axes.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import drjit as dr
import numpy as np

from thinfilm_mi.colour.cie import colour_differences, colour_weights, normalised_weights
from thinfilm_mi.materials.model import SPECTRAL_RANGE
from thinfilm_mi.tabulate.base import BuildReport, linear_texture, opaque_float
from thinfilm_mi.tabulate.refine import (
    Budget,
    LinearAxis,
    interleave,
    midpoints4,
    power_of_two_step,
    subdivide,
)

__all__ = ["CHUNK_POINTS", "ColourTable", "FIRST_NODES", "FIRST_SCALE_NODES", "FIRST_STEP",
           "LAMBDA_RELATIVE", "LAMBDA_TOLERANCE", "LINEAR_ABS", "LINEAR_DE", "MAX_FIRST_STEP",
           "MAX_LAMBDA_LEVEL", "MAX_NODES", "MAX_NODES_2D", "MAX_TEXELS_2D", "Source",
           "TOLERANCE_ABS", "TOLERANCE_ABS_2D", "TOLERANCE_DE", "TOLERANCE_DE_2D", "build",
           "channel_count", "close_each", "first_wavelength_step", "integrate", "integrate_points",
           "settings"]

#: The nodes are dense enough when the 4-point rule predicts the integrals at
#: the midpoints within this CIEDE2000 (as colours under D65: R, and T, of every
#: channel; L* alone in mono) and :data:`TOLERANCE_ABS` in every channel. The
#: table then keeps the exact midpoints too: its grid is twice as fine as the
#: one checked, so its own error is ~1/16 of the check's for a smooth function
#: (tests/render/test_colour_variants.py: the tables are within ΔE2000 0.03 of a 0.01 nm reference).
TOLERANCE_DE = 0.05
#: The same for the nodes of a 2-D table (a ``thickness`` texture): the cells
#: multiply by four at every level, and ΔE2000 0.2 is a fifth of a just noticeable
#: difference (tests/render/test_colour_variants.py checks such a table against the reference).
TOLERANCE_DE_2D = 0.2
TOLERANCE_ABS_2D = 3e-3
TOLERANCE_ABS = 1e-3
#: Finest wavelength step tried (nm): 2^-7 nm, below the resonances of 30-film
#: metal cavities (~0.1 nm wide, narrower towards grazing incidence).
MAX_LAMBDA_LEVEL = 7
#: Max abs error in any channel of an integral: the sum of the intervals' error
#: estimates (1e-5: ΔE2000 <= 0.01 for a dark colour, Y ~ 0.001) ...
LAMBDA_TOLERANCE = 1e-5
#: ... or this fraction of the integral, where that is larger (1e-4 of a bright
#: colour: ΔE2000 ~ 0.005; L* varies as Y^(1/3), so a relative error is what the
#: eye sees).
LAMBDA_RELATIVE = 1e-4
#: Largest first step (nm): 16 steps per interference fringe of the stack's whole
#: optical thickness (:func:`first_wavelength_step`) but never coarser than this. It divides
#: 470 nm and its halves reach the 1 nm knots of the colour-matching data, where the
#: weights have kinks (D65's slope jumps at 430 nm): a 4 nm step (470/118 nm in
#: fact) put kinks inside intervals and refined them to the finest level.
MAX_FIRST_STEP = 2.0
#: First wavelength step (nm) of the adaptive integration; it divides the 1 nm
#: spacing of the colour-matching data, so the weights are linear on every interval.
FIRST_STEP = 0.5
#: The lookup's linear interpolation between texels is dense enough when it is
#: within this CIEDE2000 and this abs error per channel of the 4-point rule at
#: every midpoint (texels are cheap to add, integrals are not).
LINEAR_DE = 0.02
LINEAR_ABS = 2e-4
#: Nodes of the first grid along the angle axis, and along the thickness scale.
FIRST_NODES = 17
FIRST_SCALE_NODES = 17
#: Most nodes along one axis, and texels (nodes of both axes) of a 2-D table
#: (whose integrals stop at MAX_NODES_2D nodes per axis).
MAX_NODES = 1025
MAX_NODES_2D = 257
MAX_TEXELS_2D = 1 << 17
#: Points (angle nodes x wavelengths) per float64 kernel launch of a build.
CHUNK_POINTS = 1 << 21


def settings() -> tuple:
    """The tolerances and limits a table depends on (part of the cache key)."""
    return (TOLERANCE_DE, TOLERANCE_ABS, TOLERANCE_DE_2D, TOLERANCE_ABS_2D, LAMBDA_TOLERANCE,
            LAMBDA_RELATIVE, FIRST_STEP, MAX_FIRST_STEP, MAX_LAMBDA_LEVEL, LINEAR_DE,
            LINEAR_ABS, FIRST_NODES, FIRST_SCALE_NODES, MAX_NODES, MAX_NODES_2D, MAX_TEXELS_2D)


def close_each(a: np.ndarray, b: np.ndarray, channels: int, axis: int,
               de: float = None, abs_: float = None) -> np.ndarray:
    """Per index along ``axis``: whether every colour there agrees within ``de``
    (CIEDE2000, default :data:`TOLERANCE_DE`) and every channel within ``abs_``
    (default :data:`TOLERANCE_ABS`)."""
    de = TOLERANCE_DE if de is None else de
    abs_ = TOLERANCE_ABS if abs_ is None else abs_
    a, b = np.moveaxis(a, axis, 0), np.moveaxis(b, axis, 0)
    n = a.shape[0]
    d_abs = np.abs(a - b).reshape(n, -1).max(axis=1)
    d_col = colour_differences(a, b, channels).reshape(n, -1).max(axis=1)
    return (d_abs <= abs_) & (d_col <= de)


def first_wavelength_step(optical_thickness: float) -> float:
    """The first wavelength step (nm) for a stack of optical thickness ``Σ n_j d_j``
    (largest real index over 360-830 nm): the narrowest fringe of all the films
    together, ``Δλ = λ² / (2 Σ n_j d_j)`` at 360 nm, sampled 16 times, as a
    power-of-two multiple of :data:`FIRST_STEP` in ``[FIRST_STEP,
    MAX_FIRST_STEP]``. Deep stacks, whose cavity resonances are far narrower than
    a fringe, get :data:`FIRST_STEP` and the refinement finds the rest."""
    if optical_thickness <= 0:
        return MAX_FIRST_STEP
    return power_of_two_step(SPECTRAL_RANGE[0] ** 2 / (2.0 * optical_thickness) / 16.0,
                             FIRST_STEP, MAX_FIRST_STEP)


@dataclass
class Source:
    """What a table integrates: ``evaluate(cos, scale, wl)`` returns the spectral
    values at the points ``(cos[i], wl[i])`` (flat arrays) for the film thickness
    scale ``scale`` (a float, or ``None``), shape ``(len cos, k)`` (``R`` [, ``T``]);
    ``channels`` are the output channels this source serves (all of them unless
    the media are given per channel, e.g. ``eta``/``k`` as ``rgb``)."""
    evaluate: object
    channels: list = field(default_factory=list)
    #: the first wavelength step (nm, :func:`first_wavelength_step`)
    first_step: float = FIRST_STEP


def channel_count(kind: str) -> int:
    """The output channels of the colour weights ``kind`` (``"rgb"``: 3, ``"mono"``: 1),
    as :func:`~thinfilm_mi.colour.cie.normalised_weights` gives them."""
    return normalised_weights(kind).shape[0]


def _weights(kind: str, channels: list):
    """``wl -> ŵ_c(wl)`` (shape ``(n, len channels)``): the channel weights
    normalised to a unit integral (exact: they are linear between the 1 nm knots,
    where every interval of :func:`integrate` starts and ends)."""
    full = normalised_weights(kind)[channels]
    lam = colour_weights()[:, 0]

    def at(wl):
        return np.stack([np.interp(wl, lam, f) for f in full], axis=-1)
    return at


def integrate(sources: list, weights_kind: str, cos: np.ndarray, scales: list) -> np.ndarray:
    """Integrals of every source at the angle nodes ``cos`` and thickness scales
    ``scales`` (``[None]`` without a texture): shape ``(len scales, len cos,
    k * C)``, channel-minor (``R`` of every channel, then ``T``).

    Adaptive Simpson over wavelength, vectorised over nodes and intervals: every
    node starts on a :data:`FIRST_STEP` grid over 360-830 nm; an interval whose
    trapezoid estimates on it and on its halves differ by more than its share of
    :data:`LAMBDA_TOLERANCE` (``(T_half - T) / 3``, the trapezoid's error
    estimate, against ``LAMBDA_TOLERANCE * h / 470 nm``) is split, down to
    ``FIRST_STEP / 2^MAX_LAMBDA_LEVEL``; accepted intervals contribute their
    Simpson value ``T_half + (T_half - T) / 3``.
    """
    C = channel_count(weights_kind)
    out = None
    for src in sources:
        w = _weights(weights_kind, src.channels)
        res = np.stack([_adaptive(src.evaluate, w, cos, s, src.first_step)
                        for s in scales])                                # (S, m, k, c)
        if out is None:
            out = np.zeros(res.shape[:3] + (C,))
        out[..., src.channels] = res
    S, m, k, _ = out.shape
    return out.reshape(S, m, k * C)


def integrate_points(sources: list, weights_kind: str, cos: np.ndarray,
                     scale: np.ndarray) -> np.ndarray:
    """:func:`integrate` at the points ``(cos[i], scale[i])`` (flat arrays, one
    batch): shape ``(len cos, k * C)``."""
    C = channel_count(weights_kind)
    out = None
    for src in sources:
        res = _adaptive(src.evaluate, _weights(weights_kind, src.channels), cos,
                        np.asarray(scale, np.float64), src.first_step)     # (m, k, c)
        if out is None:
            out = np.zeros(res.shape[:2] + (C,))
        out[..., src.channels] = res
    return out.reshape(out.shape[0], -1)


def _adaptive(evaluate, w, cos: np.ndarray, scale, first_step: float = FIRST_STEP) -> np.ndarray:
    """:func:`integrate` of one source at one scale: shape ``(len cos, k, c)``."""
    lo, hi = SPECTRAL_RANGE
    n = int(round((hi - lo) / first_step))
    grid = lo + np.arange(n + 1) * ((hi - lo) / n)
    m = cos.size
    per_node = isinstance(scale, np.ndarray)     # a scale per node (2-D tables)

    def scale_at(nodes):
        return scale[nodes] if per_node else scale
    f = _evaluate_chunked(evaluate, np.repeat(cos, n + 1),
                          np.repeat(scale, n + 1) if per_node else scale, np.tile(grid, m))
    g = f.reshape(m, n + 1, -1)[..., None] * w(grid)[None, :, None, :]      # (m, n+1, k, c)
    total = np.zeros(g.shape[:1] + g.shape[2:])
    node = np.repeat(np.arange(m), n)
    a = np.tile(grid[:-1], m)
    ga, gb = g[:, :-1].reshape((-1,) + g.shape[2:]), g[:, 1:].reshape((-1,) + g.shape[2:])
    h = (hi - lo) / n
    # the tolerance of a node: absolute for dark colours, relative for bright ones
    # (the trapezoid rule on the first grid estimates the integral)
    first = (0.5 * h * (ga + gb)).reshape(m, n, -1)
    tol = np.maximum(LAMBDA_TOLERANCE, LAMBDA_RELATIVE * np.abs(first.sum(axis=1)).max(axis=1))
    levels = MAX_LAMBDA_LEVEL + int(round(np.log2(first_step / FIRST_STEP)))
    for level in range(levels + 1):
        mid = a + 0.5 * h
        gm = (_evaluate_chunked(evaluate, cos[node], scale_at(node), mid)[..., None]
              * w(mid)[:, None, :])
        coarse = 0.5 * h * (ga + gb)
        fine = 0.25 * h * (ga + 2.0 * gm + gb)
        err = np.abs(fine - coarse).reshape(len(a), -1).max(axis=1) / 3.0
        ok = (err <= tol[node] * h / (hi - lo)) | (level == levels)
        np.add.at(total, node[ok], (fine + (fine - coarse) / 3.0)[ok])
        if np.all(ok):
            break
        split = ~ok
        node = np.repeat(node[split], 2)
        a = np.stack([a[split], mid[split]], axis=1).ravel()
        ga, gm_s, gb = ga[split], gm[split], gb[split]
        ga, gb = (np.stack([ga, gm_s], axis=1).reshape((-1,) + ga.shape[1:]),
                  np.stack([gm_s, gb], axis=1).reshape((-1,) + ga.shape[1:]))
        h *= 0.5
    return total


def _evaluate_chunked(evaluate, cos: np.ndarray, scale, wl: np.ndarray) -> np.ndarray:
    if cos.size == 0:
        return np.zeros((0, 1))
    def chunk(i):
        sc = scale[i:i + CHUNK_POINTS] if isinstance(scale, np.ndarray) else scale
        return evaluate(cos[i:i + CHUNK_POINTS], sc, wl[i:i + CHUNK_POINTS])
    parts = [chunk(i) for i in range(0, cos.size, CHUNK_POINTS)]
    return np.concatenate(parts, axis=0)


class ColourTable:
    """A side's integrated ``R`` [and ``T``] per channel, over the angle (and the
    thickness scale): a float32 ``Texture1f``/``Texture2f`` with linear filtering."""

    def __init__(self, values: np.ndarray, axis: LinearAxis, channels: int, transmission: bool,
                 scale_max: float | None, report: BuildReport | None = None):
        #: what the build did (:func:`build`)
        self.report = report
        self.axis = axis
        self.channels = channels
        self.transmission = transmission
        self.scale_max = scale_max
        self.values = values                      # float64 (S, nu, k*C) for tests
        self.nbytes = values.size * 4
        self.ns, self.nu = values.shape[0], values.shape[1]
        self.texture = linear_texture(values if scale_max is not None else values[0])

        self._nu = opaque_float(self.nu)
        self._inv_u = opaque_float(1.0 / self.nu)
        self._n0 = opaque_float(axis.n0)
        self._n_exit = opaque_float(axis.n_exit)
        if scale_max is not None:
            self._s = opaque_float((self.ns - 1) / scale_max if scale_max > 0 else 0.0)
            self._inv_s = opaque_float(1.0 / self.ns)

    @property
    def texels(self) -> int:
        return self.ns * self.nu

    def lookup(self, cos_i, scale=None, active=True):
        """``(R, T)`` as ``mi.Spectrum`` (``T`` ``None`` unless tabulated). Not
        clamped: the sRGB channels of a saturated interference colour lie outside
        [0, 1] (the integrals have negative weights), exactly as a spectral render
        converted to sRGB gives them; Y stays within [0, 1]."""
        import mitsuba as mi
        cos_i = dr.clip(cos_i, 0.0, 1.0)
        sin_i = dr.safe_sqrt((1.0 - cos_i) * (1.0 + cos_i))
        x = self.axis.angle.texel(cos_i, sin_i, self._n0, self._n_exit, self._nu)
        u = (x + 0.5) * self._inv_u
        if self.scale_max is None:
            res = self.texture.eval(mi.Point1f(u), active)
        else:
            y = dr.maximum(scale, 0.0) * self._s
            res = self.texture.eval(mi.Point2f(u, (y + 0.5) * self._inv_s), active)
        C = self.channels
        R = mi.Spectrum(*res[:C]) if C > 1 else mi.Spectrum(res[0])
        if not self.transmission:
            return R, None
        return R, (mi.Spectrum(*res[C:2 * C]) if C > 1 else mi.Spectrum(res[C]))


def _linear_ok(values: np.ndarray, axis: int, mirror: bool, channels: int) -> bool:
    """Whether linear interpolation between the nodes along ``axis`` is within
    :data:`LINEAR_DE` and :data:`LINEAR_ABS` of the 4-point rule at every midpoint."""
    f = np.moveaxis(values, axis, 0)
    lin = 0.5 * (f[:-1] + f[1:])
    mid = np.moveaxis(midpoints4(values, axis, mirror), axis, 0)
    return bool(np.all(close_each(lin, mid, channels, 0, LINEAR_DE, LINEAR_ABS)))


def _counted(evaluate, report: BuildReport):
    """``evaluate`` counting its points into ``report["points"]``."""
    def counting(cos, scale, wl):
        report["points"] += cos.size
        return evaluate(cos, scale, wl)
    return counting


def build(sources: list, weights_kind: str, transmission: bool, axis: LinearAxis,
          scale_max: float | None = None, fixed_scale: float | None = None,
          report: BuildReport | None = None) -> ColourTable:
    """The :class:`ColourTable` of one side (see the module docstring): over the
    angle, and the thickness scale in ``[0, scale_max]`` if given (:func:`_build_2d`);
    with ``fixed_scale`` every film's thickness is scaled by it (a constant
    ``thickness`` texture).

    Integrals are computed only where they are needed: every interval of the
    first grid gets its exact midpoint; an interval whose midpoint the 4-point
    rule predicted within the tolerances (:func:`close_each`) is finished, and
    its finer nodes are the rule's; one it mispredicted is split and both
    halves are checked again (a critical angle, the grazing rise of a
    resonant stack). The exact midpoints are kept.

    What the build did is written into ``report`` (a :class:`BuildReport`, also the
    table's ``report``): ``points`` (spectral values evaluated), ``rounds``
    (refinement levels), ``texels``."""
    report = BuildReport() if report is None else report
    report.update({"kind": axis.angle.name, "points": 0, "rounds": 0, "result": "building"})
    sources = [replace(src, evaluate=_counted(src.evaluate, report)) for src in sources]
    if scale_max is not None:
        return _build_2d(sources, weights_kind, transmission, axis, scale_max, report)
    C = channel_count(weights_kind)
    seg = axis.segments
    nu = FIRST_NODES * seg
    values = integrate(sources, weights_kind, axis.cos(nu), [fixed_scale])   # (1, nu, kC)
    open_u = np.ones(nu - seg, bool)                    # intervals along the angle
    while open_u.any() and nu // seg < MAX_NODES:
        mid = axis.predicted(values)
        idx = np.flatnonzero(open_u)
        exact = integrate(sources, weights_kind, axis.midpoints(nu)[idx], [fixed_scale])
        bad = idx[~close_each(mid[:, idx], exact, C, axis=1)]
        mid[:, idx] = exact
        values, nu = axis.interleave(values, mid), axis.refined(nu)
        report["rounds"] += 1
        open_u = np.zeros(nu - seg, bool)
        open_u[2 * bad], open_u[2 * bad + 1] = True, True
    return _for_lookup(values, axis, C, transmission, None, MAX_NODES * seg * 4, report)


def _for_lookup(values: np.ndarray, axis: LinearAxis, C: int, transmission: bool,
                scale_max: float | None, max_texels: int, report: BuildReport) -> ColourTable:
    """The table of ``values`` (scales x angles x channels), with texels added by
    the 4-point rule (along the angle, then the scale) until linear interpolation,
    the lookup, is within :data:`LINEAR_DE` / :data:`LINEAR_ABS` of it, or
    ``max_texels`` would be exceeded."""
    budget = Budget(points=0, texels=max_texels)
    ns, nu = values.shape[0], values.shape[1]
    while budget.allows(texels=nu * ns * 2):
        if all(_linear_ok(a, 1, axis.mirror, C) for a in axis.split(values)):
            break
        values, nu = axis.interleave(values, axis.predicted(values)), axis.refined(nu)
    while scale_max is not None and budget.allows(texels=nu * ns * 2):
        if _linear_ok(values, 0, False, C):
            break
        values, ns = subdivide(values, 0), 2 * ns - 1
    report.update({"result": "table", "texels": values.shape[0] * values.shape[1]})
    return ColourTable(values, axis, C, transmission, scale_max, report)


def _build_2d(sources: list, weights_kind: str, transmission: bool, axis: LinearAxis,
              scale_max: float, report: BuildReport) -> ColourTable:
    """:func:`build` over the angle and the thickness scale ``s`` in ``[0,
    scale_max]``, refined cell by cell: every level doubles both axes; a new
    node is predicted by the 4-point rule (along its axis; a cell centre along
    both) and computed exactly only next to an open cell. A cell stays open
    while one of its new nodes was mispredicted (:func:`close_each`); its four
    children then are checked again. Every exact integral of one level is one
    batch (:func:`integrate_points`), so interference colours that change with
    the thickness but little with the angle cost integrals along ``s`` only."""
    C = channel_count(weights_kind)
    seg = axis.segments
    nu, ns = FIRST_NODES * seg, FIRST_SCALE_NODES
    S = np.linspace(0.0, scale_max, ns)
    values = integrate(sources, weights_kind, axis.cos(nu), list(S))      # (ns, nu, kC)
    open_ = np.ones((ns - 1, nu - seg), bool)                             # cells (s, u)

    while open_.any() and nu // seg < MAX_NODES_2D and ns < MAX_NODES_2D:
        m = nu // seg
        # the intervals either side of every angle node (-1 at a segment's ends)
        j = np.arange(nu)
        left = np.where(j % m > 0, (j // m) * (m - 1) + j % m - 1, -1)
        right = np.where(j % m < m - 1, (j // m) * (m - 1) + j % m, -1)
        um = axis.predicted(values)                                      # (ns, nu-seg)
        sm = midpoints4(values, 0)                                      # (ns-1, nu)
        cm = midpoints4(um, 0)                                          # (ns-1, nu-seg)
        need_um = np.zeros(um.shape[:2], bool)
        need_um[:-1] |= open_
        need_um[1:] |= open_
        pad = np.concatenate([open_, np.zeros((ns - 1, 1), bool)], axis=1)
        need_sm = pad[:, left] & (left >= 0)[None, :] | pad[:, right] & (right >= 0)[None, :]
        cos_n, cos_m = axis.cos(nu), axis.midpoints(nu)
        s_mid = 0.5 * (S[:-1] + S[1:])
        sets = [(um, need_um, S[:, None], cos_m[None, :]),
                (sm, need_sm, s_mid[:, None], cos_n[None, :]),
                (cm, open_, s_mid[:, None], cos_m[None, :])]
        cos_pts = np.concatenate([np.broadcast_to(c, need.shape)[need] for _, need, _, c in sets])
        s_pts = np.concatenate([np.broadcast_to(sc, need.shape)[need] for _, need, sc, _ in sets])
        exact = integrate_points(sources, weights_kind, cos_pts, s_pts)
        bad = []
        start = 0
        for grid, need, _, _ in sets:
            k = int(need.sum())
            ok = close_each(grid[need], exact[start:start + k], C, axis=0,
                            de=TOLERANCE_DE_2D, abs_=TOLERANCE_ABS_2D)
            grid[need] = exact[start:start + k]
            miss = np.zeros(need.shape, bool)
            miss[need] = ~ok
            bad.append(miss)
            start += k
        bad_um, bad_sm, bad_cm = bad
        # a cell failed if its centre, an edge midpoint along u (below, above) or
        # one along s (left, right node) was mispredicted
        u_int = np.arange(nu - seg)
        node_l = (u_int // (m - 1)) * m + u_int % (m - 1)              # its left node
        failed = (bad_cm | bad_um[:-1] | bad_um[1:] | bad_sm[:, node_l]
                  | bad_sm[:, node_l + 1]) & open_
        values = interleave(axis.interleave(values, um), axis.interleave(sm, cm), 0)
        nu, ns = axis.refined(nu), 2 * ns - 1
        report["rounds"] += 1
        S = np.linspace(0.0, scale_max, ns)
        open_ = np.zeros((ns - 1, nu - seg), bool)
        fs, fu = np.nonzero(failed)
        for ds in (0, 1):
            for du in (0, 1):
                open_[2 * fs + ds, 2 * fu + du] = True
    return _for_lookup(values, axis, C, transmission, scale_max, MAX_TEXELS_2D, report)
