r"""The random walk (no plugin classes here): the unbiased estimator of the sum over paths
between a smooth top and any bottom (a position-free walk, Guo, Hašan, Yan and Zhao 2018;
pbrt-v4's ``LayeredBxDF``), registered in
:func:`~thinfilm_mi.render.layered.nested.sum_estimator` where the bottom has no closed
form (:mod:`thinfilm_mi.render.layered.forms`).

**The estimate** (:meth:`RandomWalk.sum`): from ``w_0 = ω_i'``, at every base vertex ``k``
the contribution ``β_k f_b(w_k, ω_o') cos θ_o'`` (the base's ``eval``, towards the fixed
inner direction of ``ω_o``: next-event estimation through the smooth top, which refracts
``ω_o'`` to ``ω_o`` deterministically); then the base is sampled, ``w``, weight ``g``, and
the walk goes on reflected by the underside: ``β_{k+1} = β_k g R_in(θ_w) A(w)²``,
``w_{k+1} = (-w_x, -w_y, w_z)``. The first term is exact (``w_0`` is fixed); later ones
are unbiased estimates of the interreflection series. **The link**: the second vertex's
term, the integral ``∫ f_b(ω_i', w) cos θ_w U(w̄) f_b(w̄, ω_o') cos θ_o' dw`` over the
direction that reaches it, is estimated by two strategies combined by Veach's power
heuristic: the walk's own step (its density ``p_f``: the step's at ``ω_i'``), and a
*reverse sample* ``v`` drawn from the base at ``ω_o'`` (its non-delta lobes; density
``p_v``: an exact density too, as pbrt-v4's ``LayeredBxDF`` pre-samples its exit), linked
from the first vertex: ``f_b(ω_i', v̄) cos θ_v U(v) f_b(v, ω_o') cos θ_o' / p_v``. The
light a glossy base sends beyond the critical angle of ``ω_o'``'s lobe, which total
internal reflection traps, reaches ``ω_o'`` by the link rather than by the chance that the
walk's own sample falls there. Later vertices have no link (each would cost two more calls
of the base per vertex, for paths already spread by a bounce). A delta step (a Dirac
density) is the walk's alone. **The steps** (:meth:`RandomWalk.steer`): a base sample
inside the top's escape cone, where most of the light leaves the layer, is kept with
probability :data:`ESCAPE_KEEP`, else unfolded beyond the critical angle
(:func:`~thinfilm_mi.render.layered.escape.unfold`), where total internal reflection keeps
the light; the step's weight is ``f_b cos θ / p`` by the mixture's density ``p``
(:meth:`RandomWalk.step_pdf`). The throughput of trapped light so falls at every vertex by
the share of the base's lobe that could escape there, rather than staying whole until a
sample escapes: its energy reaches ``ω_o'`` along a decaying throughput, not by a walk of
random length (whose long ones were the heaviest sample weights). Russian roulette from
:data:`RR_DEPTH` vertices on, of walks whose throughput is below :data:`ROULETTE_BELOW`
(:func:`roulette`; unbiased); the walk stops after ``max_bounces`` base vertices: the paths
with more are dropped (the link too where ``N = 1``). For a Lambertian base of albedo ``ρ``
each vertex sends back ``ρ R̄`` of what it receives (``R̄``: the underside's hemispherical
reflectance), so the dropped energy is at most ``(ρ R̄)^N / (1 - ρ R̄)`` of the light that
entered: ``0.596^64/0.404 ≈ 1e-14`` for a bare ``η = 1.5`` coat over white. A base that
sends its light beyond the critical angle meets ``R_in = 1`` there and may lose more
(``tests/render/layered/test_walk.py`` measures the truncation at ``N = 1``). Random
numbers: a PCG32 seeded from the sample's numbers in ``sample`` and from a TEA hash of the
two directions in ``eval`` (as pbrt-v4's ``LayeredBxDF``), so that ``eval`` repeats its
estimate for the same pair of directions.
"""
from __future__ import annotations

import struct

import drjit as dr

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.layered.bottom import base_interaction, intensity
from thinfilm_mi.render.layered.escape import critical_cosine, fold, unfold
from thinfilm_mi.render.textures import mitsuba_module

