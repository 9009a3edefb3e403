r"""The delta-base chain (no plugin classes here): the part of
:mod:`thinfilm_mi.render.layered.nested`'s estimator that a base with a delta reflection adds.

**Bases with delta lobes** (a smooth ``conductor``, ``dielectric``, ``plastic``'s
reflection, our ``thinfilm_diffuse``'s film): the paths are split by their *last non-delta
base vertex*. Paths without one are all-delta: they leave in the mirror direction and join
the coating's delta lobe (component 0)::

    R(θ_i) + T(θ_i)² A(θ_i')² B_δ(ω_i') D(ω_i'),   D = Σ_n M^n = (1 - M)^-1,   M = R_in A² B_δ

(:meth:`DeltaBase.chain`; ``B_δ(w)``: the base's delta reflectance for light leaving it
along ``w``, the weight of a sample of the base with only ``DeltaReflection`` enabled;
polarized: the Mueller chain ``leave · B_δ · (I - U B_δ)^-1 · enter``, each factor in the
frames :meth:`~thinfilm_mi.render.layered.top.SmoothTop.crossing` uses). It carries no
``(η_e/η_c)²``: entering, radiance gains ``(η_c/η_e)²``, leaving it loses it again, and the
Dirac delta of the inner directions maps to that of the outer ones with the Jacobian
``dω'/dω`` that produced the factor for the non-delta part. Every other path ends at a
non-delta vertex ``k``, reached by next-event estimation through the base's ``eval`` (as for
any base) and preceded, on the light's side, by zero or more delta round trips at the exit
direction: the walk's sum is multiplied by ``D`` at ``w̄ = (-ω_o'_x, -ω_o'_y, ω_o'_z)``
(:meth:`DeltaBase.round_trips`, deterministic per
direction pair: plain AD carries its gradients). On the camera's side the walk samples the
base with all its lobes: a delta sample keeps ``w`` (``w_{k+1} = w_k``) and multiplies
``β`` by its weight and the underside; ``eval`` at such a vertex is 0, as it must be (its
delta part is the next vertex's business). ``D`` is estimated as ``1 + M_1 (1 + M_2 (1 -
M_3)^-1)`` from independent samples of ``B_δ``: exact where ``B_δ`` is a deterministic
function of the directions (every Mitsuba BSDF with a delta reflection and ours, except
mixtures), and where a base picks its delta lobe at random (a ``blendbsdf`` of a delta and
another BSDF) only the last level's closed form is biased, by ``E[M]² (E[(1 - M)^-1] - (1
- E[M])^-1) >= 0`` (Jensen): < 1e-4 relative for a conductor blended 50/50 with black under
a bare 1.5 coat (``tests/render/layered/test_delta.py``), where one closed form of one sample was
1-3 % off. Light a base transmits (a ``dielectric``'s refraction) is lost, as any base's.
"""
from __future__ import annotations

import drjit as dr

from thinfilm_mi.render.layered.bottom import base_context, base_interaction, intensity
from thinfilm_mi.render.textures import mitsuba_module
from thinfilm_mi.render.variant import spectral_mean

__all__ = ["TAIL_LEVELS", "DeltaBase"]

#: Levels of the delta round trips' series drawn before its closed form
#: (:meth:`DeltaBase.round_trips`): the bias of a base that picks its delta lobe at random
#: falls as ``E[M]^TAIL_LEVELS``; each level is one more sample of the base.
TAIL_LEVELS = 2


