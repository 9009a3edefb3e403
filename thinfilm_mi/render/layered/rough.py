r"""The estimator under a rough top (no plugin classes here): ``thinfilm_coating`` with
``alpha > 0``, a :class:`~thinfilm_mi.render.layered.top.RoughTop` (the thin-film stack
on the microfacets of a rough interface) over a
:class:`~thinfilm_mi.render.layered.bottom.NestedBottom`, through a
:class:`~thinfilm_mi.render.layered.coat.CoatMedium` (Guo, Hašan, Yan and Zhao 2018;
pbrt-v4's ``LayeredBxDF``; the top names the engine's components: 0 its glossy reflection,
1 the light that crosses it, :meth:`~thinfilm_mi.render.layered.top.RoughTop.crossed_lobes`).

**The estimate** of ``f cos θ_o`` (:meth:`RoughEstimator.eval_pdf`; ``ω_i``, ``ω_o``
outside; the top's directions in its own frame, the coat medium below, ``f_t`` its lobes
in radiance transport, ``A`` Beer–Lambert along one crossing of the coat)::

    f cos θ_o = f_t(ω_i, ω_o) cos θ_o  (the top's reflection, evaluated)
              + the walk's estimate of the light that crosses the top

The walk (:meth:`RoughEstimator.walk`, pbrt-v4's ``LayeredBxDF::f``): the top's
transmission is sampled from ``ω_i`` (``w_0``: the base's ``wi``, weight ``β_0 = f_t cos /
p · A(w_0)``) and, once for the walk, from ``ω_o`` (``v``, density ``p_o(v)``: the light's
side). At every base vertex ``k`` two next-event estimates reach ``ω_o`` through the top,
combined by the power heuristic:

* towards ``-v``: ``β_k f_b(w_k, -v) cos · A(v) f_t(v, ω_o) cos θ_o / p_o(v)``, weight
  ``p_o² / (p_o² + p_b²)`` (``p_b``: the base's density of ``-v``);
* along the base's sample ``y`` (weight ``g``): ``β_k g A(y) f_t(-y, ω_o) cos θ_o``, weight
  ``p_b² / (p_b² + p_o(-y)²)``, 1 where the base sampled a delta lobe (the light's side
  never draws one).

**Over a pure-delta base** (a smooth ``conductor``), whose
mirror makes the first estimate 0 and left the second alone with the top's peaked
transmission evaluated at a random ``-y``, the light's side is linked one step earlier
(:attr:`RoughEstimator.mirror`): towards ``w* = (v_x, v_y, -v_z)``, the base's ``wi`` that
the mirror sends along ``-v``, from the top's transmission at ``ω_i`` before the first
vertex (``f_t(ω_i, -w*) cos · A(w*) B_δ(w*) · A(v) f_t(v, ω_o) cos θ_o / p_o(v)``) and from
the underside's reflection at every vertex (``β_k g A(y) f_r(-y, -w*) cos · A(w*) B_δ(w*)
…``, for the next vertex), weight ``p_o² / (p_o² + p²)``, ``p`` the density with which the
walk samples ``-w*`` there; the walk's exit after the mirror then weighs itself against
it, ``p_w² / (p_w² + p_o(-y)²)`` with ``p_w`` the density its ``w_k`` was sampled with (the
mirror maps the two directions with a unit Jacobian, so both densities measure the same
path). **Over a base with a glossy lobe** the link draws that ``wi`` instead: ``w*`` from
the base's non-delta lobes sampled at ``-v`` (density ``p̃``; the same lobe, by
reciprocity), reached as above with ``B_δ(w*)`` replaced by ``f_b(w*, -v) cos / p̃``
(:meth:`RoughEstimator.light_link`). Its two next-event estimates and the link are then
three strategies for the last two directions of a path, weighed by the power heuristic of
``p_w p_b(y | w)`` (the exit), ``p_w p_o(-y)`` (towards ``-v``) and ``p_o(-y) p̃(w | y)``
(the link): a near-specular base, whose first two both evaluate a peaked lobe at a random
direction, gains most. A diffuse base has no link (its next-event estimate is as broad).
In polarized variants each factor is the Mueller matrix of its event, in the order of the
sampled path's (the link replaces the sampled reflection ``r`` by its value).

The walk then reflects at the underside, sampled from ``-y`` (the reflection lobe alone,
its transmission being the next-event estimates' business): ``β_{k+1} = β_k g A(y) f_t
cos / p · A(w_{k+1})``. Russian roulette and ``max_bounces`` as the smooth walk's
(:func:`~thinfilm_mi.render.layered.walk.roulette`: from ``RR_DEPTH`` vertices, of walks
whose throughput is below ``ROULETTE_BELOW``);
random numbers from a PCG32 seeded with a hash of the directions in ``eval`` and of the
sample's numbers in ``sample`` (the smooth walk's seeds). pbrt-v4 weighs the second
estimate with the density of ``ω_o`` given ``-y``; here both weights use the density of
the light's side sampler at the same inner direction, so that they sum to one.

**Sampling** (:meth:`RoughEstimator.sample`): a deterministic mixture whose density
:meth:`RoughEstimator.mixture_pdf` is exact::

    p(ω_o) = w_R p_R(ω_o) + w_B p_b(ω_i', ω_o') (η_e/η_c)² cos θ_o / cos θ_o' + w_C cos θ_o / π

``p_R``: the top's reflection lobe (visible normals, as ``thinfilm_roughdielectric``);
``p_b``: the base's non-delta lobes at the mean refraction ``ω_i'`` refracted out (the
smooth estimator's lobe); the cosine lobe for the interreflections. ``w_R = P_R + (1 -
P_R)(1 - c) b̄``, ``w_B = (1 - P_R)(1 - c)(1 - b̄)``, ``w_C = (1 - P_R) c`` with ``P_R``
the spectral mean of the stack's ``R(θ_i)``, ``c`` :data:`ROUGH_MIXTURE`
and ``b̄`` the base's mean delta reflectance (1 over a pure-delta base: its light leaves
about the mirror direction, spread by the two crossings, narrower than the top's own
reflection). The weight is the walk's estimate of ``f cos θ_o`` over ``p``, so that
``sample``, ``eval`` and ``pdf`` agree and MIS weights sum to one.

**Gradients**: the sampled directions and densities are detached (sampling decisions);
the values (the stack's ``R`` and ``T``, the microfacet terms, the base, the coat) carry
them, so the estimate's derivative is an unbiased estimate of ``∂(f cos θ_o)``.
"""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.layered.bottom import base_interaction
from thinfilm_mi.render.layered.coated import CoatedEstimator
from thinfilm_mi.render.layered.walk import (
    eval_seed,
    logical_not,
    power_heuristic,
    ratio,
    roulette,
    sample_seed,
)
from thinfilm_mi.render.textures import mitsuba_module
from thinfilm_mi.render.variant import spectral_mean
from thinfilm_mi.tabulate.base import opaque_float