__all__ = ["DEFAULT_MAX_BOUNCES", "RR_DEPTH", "ROULETTE_BELOW", "ESCAPE_KEEP", "RandomWalk", "eval_seed",
           "sample_seed", "logical_not", "power_heuristic", "ratio", "roulette"]

#: Default cap on the base vertices of a walk (``max_bounces``); its bias is stated in
#: the module docstring.
DEFAULT_MAX_BOUNCES = 64
#: Russian roulette starts after this many base vertices.
RR_DEPTH = 3
#: Russian roulette plays walks whose throughput is below this: a survivor carries it on, so
#: a trapped walk's tail adds its terms at this throughput (the steps' decay brings it there).
ROULETTE_BELOW = 0.1
#: The probability that a step keeps a base sample inside the top's escape cone (else it is
#: unfolded beyond the critical angle, :meth:`RandomWalk.steer`).
ESCAPE_KEEP = 0.5


def logical_not(mask):
    """``~mask`` (a Python bool in scalar variants, where ``~True`` is -2)."""
    return ~mask if dr.is_array_v(mask) else not mask


def _shl(x, k: int):
    """``x << k`` on 32 bits (Python ints in scalar variants do not wrap)."""
    return (x << k) & 0xFFFFFFFF if isinstance(x, int) else x << k


def _bits(x):
    """The bits of a float32 as a ``UInt32`` (an int in scalar variants)."""
    mi = mitsuba_module()
    if not dr.is_array_v(mi.Float):
        return struct.unpack("<I", struct.pack("<f", float(x)))[0]
    return dr.reinterpret_array(mi.UInt32, mi.Float(x))


def eval_seed(wi, wo):
    """A hash of the two directions (pbrt-v4's ``LayeredBxDF`` seeds ``f()`` so)."""
    mi = mitsuba_module()
    a = mi.sample_tea_32(_bits(wi.x) ^ _shl(_bits(wi.z), 7), _bits(wi.y), 4)
    b = mi.sample_tea_32(_bits(wo.x) ^ _shl(_bits(wo.z), 7), _bits(wo.y) ^ a[1], 4)
    return a[0] ^ b[1], b[0]


def sample_seed(sample1, sample2):
    """A hash of a sample's numbers (``sample`` seeds the walk so)."""
    mi = mitsuba_module()
    seed = (_bits(sample1) ^ _shl(_bits(sample2.y), 16), _bits(sample2.x))
    return mi.sample_tea_32(seed[0], seed[1], 4)


