r"""The estimator over a nested BSDF (no plugin classes here): ``thinfilm_coating``'s
model, a :class:`~thinfilm_mi.render.layered.top.SmoothTop` over a
:class:`~thinfilm_mi.render.layered.bottom.NestedBottom` with an optional
:class:`~thinfilm_mi.render.layered.coat.CoatMedium` between them (Guo, Hašan, Yan and
Zhao 2018; pbrt-v4's ``LayeredBxDF``).

**The BSDF.** For light between ``ω_i`` and ``ω_o`` outside (``ω'``: the inner
directions, :func:`~thinfilm_mi.render.layered.top.inward`; the base sees the light
arriving along ``-w'`` and its ``wi`` is ``w'``)::

    f(ω_i, ω_o) = δ-reflection R(θ_i) (+ the base's all-delta chains)
                + T(θ_i) T(θ_o) (η_e/η_c)² A(ω_i') A(ω_o') Σ_paths f_b-chain(ω_i' → … → ω_o')

``T`` is the stack's transmittance from outside (the same from inside along the same
path: ``T`` is reciprocal), ``A(w') = exp(-σ_a d / cos θ')`` Beer–Lambert along one
crossing of the coat (thickness ``d``), and the chains bounce between the base and the
stack's underside, whose reflectance ``R_in`` is the stack lit from the coat medium (total
internal reflection included). **The factor (η_e/η_c)²**: light of radiance ``L`` from
``ω_o`` enters with radiance ``T (η_c/η_e)² L`` in a solid angle ``(η_e/η_c)² cos θ_o /
cos θ_o'`` times smaller, so the irradiance on the base is ``T L cos θ_o dω_o`` (energy
is conserved); the base returns ``f_b T L cos θ_o dω_o`` towards ``ω_i'``, and leaving
the coat the radiance is multiplied by ``T(θ_i) (η_e/η_c)²``. Hence the single-bounce
term ``T_i T_o (η_e/η_c)² f_b(ω_i', ω_o')``: Mitsuba's ``plastic``'s ``inv_eta_2``.
Sample weights carry no such factor: the Jacobian ``dω'/dω = (η_e/η_c)² cos θ/cos θ'``
of the exit direction cancels it (see :meth:`NestedEstimator.sample`).

**The sum** ``Σ_paths`` is one of the registered sum estimators (:func:`sum_estimator`):
the closed form of the base where it has one (:data:`~thinfilm_mi.render.layered.forms.CLOSED_FORMS`),
else the random walk (:class:`~thinfilm_mi.render.layered.walk.RandomWalk`).

**Bases with delta lobes** (a smooth ``conductor``, ``dielectric``, ``plastic``,
``thinfilm_diffuse``): the all-delta paths join the delta lobe, every exit carries the
delta round trips, and the walk samples delta vertices as any other
(:mod:`thinfilm_mi.render.layered.delta`).

**Sampling** (:meth:`NestedEstimator.sample`): a *probe* first (:meth:`NestedEstimator.probe`):
the base sampled at ``ω_i'`` with the fixed numbers :data:`PROBE` (its non-delta lobes),
whose mean weight ``ā`` estimates the base's albedo and whose density over a Lambertian's
at the sampled directions, ``ν = p_b π / cos θ`` (1 for a Lambertian, large for a narrow
lobe), its lobe's peak. The delta lobe is picked with probability ``P_R = (R̄ + T̄ b̄) /
(R̄ + T̄ b̄ + T̄ ā_e)`` (spectral means at ``θ_i``; ``b̄``: the mean of ``B_δ(ω_i')``
sampled with fixed numbers, 0 for a base without delta lobes; ``ā_e = ā η⁻² / (1 - ā (1 -
η⁻²))``: the share of the light entering a Lambertian ``ā`` under the coat that leaves
it, ``η⁻²`` its escape cone's share; ``ā`` at least :data:`ALBEDO_FLOOR`), so that the
delta lobe's weight and the base's are both near the layer's albedo; weight the delta lobe
over ``P_R``; 1 over a pure-delta base (no component 1). Otherwise a direction is drawn
from a mixture (:meth:`NestedEstimator.base_pdf`, its exact density)::

    p(ω_o) = (1 - P_R) [ (1 - c) p_f(ω_o') (η_e/η_c)² cos θ_o / cos θ_o'
                         + c (1 - b cos φ_o) cos θ_o / π ]

the base sampled at ``ω_i'`` (its non-delta lobes only,
:meth:`~thinfilm_mi.render.layered.bottom.NestedBottom.smooth_context`) and refracted out,
a direction beyond the critical cosine ``μ_c`` *folded* into the escape cone first
(:func:`fold`: ``μ' = μ_c + (μ_c - μ)(1 - μ_c)/μ_c``, the same azimuth; light trapped by
total internal reflection leaves after more bounces, near the cone's rim, where the fold
puts it), so no sample fails: ``p_f(w) = p_b(w) + p_b(unfold(w)) μ_c / (1 - μ_c)``; or a
cosine lobe for the light the interreflections spread, with the share ``c = clip(0.8 -
0.15 ln ν, 0.2, 0.8)`` (:data:`MIXTURE_BOUNDS`, :data:`MIXTURE_SLOPE`): most of it over
a broad lobe, whose own samples cover the cosine's directions too, little over a narrow
one, whose light the cosine lobe would give heavy weights. The cosine lobe leans away
from ``ω_i``'s azimuth (``φ_o``: ``ω_o``'s azimuth from it; :meth:`NestedEstimator.forward`),
where the bounces of a glossy base carry its light, by ``b = 0.4 sin θ_i ā²``
(:data:`FORWARD_BIAS`; none at normal incidence, little over a dark base). ``P_R``, ``c``
and ``b`` are deterministic functions of ``ω_i`` (the probe's numbers are fixed), so
``pdf`` repeats them. The weight is the sum's estimate of ``f cos θ_o`` divided by ``p``: ``sample``,
``eval`` and ``pdf`` are consistent by construction, ``pdf`` is the true density of
``sample`` (Mitsuba's chi2 test passes), and MIS weights built from it sum to one in both
strategies. (Were ``p`` only an approximation of the sampler's density, as pbrt's layered
pdf is, the sum would still be unbiased: the BSDF strategy estimates ``∫ w(ω) f cos L``
for any deterministic ``w`` when its weight is an unbiased estimate of ``f cos / p_true``,
the light strategy the rest.)

**Polarized variants**: every factor of a path is a Mueller matrix in Mitsuba's implicit
Stokes bases of the directions the light travels
(:meth:`~thinfilm_mi.render.layered.top.SmoothTop.crossing`: the stack's amplitudes
rotated as ``thinfilm_dielectric`` rotates them; the base's own matrices), so the products
``T_out · B_0 · U_1 · B_1 ⋯ E_k · T_in`` chain; Russian roulette reads ``M00``. Importance
transport gets the chain's ``M00``, depolarized.

**Not covered**: light the base transmits (``principled``'s ``spec_trans``, a
``dielectric``'s refraction) leaves the layer downwards and is lost (no layer below).
"""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.render.layered.bottom import base_context, base_interaction, intensity
from thinfilm_mi.render.layered.coated import CoatedEstimator
from thinfilm_mi.render.layered.escape import critical_cosine, fold, unfold
from thinfilm_mi.render.layered.forms import closed_form
from thinfilm_mi.render.layered.walk import RandomWalk, eval_seed, logical_not, sample_seed
from thinfilm_mi.render.textures import mitsuba_module
from thinfilm_mi.render.variant import spectral_mean