class DeltaBase:
    """The delta reflection of ``layer.base`` (a
    :class:`~thinfilm_mi.render.layered.nested.NestedEstimator`, whose top's crossings,
    underside and coat absorption it composes)."""

    def __init__(self, layer):
        self.layer = layer

    def reflectance(self, ctx_mode, si, w, numbers, active):
        """``B_δ(w)``: the base's delta reflection for light leaving it along ``w`` (its
        ``wi``; the light arrives along ``-(−w_x, −w_y, w_z)``): the weight of a sample of
        the base with only its delta reflection enabled (``numbers``: ``(s1, s2)``), 0
        where it samples none."""
        mi = mitsuba_module()
        s1, s2 = numbers
        bs, g = self.layer.base.sample(base_context(ctx_mode, mi.BSDFFlags.DeltaReflection),
                                         base_interaction(si, w), s1, s2, active)
        ok = active & mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaReflection) \
            & (bs.wo.z > 0) & (bs.pdf > 0)
        return dr.select(ok, g, 0.0)

    def mean(self, ctx_mode, si, w, active):
        """The spectral mean of ``B_δ(w)``'s intensity sampled with fixed numbers (a
        deterministic function of the directions, for the choice of the delta lobe), at
        most 1."""
        mi = mitsuba_module()
        b = self.reflectance(ctx_mode, si, w, (mi.Float(0.5), mi.Point2f(0.5, 0.5)), active)
        return dr.minimum(spectral_mean(intensity(b, self.layer.mode.polarized)), 1.0)

    def round_trips(self, ctx_mode, si, w, rng, active):
        """``D(w)``: the delta round trips before a base vertex that light reaches along
        ``-w̄`` (``w̄ = (-w_x, -w_y, w_z)``): ``D = Σ_n M^n = (1 - M)^-1``, ``M = U(w)
        B_δ(w)`` (reflected by the base up along ``w``, by the underside back along
        ``-w̄``). Estimated as ``1 + M_1 (1 + M_2 (1 - M_3)^-1)`` (:data:`TAIL_LEVELS` = 2
        levels) with ``M_j`` of independent samples of ``B_δ`` (numbers from ``rng``): exact
        where ``B_δ`` is deterministic (it then sums to ``(1 - M)^-1``), and where a base
        picks its delta lobe at random (a ``blendbsdf``) only the closed form's ``E[(1 -
        M)^-1] >= (1 - E[M])^-1`` (Jensen) is biased, weighted by ``E[M]^2`` (module
        docstring). A spectrum division, or Mueller matrices (the inverse of ``I - M``) in
        polarized variants; 0 where the closed form diverges (``M`` >= 1: a lossless
        closed cavity, which no light enters)."""
        mi = mitsuba_module()
        u = self.layer.underside(si, w, active)
        m = [u * self.reflectance(ctx_mode, si, w, self.numbers(rng), active)
             for _ in range(TAIL_LEVELS + 1)]
        if self.layer.mode.polarized:
            one = dr.identity(mi.Spectrum)
            d = dr.select(dr.all(m[-1][0][0] < 1), dr.rcp(one - m[-1]), dr.zeros(mi.Spectrum))
        else:
            one = mi.Spectrum(1.0)
            d = dr.select(m[-1] < 1, dr.rcp(dr.select(m[-1] < 1, 1.0 - m[-1], 1.0)), 0.0)
        for m_j in reversed(m[:-1]):
            d = one + m_j * d
        return mi.Spectrum(d)

    @staticmethod
    def numbers(rng):
        """``(s1, s2)`` for one sample of the base from ``rng``."""
        mi = mitsuba_module()
        return rng.next_float32(), mi.Point2f(rng.next_float32(), rng.next_float32())

    @staticmethod
    def rng(seed):
        """A PCG32 for :meth:`round_trips` and :meth:`chain`, from the walk's ``seed``
        (two ``UInt32``) on a stream of its own."""
        mi = mitsuba_module()
        a, b = mi.sample_tea_32(seed[1], seed[0], 4)
        return mi.PCG32(size=1, initstate=mi.UInt64(a), initseq=mi.UInt64(b))

    def chain(self, ctx_mode, si, top_i, wi_in, rng, active):
        """The all-delta paths at the mirror direction: ``T(θ_i)² A(θ_i')² B_δ D`` at
        ``ω_i' = wi_in`` (Mueller chain ``leave · B_δ · D · enter``, ``B_δ`` a sample
        independent of those of :meth:`round_trips`; no ``(η_e/η_c)²``: module docstring;
        ``top_i``: the stack's response at ``θ_i``). Light tracing gets its intensity,
        depolarized, as the coating's transmitted part."""
        mi = mitsuba_module()
        c = self.layer
        wo = mi.reflect(si.wi)
        wo_in = mi.Vector3f(-wi_in.x, -wi_in.y, wi_in.z)
        b = self.reflectance(ctx_mode, si, wi_in, self.numbers(rng), active)
        d = self.round_trips(ctx_mode, si, wi_in, rng, active)
        leave = c.top.crossing(top_i.T, top_i.transmission, wi_in, si.wi)
        enter = c.top.crossing(top_i.T, top_i.transmission, -wo, -wo_in)
        value = leave * b * d * enter
        if c.mode.polarized and ctx_mode != mi.TransportMode.Radiance:
            value = mi.depolarizer(mi.UnpolarizedSpectrum(value[0][0]))
        a = c.medium.attenuation(si, wi_in.z, active)
        if a is not None:
            value = value * a * a
        return dr.select(active, value, dr.zeros(mi.Spectrum))