class RandomWalk:
    """The random walk of ``layer`` (a :class:`~thinfilm_mi.render.layered.nested.NestedEstimator`:
    its top's underside, its bottom, its coat medium and ``max_bounces``)."""

    def __init__(self, layer):
        self.layer = layer

    def refresh(self) -> None:
        """Nothing to re-derive after an edit (the walk reads the parameters at each call)."""

    def sum(self, ctx_mode, si, w0, wo_in, seed, active):
        """``Σ_k β_k f_b(w_k, ω_o') cos θ_o'`` from ``w_0 = w0`` (module docstring), the
        PCG32 seeded with ``seed`` (two ``UInt32``).

        Gradients: the walk runs detached, then again with the same random numbers
        (:meth:`_walk` given ``total``), adding per vertex what the parameters change there, as
        Mitsuba's ``prb`` replays a path: ``dW = Σ_j β_j de_j + Σ_j dlog(g_j r_j) (W -
        W_{≤j})`` with ``e_j`` vertex ``j``'s own terms (the base's ``eval`` towards
        ``ω_o'``, MIS-weighted, and at the first vertex the link), ``g_j r_j`` the step's
        base weight (the base's ``eval`` over its detached pdf at the sampled
        direction: sampling decisions are detached; at a delta vertex, whose ``eval`` is
        0, the replayed sample's weight times its pdf) and underside, and ``W - W_{≤j}``
        what the walk gathered after vertex ``j``. Every term depends on the parameters
        through its own vertex only, the sum-style loop Dr.Jit differentiates in reverse
        mode without storing the trajectory."""
        if not self.layer.tracks_gradients(si, active):
            return self._walk(ctx_mode, si, w0, wo_in, seed, active, None)
        if self.layer.mode.polarized:
            # the walk's sum after vertex j is a matrix product β_j s_j R_j: its derivative
            # needs the suffix R_j, which a forward loop does not have (the scalar replay
            # divides by β_j s_j instead; a Mueller product of depolarizers is singular)
            raise ThinFilmError(f"{self.layer.plugin}: gradients in polarized variants over a walked "
                                f"base ({self.layer.base.class_name()}) are not supported (the "
                                "replay's per-vertex ratios are per wavelength, not per "
                                "Mueller matrix); they are over a pure-delta base and over "
                                "Mitsuba's diffuse without coat_sigma_a (no walk)")
        with dr.suspend_grad():
            total = self._walk(ctx_mode, si, w0, wo_in, seed, active, None)
        surrogate = self._walk(ctx_mode, si, w0, wo_in, seed, active, total)
        return total + (surrogate - dr.detach(surrogate))

    def _reverse(self, ctx_mode, si, wo_in, rng, active, replay):
        """The walk's reverse sample: ``v`` drawn from the base at ``ω_o'`` (its non-delta
        lobes), the second vertex's direction of the link; returns ``(v̄,
        p_v, r, ok)`` with ``v̄ = (-v_x, -v_y, v_z)`` (the direction the linking vertex
        sends the light to), ``p_v`` its density and ``r = U(v) e(v) / p_v`` (the
        underside, then the base's ``eval`` at ``v`` towards ``ω_o'``; attached in the
        replay, ``v`` and ``p_v`` never)."""
        mi = mitsuba_module()
        base = self.layer.base
        with dr.suspend_grad():
            s1 = rng.next_float32()
            s2 = mi.Point2f(rng.next_float32(), rng.next_float32())
            bs, _ = base.sample(self.layer.bottom.smooth_context(ctx_mode),
                                base_interaction(si, wo_in), s1, s2, active)
        ok = active & (bs.wo.z > 0) & (bs.pdf > 0)
        with dr.suspend_grad(when=not replay):
            e = base.eval(mi.BSDFContext(ctx_mode), base_interaction(si, bs.wo), wo_in, ok)
            r = self.layer.underside(si, bs.wo, ok) * e / dr.select(ok, bs.pdf, 1.0)
        mirrored = mi.Vector3f(-bs.wo.x, -bs.wo.y, bs.wo.z)
        return mirrored, bs.pdf, dr.select(ok, r, dr.zeros(mi.Spectrum)), ok

    def _walk(self, ctx_mode, si, w0, wo_in, seed, active, total):
        """The walk (``total`` None), or its replay carrying the gradients (``total``: the
        detached walk's sum)."""
        mi = mitsuba_module()
        ctx = mi.BSDFContext(ctx_mode)
        ctx_s = self.layer.bottom.smooth_context(ctx_mode)
        base, max_bounces = self.layer.base, self.layer.max_bounces
        replay = total is not None
        rng = mi.PCG32(size=1, initstate=mi.UInt64(seed[0]), initseq=mi.UInt64(seed[1]))
        zero = dr.zeros(mi.Spectrum)
        v_bar, p_v, rev, v_ok = self._reverse(ctx_mode, si, wo_in, rng, active, replay)
        si_o = base_interaction(si, wo_in)

        def cond(acc, gathered, beta, mis, w, depth, rng, active):
            return active

        def body(acc, gathered, beta, mis, w, depth, rng, active, first=False):
            alive = active
            si_b = base_interaction(si, w)
            e = base.eval(ctx, si_b, wo_in, active)
            more = active & (depth + 1 < max_bounces)
            linked = zero
            if first:
                # the link to the reverse sample: the second vertex's term by the other strategy
                link = more & v_ok
                f_c, p_c = base.eval_pdf(ctx, si_b, v_bar, link)
                w_link = dr.select(link, power_heuristic(p_v, self.step_pdf(ctx, si_b, v_bar, p_c,
                                                                           link)), 0.0)
                linked = beta * f_c * rev * w_link
            with dr.suspend_grad(when=replay):
                gathered = dr.select(active, gathered + beta * e * mis + linked, gathered)
                depth = depth + 1
                s1 = rng.next_float32()
                s2 = mi.Point2f(rng.next_float32(), rng.next_float32())
                bs, g = base.sample(ctx, si_b, s1, s2, active)
                bs.wo, g, p = self.steer(ctx, si_b, bs, g, rng.next_float32(), active)
                cos = bs.wo.z
                active = more & (cos > 0) & (p > 0)
                # the light that reached the base along -bs.wo left the previous vertex
                # along w_next and reflected at the underside
                w_next = mi.Vector3f(-bs.wo.x, -bs.wo.y, cos)
                step = g * self.layer.underside(si, w_next, active)
                mis_next = dr.select(active, 1.0, mis)
                if first:
                    # the second vertex's own term, weighted against the link that reaches it
                    p_r = base.pdf(ctx_s, si_o, w_next, active & logical_not(
                        mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)))
                    mis_next = power_heuristic(p, p_r)
            if replay:
                acc = mi.Spectrum(acc + self._replayed(ctx, si, si_b, bs, (s1, s2), w_next,
                                                       total - gathered, active)
                                  + dr.select(alive, beta * e * mis + linked, zero))
            else:
                acc = gathered
            with dr.suspend_grad(when=replay):
                beta = dr.select(active, beta * step, zero)
                beta, active = roulette(beta, depth, rng, active, self.layer.mode.polarized)
            return acc, gathered, beta, mis_next, w_next, depth, rng, active

        acc0, gathered0, beta0, loop0 = (mi.Spectrum(zero), mi.Spectrum(zero), mi.Spectrum(1.0),
                                         mi.Spectrum(zero))
        if self.layer.mode.polarized:
            # Mueller matrices that start as literals (zeros, the identity) fill in one
            # entry per product along the walk, so Dr.Jit would find the loop state still
            # changing when it records the loop a second time (a principled base): start
            # them as evaluated values
            dr.make_opaque(acc0, gathered0, beta0, loop0)
        # the first vertex, with its link, before the loop (whose vertices have none); the
        # loop sums from zero (the replay's loop takes no differentiable input)
        first = body(acc0, gathered0, beta0, mi.Float(1.0), mi.Vector3f(w0), mi.UInt32(0),
                     rng, mi.Bool(active), first=True)
        labels = ("acc", "gathered", "beta", "mis", "w", "depth", "rng", "active")
        # max_iterations=-1: the replay is a sum of per-vertex terms (Dr.Jit's fast path
        # for reverse-mode differentiation of such loops)
        rest = dr.while_loop((loop0,) + first[1:], cond, body, labels=labels,
                             max_iterations=-1 if replay else None)
        # the walk's sum is what it gathered; the replay's, the first vertex's and the loop's
        return first[0] + rest[0] if replay else rest[1]

    def steer(self, ctx, si_b, bs, g, u, active):
        """A step's direction from the base's sample ``bs`` (weight ``g``) at ``si_b``:
        a non-delta sample inside the escape cone is kept where ``u < ESCAPE_KEEP``, else
        unfolded beyond the critical cosine (:func:`~thinfilm_mi.render.layered.escape.unfold`),
        where total internal reflection keeps the light in the layer. Returns ``(w, f_b cos /
        p, p)``, ``p`` the step's density (:meth:`step_pdf`); detached (a sampling decision)."""
        mi = mitsuba_module()
        mu_c = critical_cosine(self.layer.top.eta_f)
        smooth = active & (mu_c > 0) & (bs.pdf > 0) & logical_not(
            mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta))
        turn = smooth & (bs.wo.z >= mu_c) & (u >= ESCAPE_KEEP)
        w = dr.select(turn, unfold(bs.wo, mu_c), bs.wo)
        trapped = smooth & (w.z > 0) & (w.z < mu_c)
        # the base at the other direction of the fold's pair: the unfolded one's value and
        # density, or a kept trapped one's escape direction's density
        f_o, p_o = self.layer.base.eval_pdf(ctx, si_b, dr.select(turn, w, fold(w, mu_c)), trapped)
        p_b = dr.select(turn, p_o, bs.pdf)
        jac = (1.0 - mu_c) / dr.maximum(mu_c, 1e-6)
        p = dr.select(trapped, p_b + (1.0 - ESCAPE_KEEP) * jac * dr.select(turn, bs.pdf, p_o),
                      dr.select(smooth, ESCAPE_KEEP * bs.pdf, bs.pdf))
        f = dr.select(turn, f_o, g * bs.pdf)
        weight = dr.select(smooth, f / dr.select(p > 0, p, 1.0), g)
        return w, dr.select(smooth & (p <= 0), 0.0, weight), p

    def step_pdf(self, ctx, si_b, w, p_b, active):
        """The density of a step (:meth:`steer`) from ``si_b`` to the non-delta direction
        ``w``, where the base's own is ``p_b``: ``ESCAPE_KEEP p_b`` inside the escape cone,
        ``p_b + (1 - ESCAPE_KEEP) p_b(fold(w)) (1 - μ_c)/μ_c`` beyond it (the unfolded
        samples' share)."""
        mu_c = critical_cosine(self.layer.top.eta_f)
        steered = active & (mu_c > 0)
        trapped = steered & (w.z > 0) & (w.z < mu_c)
        p_o = self.layer.base.pdf(ctx, si_b, fold(w, mu_c), trapped)
        jac = (1.0 - mu_c) / dr.maximum(mu_c, 1e-6)
        return dr.select(trapped, p_b + (1.0 - ESCAPE_KEEP) * jac * p_o,
                         dr.select(steered, ESCAPE_KEEP * p_b, p_b))

    def _replayed(self, ctx, si, si_b, bs, numbers, w_next, after, active):
        """A vertex's step in the replay: ``dlog(g r) (W - W_{≤j})`` (``after``: what the
        detached walk gathered after this vertex), ``g`` the base's ``eval`` at the sampled
        direction over its detached pdf (at a delta vertex, whose ``eval`` is 0, the
        replayed sample's weight times its pdf, so that the base's delta parameters, a
        conductor's eta and k, keep their gradients) and ``r`` the underside."""
        mi = mitsuba_module()
        base = self.layer.base
        e_r = base.eval(ctx, si_b, bs.wo, active)
        if self.layer.delta is not None:
            bs_a, g_a = base.sample(ctx, si_b, numbers[0], numbers[1], active)
            e_r = dr.select(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta), g_a * bs_a.pdf, e_r)
        g_r = e_r / dr.detach(dr.select(bs.pdf > 0, bs.pdf, 1.0)) \
            * self.layer.underside(si, w_next, active)
        return dr.select(active, ratio(g_r) * after, dr.zeros(mi.Spectrum))