__all__ = ["MIXTURE_BOUNDS", "MIXTURE_SLOPE", "FORWARD_BIAS", "PROBE", "ALBEDO_FLOOR", "NestedEstimator",
           "sum_estimator", "critical_cosine", "fold", "unfold"]

#: The bounds of the cosine lobe's share ``c`` of the sampling mixture: every direction a
#: bounce can reach keeps a density, and the base's own lobe keeps a fifth. Any ``c`` in
#: (0, 1) that depends on ``ω_i`` only keeps the estimate unbiased and ``pdf`` exact; it only
#: moves the noise between glossy and diffuse-looking light.
MIXTURE_BOUNDS = (0.2, 0.8)
#: How fast ``c`` falls with the base lobe's peak ``ν`` (per e-fold): 0.8 for a Lambertian
#: or a lobe as broad, 0.45 at ``ν = 10``, 0.2 from ``ν ≈ 55`` (a ``roughconductor``'s
#: α 0.3 under a 1.5 coat at normal incidence: ``ν ≈ 2``, α 0.12 ``ν ≈ 11``, α 0.05 more than
#: 55).
MIXTURE_SLOPE = 0.15
#: The cosine lobe's bias towards the azimuth away from ``ω_i`` over a white base at grazing
#: incidence (:meth:`NestedEstimator.forward_bias`): the light that bounces in the layer
#: leaves forwards. Any value in [0, 1) keeps ``pdf`` exact.
FORWARD_BIAS = 0.4
#: The probe's fixed numbers ``(sample1, sample2)``: two stratified samples of the base
#: (one picks a ``principled``'s lobes too unevenly for its albedo).
PROBE = ((0.25, (0.3, 0.25)), (0.75, (0.8, 0.75)))
#: The least albedo the probe reports, so that ``P_R < 1`` where the base may reflect
#: light the probe's two samples missed.
ALBEDO_FLOOR = 0.05