__all__ = ["ROUGH_MIXTURE", "RoughEstimator"]

#: The cosine lobe's share ``c`` of the rough top's sampling mixture. Any fixed value in
#: (0, 1) keeps ``pdf`` exact; the smooth top fits its share per direction from a probe of
#: the base (:mod:`~thinfilm_mi.render.layered.nested`), which the rough top does not use yet.
ROUGH_MIXTURE = 0.5


class RoughEstimator(CoatedEstimator):
    """The layered BSDF of ``top`` (a :class:`~thinfilm_mi.render.layered.top.RoughTop`)
    over ``bottom`` (a :class:`~thinfilm_mi.render.layered.bottom.NestedBottom`) through
    ``medium``; the rest as :class:`~thinfilm_mi.render.layered.coated.CoatedEstimator`."""

    def __init__(self, top, bottom, medium, mode, plugin: str, max_bounces: int):
        super().__init__(top, bottom, medium, mode, plugin, max_bounces)
        #: the cosine lobe's share of the sampling mixture (:data:`ROUGH_MIXTURE`)
        self.mix = opaque_float(ROUGH_MIXTURE)
        #: how the walk links the light side one step early (module docstring): through the
        #: mirror of a pure-delta base, or, over a base with a glossy lobe, by a sample of its
        #: non-delta lobes drawn from the light's side (a diffuse base's next-event
        #: estimate is already as broad as the link's)
        self.mirror = self.delta is not None and not bottom.lobes
        self.reverse = mitsuba_module().BSDFFlags.GlossyReflection in bottom.lobes

    def describe(self) -> str:
        """The stack, the media and the base, then the roughness, for ``to_string``."""
        return super().describe() + self.top.microfacet.describe()

    # -- pieces ----------------------------------------------------------------
    def absorb(self, si, cos, active):
        """Beer–Lambert along one crossing of the coat at ``|cos|`` (1 without a medium)."""
        a = self.medium.attenuation(si, dr.abs(cos), active)
        return 1.0 if a is None else a

    def walk(self, ctx_mode, si, wo, seed, active):
        """The walk's estimate of the light that crosses the top (module docstring), the
        PCG32 seeded with ``seed`` (two ``UInt32``).

        Gradients: the walk runs detached, then again with the same random numbers,
        adding what the parameters change at each vertex (as
        :meth:`~thinfilm_mi.render.layered.walk.RandomWalk.sum` replays a path: ``dW =
        Σ_j (the next-event terms' own derivatives at j) + Σ_j dlog(step_j) (W - W_{≤j})
        + dlog(β_0) W + dlog(L) W_L``, ``step_j`` the throughput's factor at vertex ``j``,
        ``L`` the light side's factor and ``W_L`` the terms it multiplies): a sum-style
        loop Dr.Jit differentiates in reverse mode without storing the trajectory."""
        mi = mitsuba_module()
        if not self.tracks_gradients(si, active):
            return self.run(ctx_mode, si, wo, seed, active, None)[0]
        if self.mode.polarized:
            raise ThinFilmError(f"{self.plugin}: gradients in polarized variants under a rough "
                                "top are not supported (the replay's per-vertex ratios are "
                                "per wavelength, not per Mueller matrix)")
        with dr.suspend_grad():
            totals = self.run(ctx_mode, si, wo, seed, active, None)
        surrogate = self.run(ctx_mode, si, wo, seed, active, totals)[0]
        return mi.Spectrum(totals[0] + (surrogate - dr.detach(surrogate)))

    def run(self, ctx_mode, si, wo, seed, active, totals):
        """``(W, W_L)``: the walk's sum and its light-side terms (``totals`` None), or
        its replay carrying the gradients (``totals``: the detached walk's)."""
        mi = mitsuba_module()
        top = self.top
        rng = mi.PCG32(size=1, initstate=mi.UInt64(seed[0]), initseq=mi.UInt64(seed[1]))
        b0, t0, p0, ok0 = top.sample(si, si.wi, self.numbers(rng), active, False, False)
        v, _, p_o, ok_o = top.sample(si, wo, self.numbers(rng), active, False, False)
        e_o, _ = top.lobe(si, v, wo, ok_o, reflect=False, inside=True)
        light = e_o * self.absorb(si, v.z, ok_o) / dr.select(ok_o, p_o, 1.0)
        light_d = light if totals is None else dr.detach(light)
        w0 = -b0
        beta0 = mi.Spectrum(t0 * self.absorb(si, w0.z, ok0))
        zero = dr.zeros(mi.Spectrum)
        acc0, light_acc0, gathered0 = mi.Spectrum(zero), mi.Spectrum(zero), mi.Spectrum(zero)
        if self.mode.polarized:
            # Mueller matrices that start as literals fill in along the loop (walk.py)
            dr.make_opaque(acc0, light_acc0, gathered0)
        link = self.light_link(ctx_mode, si, v, light_d, active & ok_o & (self.max_bounces > 0),
                               rng)
        link0 = zero
        if link is not None:
            # the first vertex reached from the light side, from the top's transmission
            w_link, tail, rev, ok_l = link
            t_l, p_l = top.lobe(si, si.wi, -w_link, ok_l, reflect=False, inside=False)
            link0 = dr.select(ok_l, t_l * tail * self.link_weight(p_l, p_o, rev), zero)
            # the sum starts with it (the replay's loop takes no differentiable input:
            # its own derivative joins after the loop)
            light_acc0 = mi.Spectrum(light_acc0 + dr.detach(link0))
            gathered0 = mi.Spectrum(gathered0 + dr.detach(link0))
        state = (acc0, light_acc0, gathered0, dr.detach(beta0), mi.Vector3f(w0),
                 mi.Float(dr.detach(p0)), mi.UInt32(0), rng, mi.Bool(ok0))
        side = (v, p_o, ok_o, light_d, link)

        def cond(acc, light_acc, gathered, beta, w, p_w, depth, rng, active):
            return active

        def body(acc, light_acc, gathered, beta, w, p_w, depth, rng, active):
            return self.vertex(ctx_mode, si, wo, side, totals, acc, light_acc, gathered,
                               beta, w, p_w, depth, rng, active)

        labels = ("acc", "light_acc", "gathered", "beta", "w", "p_w", "depth", "rng", "active")
        out = dr.while_loop(state, cond, body, labels=labels,
                            max_iterations=-1 if totals is not None else None)
        if totals is None:
            return out[0], out[1]
        # the link before the loop, and the factors before it that scale the rest of W
        # (β_0) and W_L (the light side)
        return mi.Spectrum(out[0] + link0 + ratio(beta0) * (totals[0] - dr.detach(link0))
                           + ratio(light) * totals[1]), None

    def light_link(self, ctx_mode, si, v, light, active, rng):
        """``(w*, tail, rev, ok)``: the base's ``wi`` from which the light side's ``-v`` is
        reached, and what the light gains from there to ``ω_o`` (``tail``); ``rev``: the
        reverse sample's densities ``(p̃(w*), p_b(-v | w*))`` (``None`` through a mirror);
        ``None`` where the walk links nothing (module docstring)."""
        mi = mitsuba_module()
        if self.mirror:
            w_link = mi.Vector3f(v.x, v.y, -v.z)
            reflect = self.delta.reflectance(ctx_mode, si, w_link,
                                             (mi.Float(0.5), mi.Point2f(0.5, 0.5)), active)
            return w_link, self.absorb(si, w_link.z, active) * reflect * light, None, active
        if not self.reverse:
            return None
        base = self.base
        with dr.suspend_grad():
            bs, _ = base.sample(self.bottom.smooth_context(ctx_mode), base_interaction(si, -v),
                                rng.next_float32(), self.numbers(rng), active)
        w_link, p_rev = dr.detach(bs.wo), dr.detach(bs.pdf)
        ok = active & (w_link.z > 0) & (p_rev > 0)
        e, p_b = base.eval_pdf(mi.BSDFContext(ctx_mode), base_interaction(si, w_link), -v, ok)
        tail = self.absorb(si, w_link.z, ok) * e * light / dr.select(ok, p_rev, 1.0)
        return w_link, tail, (p_rev, dr.detach(p_b)), ok

    @staticmethod
    def link_weight(p_l, p_o, rev):
        """The link's MIS weight: against the walk's own step of density ``p_l`` to the
        same direction (through a mirror), or, with the reverse sample's densities ``rev``,
        against the walk's exit and its next-event estimate there."""
        if rev is None:
            return power_heuristic(p_o, p_l)
        p_rev, p_b = rev
        return power_heuristic(p_o * p_rev, p_l * p_b, p_l * p_o)

    def vertex(self, ctx_mode, si, wo, side, totals, acc, light_acc, gathered, beta, w,
               p_w, depth, rng, active):
        """One base vertex of :meth:`run` (``p_w``: the density ``w`` was sampled with):
        its two next-event estimates, the base's sample, the underside's reflection, the
        link to the light side through the next vertex (over a mirror or glossy base,
        :meth:`light_link`), and Russian roulette; in the replay (``totals`` given) the
        vertex's gradient terms (:meth:`walk`)."""
        mi = mitsuba_module()
        top, base = self.top, self.base
        v, p_o, ok_o, light, link = side
        ctx = mi.BSDFContext(ctx_mode)
        ctx_s = self.bottom.smooth_context(ctx_mode)
        zero = dr.zeros(mi.Spectrum)
        si_b = base_interaction(si, w)
        e, p_b = base.eval_pdf(ctx, si_b, -v, active & ok_o)
        if self.reverse:
            # the reverse sample would reach w from -v with this density
            q = base.pdf(ctx_s, base_interaction(si, -v), w, active & ok_o)
            w_nee = power_heuristic(p_w * p_o, p_w * dr.detach(p_b), p_o * dr.detach(q))
        else:
            w_nee = power_heuristic(p_o, dr.detach(p_b))
        nee = dr.select(active & ok_o, beta * e * light * w_nee, zero)
        bs, g = base.sample(ctx, si_b, rng.next_float32(), self.numbers(rng), active)
        y = dr.detach(bs.wo)
        alive = active & (y.z > 0) & (bs.pdf > 0)
        delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        if totals is not None:
            # g as the base's eval over its detached pdf (a delta vertex: its sample's)
            pdf = dr.detach(dr.select(alive, bs.pdf, 1.0))
            g = dr.select(delta, g, base.eval(ctx, si_b, y, alive) / pdf)
        e_y, _ = top.lobe(si, -y, wo, alive, reflect=False, inside=True)
        _, p_y = top.lobe(si, wo, -y, alive, reflect=False, inside=False, want_value=False)
        # a delta vertex's exit is the walk's alone, or, through a mirror, weighed against
        # the link that reached it from the light side (its density that of the sampled w)
        mis_delta = power_heuristic(p_w, dr.detach(p_y)) if self.mirror else 1.0
        if self.reverse:
            q = base.pdf(ctx_s, base_interaction(si, y), w, alive & logical_not(delta))
            mis_lobe = power_heuristic(p_w * dr.detach(bs.pdf), p_w * dr.detach(p_y),
                                       dr.detach(p_y) * dr.detach(q))
        else:
            mis_lobe = power_heuristic(dr.detach(bs.pdf), dr.detach(p_y))
        mis = dr.select(delta, mis_delta, mis_lobe)
        through = g * self.absorb(si, y.z, alive)
        exit_ = dr.select(alive, beta * through * e_y * mis, zero)
        z, r, p_z, ok_r = top.sample(si, -y, self.numbers(rng), alive, True, True)
        w_next = -z
        depth = depth + 1
        active = alive & ok_r & (depth < self.max_bounces)
        step = through * r * self.absorb(si, w_next.z, active)
        linked = zero
        if link is not None:
            # the next vertex reached from the light side: the underside reflects towards
            # the base's wi from which -v is reached
            w_link, tail, rev, ok_link = link
            ok_l = alive & ok_link & (depth < self.max_bounces)
            f_l, p_l = top.lobe(si, -y, -w_link, ok_l, reflect=True, inside=True)
            linked = dr.select(ok_l, beta * through * f_l * tail
                               * self.link_weight(p_l, p_o, rev), zero)
        light_acc = mi.Spectrum(light_acc + dr.detach(nee + linked))
        gathered = mi.Spectrum(gathered + dr.detach(nee + exit_ + linked))
        if totals is None:
            acc = gathered
        else:
            acc = mi.Spectrum(acc + nee + exit_ + linked
                              + dr.select(active, ratio(step) * (totals[0] - gathered), zero))
        beta = mi.Spectrum(dr.select(active, beta * dr.detach(step), zero))
        beta, active = roulette(beta, depth, rng, active, self.mode.polarized)
        return (acc, light_acc, gathered, mi.Spectrum(beta), w_next, mi.Float(dr.detach(p_z)),
                depth, rng, active)

    @staticmethod
    def numbers(rng):
        """Two numbers of ``rng`` as a ``Point2f``."""
        return mitsuba_module().Point2f(rng.next_float32(), rng.next_float32())

    def value(self, ctx, si, wo, seed, active, has_top: bool, has_base: bool):
        """The estimate of ``f cos θ_o`` of the enabled components (``seed``: the walk's)."""
        mi = mitsuba_module()
        value = dr.zeros(mi.Spectrum)
        if has_top:
            value = self.top.lobe(si, si.wi, wo, active, reflect=True, inside=False, ctx=ctx)[0]
        if has_base:
            crossed = self.walk(ctx.mode, si, wo, seed, active)
            if self.mode.polarized and ctx.mode != mi.TransportMode.Radiance:
                # importance transport: the chain's intensity for unpolarised light
                crossed = mi.depolarizer(mi.UnpolarizedSpectrum(crossed[0][0]))
            value = value + crossed
        return dr.select(active, value, dr.zeros(mi.Spectrum))

    def shares(self, ctx_mode, si, active, has_top: bool, has_base: bool):
        """``(w_R, w_B, w_C)``: the mixture's shares (module docstring), deterministic
        functions of ``ω_i``, detached."""
        mi = mitsuba_module()
        if not has_base:
            return mi.Float(1.0), mi.Float(0.0), mi.Float(0.0)
        p_r = mi.Float(0.0)
        if has_top:
            resp = self.top.unpolarized(si, si.wi.z, active, inside=False, transmission=False)
            p_r = dr.minimum(spectral_mean(resp.R), 1.0)
        b = mi.Float(1.0 if not self.bottom.lobes else 0.0)
        if self.delta is not None and self.bottom.lobes:
            wi_in, ok = self.top.inward(si.wi)
            b = self.delta.mean(ctx_mode, si, wi_in, active & ok)
        rest = 1.0 - p_r
        return dr.detach((p_r + rest * (1.0 - self.mix) * b,
                          rest * (1.0 - self.mix) * (1.0 - b), rest * self.mix))

    def mixture_pdf(self, ctx_mode, si, wo, shares, active):
        """The density of :meth:`sample` at ``wo`` for the mixture ``shares``."""
        w_r, w_b, w_c = shares
        active = active & (wo.z > 0)
        _, p_r = self.top.lobe(si, si.wi, wo, active, reflect=True, inside=False,
                               want_value=False)
        p = w_r * p_r + w_c * wo.z * dr.inv_pi
        if self.bottom.lobes:
            wi_in, ok_i = self.top.inward(si.wi)
            wo_in, ok_o = self.top.inward(wo)
            ok = active & ok_i & ok_o
            p_b = self.bottom.bsdf.pdf(self.bottom.smooth_context(ctx_mode),
                                       base_interaction(si, wi_in), wo_in, ok)
            jac = self.top.inv_eta2 * wo.z / dr.maximum(wo_in.z, 1e-12)
            p = p + dr.select(ok, w_b * p_b * jac, 0.0)
        return dr.detach(dr.select(active, p, 0.0))

    # -- the BSDF interface ----------------------------------------------------
    def sample(self, ctx, si, sample1, sample2, active, has_top: bool, has_base: bool):
        """``(bs, weight)``: a direction of the mixture (:meth:`mixture_pdf`), weighted by
        the estimate of ``f cos θ_o`` over its density."""
        mi = mitsuba_module()
        bs = dr.zeros(mi.BSDFSample3f)
        active = mi.Bool(active) & (si.wi.z > 0)
        if not (has_top or has_base):
            return bs, mi.Spectrum(0.0)
        shares = self.shares(ctx.mode, si, active, has_top, has_base)
        w_r, w_b, _ = shares
        pick_r = sample1 < w_r
        pick_b = logical_not(pick_r) & (sample1 < w_r + w_b)
        pick_c = logical_not(pick_r | pick_b)
        with dr.suspend_grad():
            wo, _, _, _ = self.top.sample(si, si.wi, sample2, active & pick_r, True, False)
            if self.bottom.lobes:
                s_b = dr.clip((sample1 - w_r) / dr.select(w_b > 0, w_b, 1.0), 0.0, 1.0)
                wi_in, _ = self.top.inward(si.wi)
                bs_b, _ = self.bottom.bsdf.sample(self.bottom.smooth_context(ctx.mode),
                                                  base_interaction(si, wi_in), s_b, sample2,
                                                  active & pick_b)
                out, leaves = self.top.outward(bs_b.wo)
                # a base sample that failed (below its horizon, a zero vector, no density)
                # or that total internal reflection keeps inside is no direction of the
                # mixture: outward() would still map it to one above the horizon
                leaves &= (bs_b.wo.z > 0) & (bs_b.pdf > 0)
                wo = dr.select(pick_b, dr.select(leaves, out, mi.Vector3f(0.0)), wo)
            wo = dr.select(pick_c, mi.warp.square_to_cosine_hemisphere(sample2), wo)
        pdf = self.mixture_pdf(ctx.mode, si, wo, shares, active)
        ok = active & (wo.z > 0) & (pdf > 0)
        f = self.value(ctx, si, wo, sample_seed(sample1, sample2), ok, has_top, has_base)
        bs.wo = dr.select(ok, wo, 0.0)
        bs.pdf = dr.select(ok, pdf, 0.0)
        bs.eta = 1.0
        bs.sampled_component = dr.select(pick_r & has_top, mi.UInt32(0), mi.UInt32(1))
        bs.sampled_type = dr.select(pick_c, mi.UInt32(+mi.BSDFFlags.DiffuseReflection),
                                    mi.UInt32(+mi.BSDFFlags.GlossyReflection))
        return bs, dr.select(ok, f / dr.select(ok, pdf, 1.0), 0.0)

    def eval_pdf(self, ctx, si, wo, active, has_top: bool, has_base: bool,
                 want_value: bool = True, want_pdf: bool = True):
        """``(f cos θ_o, pdf)``: the estimate (seeded by the directions) and the density
        of :meth:`sample`."""
        mi = mitsuba_module()
        active = mi.Bool(active) & (si.wi.z > 0) & (wo.z > 0)
        value, pdf = mi.Spectrum(0.0), mi.Float(0.0)
        if not (has_top or has_base):
            return value, pdf
        if want_value:
            value = self.value(ctx, si, wo, eval_seed(si.wi, wo), active, has_top, has_base)
        if want_pdf:
            shares = self.shares(ctx.mode, si, active, has_top, has_base)
            pdf = self.mixture_pdf(ctx.mode, si, wo, shares, active)
        return value, pdf