def ratio(x):
    """``x / detach(x)``: 1, with the gradient of ``log x`` (0 where ``x`` is 0): a replayed
    factor's share of the derivative."""
    live = dr.detach(x) != 0
    return dr.select(live, x / dr.select(live, dr.detach(x), 1.0), 0.0)


def power_heuristic(p, *others):
    """Veach's power heuristic (exponent 2) of the strategy of density ``p`` against the
    others' densities; detached."""
    p2 = dr.square(dr.detach(p))
    total = p2
    for q in others:
        total = total + dr.square(dr.detach(q))
    return dr.select(p2 > 0, p2 / dr.select(p2 > 0, total, 1.0), 0.0)


def roulette(beta, depth, rng, active, polarized: bool):
    """Russian roulette from :data:`RR_DEPTH` vertices on, of walks whose throughput is
    below :data:`ROULETTE_BELOW`: survival ``q = max β / ROULETTE_BELOW``, ``β /= q``
    (unbiased; a walk above it goes on: trapped light keeps its weight rather than gaining
    ``1/q`` at every vertex). Returns ``(β, active)``."""
    mi = mitsuba_module()
    b = dr.max(intensity(beta, polarized))
    play = active & (depth >= RR_DEPTH) & (b < ROULETTE_BELOW)
    q = b / ROULETTE_BELOW
    u = rng.next_float32()
    active = active & (logical_not(play) | (u < q)) & (b > 0)
    return dr.select(play, beta / dr.select(q > 0, q, 1.0), beta), mi.Bool(active)