def _azimuth(w):
    """The unit azimuth of ``w`` (a ``Vector2f``; 0 along the normal)."""
    mi = mitsuba_module()
    sin = dr.sqrt(dr.square(w.x) + dr.square(w.y))
    inv = dr.rcp(dr.select(sin > 0, sin, 1.0))
    return mi.Vector2f(w.x * inv, w.y * inv)


def _cos_azimuth(w, d):
    """The cosine of the azimuth between ``w`` and the unit azimuth ``d`` (0 along the
    normal)."""
    sin = dr.sqrt(dr.square(w.x) + dr.square(w.y))
    return (w.x * d.x + w.y * d.y) / dr.select(sin > 0, sin, 1.0)


def sum_estimator(layer):
    """The estimator of ``layer``'s (a :class:`NestedEstimator`) sum over paths: its base's
    closed form where it has one that applies, else the random walk."""
    return closed_form(layer) or RandomWalk(layer)


class NestedEstimator(CoatedEstimator):
    """The layered BSDF of ``top`` (a :class:`~thinfilm_mi.render.layered.top.SmoothTop`,
    whose substrate is the coat medium) over ``bottom`` (a
    :class:`~thinfilm_mi.render.layered.bottom.NestedBottom`), through ``medium`` (a
    :class:`~thinfilm_mi.render.layered.coat.CoatMedium`), its sum over paths :attr:`sum`
    (:func:`sum_estimator`); the rest as :class:`~thinfilm_mi.render.layered.coated.CoatedEstimator`."""

    def __init__(self, top, bottom, medium, mode, plugin: str, max_bounces: int):
        self.sum = None
        super().__init__(top, bottom, medium, mode, plugin, max_bounces)
        #: the sum over paths (:func:`sum_estimator`)
        self.sum = sum_estimator(self)

    form = property(lambda self: None if isinstance(self.sum, RandomWalk) else self.sum,
                    doc="The closed form of the sum, or ``None`` (the walk).")

    def refresh(self) -> None:
        """Re-derive the load-time quantities after an edit (the top refreshed first)."""
        super().refresh()
        #: no films between equal indices: the nested BSDF itself (times the coat's
        #: absorption), bit for bit
        self.invisible = self.top.invisible
        if self.sum is not None:
            self.sum.refresh()

    # -- pieces ----------------------------------------------------------------
    def underside(self, si, arrive, active):
        """``R_in(θ') A(θ')²``: what one reflection at the stack's underside, of light
        travelling up along ``arrive``, and the two crossings of the coat around it leave
        (:meth:`SmoothTop.crossing`: a Mueller matrix in polarized variants)."""
        resp = self.top.unpolarized(si, arrive.z, active, inside=True, transmission=False)
        mi = mitsuba_module()
        leave = mi.Vector3f(arrive.x, arrive.y, -arrive.z)
        r = self.top.crossing(resp.R, resp.reflection, arrive, leave)
        a = self.medium.attenuation(si, arrive.z, active)
        return r if a is None else r * a * a

    def transmitted(self, ctx_mode, si, wo, seed, active, top_i=None):
        """The estimate of the base part of ``f cos θ_o`` (outer ``si.wi``, ``wo``) by the
        sum estimator (:attr:`sum`: the walk or a closed form);
        ``top_i``: the stack's response at ``si.wi`` where the caller has it."""
        mi = mitsuba_module()
        wi_in, ok_i = self.top.inward(si.wi)
        wo_in, ok_o = self.top.inward(wo)
        active = active & ok_i & ok_o
        if top_i is None:
            top_i = self.top.unpolarized(si, si.wi.z, active, inside=False, transmission=True)
        top_o = self.top.unpolarized(si, wo.z, active, inside=False, transmission=True)
        acc = self.sum.sum(ctx_mode, si, wi_in, wo_in, seed, active)
        if self.delta is not None:
            # the light entering along -wo' may make delta round trips (base, underside)
            # before its last non-delta vertex: D at w̄ = (-wo'_x, -wo'_y, wo'_z)
            d = self.delta.round_trips(ctx_mode, si, mi.Vector3f(-wo_in.x, -wo_in.y, wo_in.z),
                                       self.delta.rng(seed), active)
            acc = acc * d
        # light enters along -wo, is refracted along -wo', ..., leaves the base along wi'
        # and the coat along wi (Mueller products right to left)
        leave = self.top.crossing(top_i.T, top_i.transmission, wi_in, si.wi)
        enter = self.top.crossing(top_o.T, top_o.transmission, -wo, -wo_in)
        value = leave * acc * enter * (self.top.inv_eta2 * wo.z / dr.maximum(wo_in.z, 1e-12))
        if self.mode.polarized and ctx_mode != mi.TransportMode.Radiance:
            # importance transport: the chain's intensity for unpolarised light, depolarized
            value = mi.depolarizer(mi.UnpolarizedSpectrum(value[0][0]))
        for a in (self.medium.attenuation(si, wi_in.z, active), self.medium.attenuation(si, wo_in.z, active)):
            if a is not None:
                value = value * a
        return dr.select(active, value, dr.zeros(mi.Spectrum))

    def probe(self, ctx_mode, si, active):
        """``(ā, c)``: the base's albedo at ``ω_i'`` and the cosine lobe's share of the
        mixture, from samples of its non-delta lobes at the fixed numbers :data:`PROBE`
        (module docstring); deterministic in ``ω_i``, detached (sampling decisions)."""
        mi = mitsuba_module()
        wi_in, ok = self.top.inward(si.wi)
        ok = active & ok
        ctx = self.bottom.smooth_context(ctx_mode)
        si_b = base_interaction(si, wi_in)
        albedo, peak = mi.Float(0.0), mi.Float(0.0)
        with dr.suspend_grad():
            for s1, s2 in PROBE:
                bs, g = self.bottom.bsdf.sample(ctx, si_b, mi.Float(s1), mi.Point2f(*s2), ok)
                hit = ok & (bs.pdf > 0) & (bs.wo.z > 0)
                albedo += dr.select(hit, spectral_mean(intensity(g, self.mode.polarized)), 0.0)
                peak += dr.select(hit, bs.pdf * dr.pi / dr.maximum(bs.wo.z, 1e-3), 0.0)
        albedo = dr.clip(albedo / len(PROBE), ALBEDO_FLOOR, 1.0)
        low, high = MIXTURE_BOUNDS
        share = dr.clip(high - MIXTURE_SLOPE * dr.log(dr.maximum(peak / len(PROBE), 1.0)),
                        low, high)
        return dr.detach(albedo), dr.detach(share)

    def prob_reflect(self, ctx_mode, si, top_i, albedo, active):
        """``P_R``: the delta lobe's spectral mean ``R̄ + T̄ b̄`` (``b̄``: the mean of the
        base's delta reflectance at ``ω_i'`` sampled with fixed numbers, 0 for a base
        without delta lobes) against it plus the base's ``T̄ ā_e`` (module docstring;
        ``albedo``: the probe's ``ā``): a deterministic function of the directions, the
        same in ``sample`` and ``pdf``; detached (a sampling decision divides the weight as
        a constant)."""
        mi = mitsuba_module()
        pr = spectral_mean(mi.UnpolarizedSpectrum(top_i.R))
        pt = spectral_mean(mi.UnpolarizedSpectrum(top_i.T))
        delta = pr
        if self.delta is not None:
            wi_in, ok = self.top.inward(si.wi)
            delta = pr + pt * self.delta.mean(ctx_mode, si, wi_in, active & ok)
        escape = self.top.inv_eta2
        total = delta + pt * albedo * escape / (1.0 - albedo * (1.0 - escape))
        return dr.detach(dr.select(total > 0, delta / dr.select(total > 0, total, 1.0), 1.0))

    def base_pdf(self, ctx_mode, si, wo, share, bias, active):
        """The non-delta density at ``wo`` without the factor ``1 - P_R`` (``share``: the
        cosine lobe's, from :meth:`probe`; ``bias``: its :meth:`forward_bias`)."""
        ctx = self.bottom.smooth_context(ctx_mode)
        wi_in, ok_i = self.top.inward(si.wi)
        wo_in, ok_o = self.top.inward(wo)
        ok = active & ok_i & ok_o & (wo.z > 0)
        si_b = base_interaction(si, wi_in)
        p_b = self.bottom.bsdf.pdf(ctx, si_b, wo_in, ok)
        # the base's directions beyond the critical cosine that fold onto wo_in
        mu_c = critical_cosine(self.top.eta_f)
        pre = unfold(wo_in, mu_c)
        ok_f = ok & (mu_c > 0) & (pre.z > 0)
        p_f = self.bottom.bsdf.pdf(ctx, si_b, pre, ok_f)
        p_b = p_b + dr.select(ok_f, p_f * mu_c / dr.maximum(1.0 - mu_c, 1e-6), 0.0)
        jac = self.top.inv_eta2 * wo.z / dr.maximum(wo_in.z, 1e-12)
        p = (1.0 - share) * p_b * jac + share * self.forward_pdf(si, wo, bias)
        return dr.select(ok, p, 0.0)

    def forward_bias(self, si, albedo):
        """``b = FORWARD_BIAS sin θ_i ā²`` (``ā``: the probe's albedo): the cosine lobe's
        bias towards the azimuth away from ``ω_i`` (:meth:`forward_pdf`), none at normal
        incidence, where no azimuth stands out, and little over a dark base, whose light
        seldom bounces; detached (a sampling decision)."""
        sin = dr.sqrt(dr.square(si.wi.x) + dr.square(si.wi.y))
        return dr.detach(FORWARD_BIAS * dr.minimum(sin, 1.0) * dr.square(albedo))

    def forward(self, si, w, u, bias):
        """A cosine lobe's sample ``w`` on ``ω_i``'s side of the hemisphere mirrored to the
        other side (across the plane of the normal square to ``ω_i``'s azimuth) where ``u``
        is below ``bias`` times the cosine of their azimuths: the density of
        :meth:`forward_pdf`."""
        mi = mitsuba_module()
        d = _azimuth(si.wi)
        along = w.x * d.x + w.y * d.y
        turn = (along > 0) & (u < bias * _cos_azimuth(w, d))
        return dr.select(turn, mi.Vector3f(w.x - 2.0 * along * d.x, w.y - 2.0 * along * d.y, w.z), w)

    def forward_pdf(self, si, wo, bias):
        """The density of :meth:`forward`'s directions, ``(1 - b cos φ) cos θ / π`` (``b``:
        ``bias``; ``φ``: the azimuth of ``wo`` from ``ω_i``'s): more of it away from
        ``ω_i``, where a glossy base's interreflections leave (each bounce scatters
        forwards)."""
        return (1.0 - bias * _cos_azimuth(wo, _azimuth(si.wi))) * dr.maximum(wo.z, 0.0) * dr.inv_pi

    # -- the BSDF interface ----------------------------------------------------
    def sample(self, ctx, si, sample1, sample2, active, has_delta: bool, has_base: bool):
        """``(bs, weight)``: the delta reflection or a direction of the mixture
        (:meth:`base_pdf`), weighted by the walk's estimate of ``f cos θ_o`` over ``pdf``."""
        mi = mitsuba_module()
        bs = dr.zeros(mi.BSDFSample3f)
        active = mi.Bool(active) & (si.wi.z > 0)
        if not (has_delta or has_base):
            return bs, mi.Spectrum(0.0)
        if self.invisible:
            return self._sample_invisible(ctx, si, sample1, sample2, active, has_delta, has_base)
        top_i = self.top.unpolarized(si, si.wi.z, active, inside=False, transmission=True)
        albedo, share = self.probe(ctx.mode, si, active) if has_base else (None, None)
        if has_delta and has_base:
            p_r = self.prob_reflect(ctx.mode, si, top_i, albedo, active)
        else:
            p_r = mi.Float(1.0 if has_delta else 0.0)
        sel_r = active & (sample1 < p_r)
        sel_b = active & (sample1 >= p_r)
        bs.eta = 1.0
        weight = mi.Spectrum(0.0)
        wo = mi.reflect(si.wi)
        seed = sample_seed(sample1, sample2)
        if has_delta:
            inv_p = dr.rcp(dr.select(p_r > 0, p_r, 1.0))
            delta = self.mode.value(top_i.R * inv_p, top_i.reflection, ctx, si.wi, wo)
            if self.delta is not None:
                wi_in, ok = self.top.inward(si.wi)
                delta = delta + self.delta.chain(ctx.mode, si, top_i, wi_in,
                                                 self.delta.rng(seed), sel_r & ok) * inv_p
            weight = dr.select(sel_r, delta, weight)
        if has_base:
            s = (sample1 - p_r) / dr.select(p_r < 1, 1.0 - p_r, 1.0)
            cosine = sel_b & (s < share)
            s_b = (s - share) / (1.0 - share)
            wi_in, _ = self.top.inward(si.wi)
            ctx_b = self.bottom.smooth_context(ctx.mode)
            bs_b, _ = self.bottom.bsdf.sample(ctx_b, base_interaction(si, wi_in), dr.clip(s_b, 0.0, 1.0),
                                       sample2, sel_b & logical_not(cosine))
            mu_c = critical_cosine(self.top.eta_f)
            trapped = (bs_b.wo.z > 0) & (bs_b.wo.z < mu_c)
            out, leaves = self.top.outward(dr.select(trapped, fold(bs_b.wo, mu_c), bs_b.wo))
            bias = self.forward_bias(si, albedo)
            wo_c = self.forward(si, mi.warp.square_to_cosine_hemisphere(sample2),
                                s / dr.select(share > 0, share, 1.0), bias)
            wo_b = dr.select(cosine, wo_c, out)
            ok = sel_b & (cosine | (leaves & (bs_b.wo.z > 0) & (bs_b.pdf > 0)))
            wo = dr.select(sel_b, wo_b, wo)
            pdf = (1.0 - p_r) * self.base_pdf(ctx.mode, si, wo, share, bias, ok)
            f = self.transmitted(ctx.mode, si, wo, seed, ok & (pdf > 0), top_i)
            weight = dr.select(ok & (pdf > 0), f / dr.select(pdf > 0, pdf, 1.0), weight)
            sel_b = ok & (pdf > 0)
            btype = dr.select(cosine, mi.UInt32(+mi.BSDFFlags.DiffuseReflection),
                              bs_b.sampled_type & mi.UInt32(+mi.BSDFFlags.Reflection))
            bs.sampled_type = dr.select(sel_r, mi.UInt32(+mi.BSDFFlags.DeltaReflection), btype)
            bs.sampled_component = dr.select(sel_r, mi.UInt32(0), mi.UInt32(1))
            bs.pdf = dr.select(sel_r, p_r, pdf)
        else:
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DeltaReflection)
            bs.sampled_component = mi.UInt32(0)
            bs.pdf = p_r
        bs.wo = wo
        valid = sel_r | sel_b
        return bs, dr.select(valid, weight, 0.0)

    def _invisible_context(self, mode, has_delta: bool, has_base: bool):
        """The base's context where the top is invisible: the lobes the caller enabled
        (Mitsuba's default context where both are)."""
        mi = mitsuba_module()
        if has_delta and has_base:
            return mi.BSDFContext(mode)
        return self.bottom.smooth_context(mode) if has_base \
            else base_context(mode, mi.BSDFFlags.DeltaReflection)

    def _sample_invisible(self, ctx, si, sample1, sample2, active, has_delta, has_base):
        """The nested BSDF's own sample (times the coat's absorption) where the top is
        invisible (no films between equal indices); its delta samples are component 0."""
        mi = mitsuba_module()
        ctx_b = self._invisible_context(ctx.mode, has_delta, has_base)
        bs, w = self.bottom.bsdf.sample(ctx_b, si, sample1, sample2, active)
        ok = active & (bs.wo.z > 0)
        bs.sampled_component = dr.select(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta),
                                         mi.UInt32(0), mi.UInt32(1))
        bs.sampled_type = bs.sampled_type & mi.UInt32(+mi.BSDFFlags.Reflection)
        a = self.medium.attenuation(si, si.wi.z, active)
        if a is not None:
            w = w * a * self.medium.attenuation(si, bs.wo.z, active)
        return bs, dr.select(ok, w, 0.0)

    def eval_pdf(self, ctx, si, wo, active, has_delta: bool, has_base: bool,
                 want_value: bool = True, want_pdf: bool = True):
        """``(f cos θ_o, pdf)``: the walk's estimate (seeded by the directions) and the
        density of :meth:`sample`."""
        mi = mitsuba_module()
        active = mi.Bool(active) & (si.wi.z > 0) & (wo.z > 0)
        value, pdf = mi.Spectrum(0.0), mi.Float(0.0)
        if not has_base:
            return value, pdf
        if self.invisible:
            # the nested BSDF's own calls, bit for bit (times the coat's absorption)
            ctx_b = self._invisible_context(ctx.mode, has_delta, has_base)
            si_b = base_interaction(si, si.wi)
            if want_value and want_pdf:
                value, pdf = self.bottom.bsdf.eval_pdf(ctx_b, si_b, wo, active)
            elif want_value:
                value = self.bottom.bsdf.eval(ctx_b, si_b, wo, active)
            else:
                pdf = self.bottom.bsdf.pdf(ctx_b, si_b, wo, active)
            a = self.medium.attenuation(si, si.wi.z, active)
            if a is not None and want_value:
                value = value * a * self.medium.attenuation(si, wo.z, active)
            return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)
        top_i = self.top.unpolarized(si, si.wi.z, active, inside=False, transmission=True) \
            if want_value or (want_pdf and has_delta) else None
        if want_value:
            value = self.transmitted(ctx.mode, si, wo, eval_seed(si.wi, wo), active, top_i)
        if want_pdf:
            albedo, share = self.probe(ctx.mode, si, active)
            pdf = self.base_pdf(ctx.mode, si, wo, share, self.forward_bias(si, albedo), active)
            if has_delta:
                pdf = pdf * (1.0 - self.prob_reflect(ctx.mode, si, top_i, albedo, active))
        return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)
