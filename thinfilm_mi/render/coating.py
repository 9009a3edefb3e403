r"""``thinfilm_coating``'s model (no plugin classes here): a smooth thin-film stack over any
nested Mitsuba BSDF, evaluated by a position-free random walk between the two interfaces
(Guo, Hašan, Yan and Zhao 2018; pbrt-v4's ``LayeredBxDF``).

Geometry (local shading frame, ``z`` up). The stack (:class:`~thinfilm_mi.render.kernel.KernelStack`)
lies between the exterior (index ``η_e``) and the coat medium (``η_c``); the nested BSDF
(the *base*) lies under the coat medium, parallel to it; lateral offsets are ignored
(position-free). A direction ``w`` outside has the inner direction ``w'`` of Snell's law
(:func:`inward`: ``w'_xy = w_xy / η``, ``η = η_c/η_e``, the mean indices: a path has one
direction for all its wavelengths), on the same (upper) hemisphere: the base sees the
light arriving along ``-w'`` and its ``wi`` is ``w'``.

**The BSDF.** For light between ``ω_i`` and ``ω_o`` outside::

    f(ω_i, ω_o) = δ-reflection R(θ_i) (+ the base's all-delta chains, below)
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
of the exit direction cancels it (see :meth:`Coating.sample`).

**The estimate** (:meth:`Coating.walk`): from ``w_0 = ω_i'``, at every base vertex ``k``
the contribution ``β_k f_b(w_k, ω_o') cos θ_o'`` (the base's ``eval``, towards the fixed
inner direction of ``ω_o``: next-event estimation through the smooth top, which refracts
``ω_o'`` to ``ω_o`` deterministically); then the base is sampled, ``w``, weight ``g``, and
the walk goes on reflected by the underside: ``β_{k+1} = β_k g R_in(θ_w) A(w)²``,
``w_{k+1} = (-w_x, -w_y, w_z)``. The first term is exact (``w_0`` is fixed); later ones
are unbiased estimates of the interreflection series. Russian roulette from
:data:`RR_DEPTH` bounces on (survival ``q = min(max β, 0.95)``, ``β /= q``: unbiased);
the walk stops after ``max_bounces`` base vertices: the paths with more are dropped. For
a Lambertian base of albedo ``ρ`` each vertex sends back ``ρ R̄`` of what it receives
(``R̄``: the underside's hemispherical reflectance), so the dropped energy is at most ``(ρ R̄)^N /
(1 - ρ R̄)`` of the light that entered: ``0.596^64/0.404 ≈ 1e-14`` for a bare ``η = 1.5``
coat over white. A base that sends its light beyond the critical angle meets ``R_in = 1``
there and may lose more (``tests/render/test_coating.py`` measures the truncation at
``N = 1``). Random numbers: a PCG32 seeded from the sample's numbers in ``sample`` and
from a TEA hash of the two directions in ``eval`` (as pbrt-v4's ``LayeredBxDF``), so
every call is deterministic.

**Closed forms**: where the base has one (Mitsuba's ``diffuse`` without coat absorption,
in spectral and polarized variants: :mod:`thinfilm_mi.render.coating_forms`), the walk's
sum is replaced by its expectation, with no noise.

**Bases with delta lobes** (a smooth ``conductor``, ``dielectric``, ``plastic``,
``thinfilm_diffuse``): the all-delta paths join the delta lobe, every exit carries the
delta round trips, and the walk samples delta vertices as any other
(:mod:`thinfilm_mi.render.coating_delta`).

**Sampling** (:meth:`Coating.sample`): the delta lobe with probability ``P_R = (R̄ + T̄ b̄)
/ (R̄ + T̄)`` (spectral means at ``θ_i``; ``b̄``: the mean of ``B_δ(ω_i')`` sampled with
fixed numbers, 0 for a base without delta lobes: deterministic, so ``pdf`` repeats it),
weight the delta lobe over ``P_R``; 1 over a pure-delta base (no component 1). Otherwise a
direction is drawn from a deterministic mixture (:meth:`Coating.base_pdf`, its exact
density)::

    p(ω_o) = (1 - P_R) [ (1 - c) p_b(ω_i', ω_o') (η_e/η_c)² cos θ_o / cos θ_o' + c cos θ_o / π ]

the base sampled at ``ω_i'`` (its non-delta lobes only, :meth:`Coating.smooth_context`, in
both) and refracted out (a base direction beyond the critical angle is a failed sample:
``p`` then integrates to less than one, as the sampler's mass does), or a cosine lobe for
the light the interreflections spread (``c``: :func:`mixture`). The weight is the walk's
estimate of ``f cos θ_o`` divided by ``p``: ``sample``, ``eval`` and ``pdf`` are
consistent by construction, ``pdf`` is the true density of ``sample`` (Mitsuba's chi2 test
passes), and MIS weights built from it sum to one in both strategies. (Were ``p`` only an
approximation of the sampler's density, as pbrt's layered pdf is, the sum would still be
unbiased: the BSDF strategy estimates ``∫ w(ω) f cos L`` for any deterministic ``w`` when
its weight is an unbiased estimate of ``f cos / p_true``, the light strategy the rest.)

**Polarized variants**: every factor of a path is a Mueller matrix in Mitsuba's implicit
Stokes bases of the directions the light travels (:meth:`Coating.crossing`: the stack's
amplitudes rotated as ``thinfilm_dielectric`` rotates them; the base's own matrices), so
the products ``T_out · B_0 · U_1 · B_1 ⋯ E_k · T_in`` chain; Russian roulette reads
``M00``. Importance transport gets the chain's ``M00``, depolarized.

**Not covered**: light the base transmits (``principled``'s ``spec_trans``, a
``dielectric``'s refraction) leaves the layer downwards and is lost (no layer below).
"""
from __future__ import annotations

import struct

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.render.coating_delta import DeltaBase, base_context, base_interaction, intensity
from thinfilm_mi.render.coating_forms import closed_form
from thinfilm_mi.render.textures import GRID, mitsuba_module, scalar, texture_range
from thinfilm_mi.render.variant import spectral_mean
from thinfilm_mi.tabulate.base import opaque_float

__all__ = ["DEFAULT_MAX_BOUNCES", "RR_DEPTH", "MIXTURE", "Coating", "nested_bsdf", "inward",
           "outward", "mixture", "check_coat_medium"]

#: Default cap on the base vertices of a walk (``max_bounces``); its bias is stated in
#: the module docstring.
DEFAULT_MAX_BOUNCES = 64
#: Russian roulette starts after this many base vertices.
RR_DEPTH = 3
#: The cosine lobe's share ``c`` of the sampling mixture (:func:`mixture`): every
#: direction a bounce can reach keeps a density (a narrow glossy base would otherwise
#: leave the interreflected light to rare, heavy samples), and the base's own lobe
#: keeps half. Any fixed value in (0, 1) keeps the estimate unbiased and ``pdf``
#: exact; it only moves the noise between glossy and diffuse-looking light.
MIXTURE = 0.5


def nested_bsdf(props, plugin: str):
    """The one nested BSDF of a coating's properties: named ``bsdf``, or the one
    nested BSDF of another name (XML's unnamed child). Refused where there is none or
    more than one."""
    mi = mitsuba_module()
    if "bsdf" in props:
        base = props.get("bsdf")
        if not isinstance(base, mi.BSDF):
            raise ThinFilmError(f"{plugin}: 'bsdf' must be a nested BSDF, got {base!r}")
        return base
    found = [obj for _, obj in props.objects() if isinstance(obj, mi.BSDF)]
    if len(found) != 1:
        raise ThinFilmError(f"{plugin}: needs exactly one nested BSDF (the base under the "
                            f"coat), got {len(found)}")
    return found[0]


def check_coat_medium(sigma_a, thickness: float, plugin: str) -> None:
    """``coat_thickness`` and ``coat_sigma_a`` finite and >= 0 (load and edits)."""
    if not np.isfinite(thickness) or thickness < 0:
        raise ThinFilmError(f"{plugin}: 'coat_thickness' must be a finite number >= 0, "
                            f"got {thickness!r}")
    if sigma_a is None:
        return
    rng = texture_range(sigma_a)
    if rng is None:
        return
    lo, hi = (float(v) for v in rng)
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo < 0:
        bad = lo if (not np.isfinite(lo) or lo < 0) else hi
        raise ThinFilmError(f"{plugin}: 'coat_sigma_a' (an absorption coefficient per unit of "
                            f"'coat_thickness') must be finite and >= 0, got {bad!r}")


def mixture(stack) -> float:
    """The cosine lobe's share ``c`` of the sampling mixture: :data:`MIXTURE`, or 0 where
    the top is invisible (no films between indices equal on Mitsuba's 1 nm grid: no
    interreflection, and the plugin is the nested BSDF itself)."""
    n_e = stack.ambient.spectral_values(GRID, real=True)
    n_c = stack.substrate.spectral_values(GRID, real=True)
    if not stack.indices and np.array_equal(n_e, n_c):
        return 0.0
    return MIXTURE


def inward(w, eta):
    """The inner direction (upper hemisphere) of an outer direction ``w`` for the relative
    index ``eta = η_c/η_e``, and whether it exists (``eta < 1`` can reflect totally)."""
    mi = mitsuba_module()
    inv = 1.0 / eta
    c2 = 1.0 - dr.square(inv) * (dr.square(w.x) + dr.square(w.y))
    return mi.Vector3f(w.x * inv, w.y * inv, dr.safe_sqrt(c2)), c2 > 0


def outward(w, eta):
    """The outer direction of an inner direction ``w`` (upper hemisphere), and whether it
    leaves (not beyond the critical angle)."""
    mi = mitsuba_module()
    c2 = 1.0 - dr.square(eta) * (dr.square(w.x) + dr.square(w.y))
    return mi.Vector3f(w.x * eta, w.y * eta, dr.safe_sqrt(c2)), c2 > 0


def _not(mask):
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


class Coating:
    """The coating of ``stack`` (its substrate is the coat medium) over ``base`` (a
    Mitsuba BSDF), with an optional Beer–Lambert coat medium (``sigma_a``, a texture,
    over ``thickness``); ``mode``: :func:`thinfilm_mi.render.modes.current`."""

    def __init__(self, stack, base, mode, sigma_a, thickness: float, max_bounces: int,
                 plugin: str):
        self.stack = stack
        self.base = base
        self.mode = mode
        self.sigma_a = sigma_a
        self.thickness = opaque_float(thickness)
        self.max_bounces = int(max_bounces)
        self.plugin = plugin
        mi = mitsuba_module()
        #: the base's delta reflection (:class:`~thinfilm_mi.render.coating_delta.DeltaBase`),
        #: or ``None`` where it has none
        self.delta = DeltaBase(self) if base.flags() & mi.BSDFFlags.DeltaReflection else None
        #: the closed form of the base part where the base has one
        #: (:mod:`~thinfilm_mi.render.coating_forms`), else ``None``: the walk
        self.form = None
        check_coat_medium(sigma_a, thickness, plugin)
        self.refresh()
        self.form = closed_form(self)

    def refresh(self) -> None:
        """Re-derive the load-time quantities after an edit (indices, films)."""
        check_coat_medium(self.sigma_a, scalar(self.thickness), self.plugin)
        if dr.is_jit_v(self.thickness):
            dr.make_opaque(self.thickness)
        self.eta = self.stack.substrate.mean_real() / self.stack.ambient.mean_real()
        c = mixture(self.stack)
        #: no films between equal indices: the nested BSDF itself (times the coat's
        #: absorption), bit for bit
        self.invisible = c == 0.0
        self.mix = opaque_float(c)
        self.inv_eta2 = opaque_float(1.0 / self.eta ** 2)
        self.eta_f = opaque_float(self.eta)
        if self.form is not None:
            self.form.refresh()

    # -- pieces ----------------------------------------------------------------
    def top(self, si, cos, active, inside: bool, transmission: bool):
        """The stack's response at the cosine ``cos`` on the side ``inside``
        (:class:`~thinfilm_mi.render.modes.Response`: unpolarised ``R``, ``T`` and, in
        polarized variants, each lobe's polarisation)."""
        mi = mitsuba_module()
        resp = self.mode.response(self.stack, si, cos, active, inside=inside,
                                  transmission=transmission)
        resp.R = mi.UnpolarizedSpectrum(resp.R)
        if transmission:
            resp.T = mi.UnpolarizedSpectrum(resp.T)
        return resp

    def crossing(self, weight, lobe, arrive, leave):
        """A crossing of (or reflection at) the stack as the variant's value: ``weight``
        (unpolarised) as a spectrum, or in polarized variants the Mueller matrix of
        ``lobe`` for light travelling along ``arrive`` and then along ``leave``, in Mitsuba's
        implicit Stokes bases of those directions (:meth:`modes.PolarizedMode.value`,
        radiance transport: it arrives along ``-wo`` and leaves along ``wi``), so that the
        products along a path chain bases that agree."""
        mi = mitsuba_module()
        if not self.mode.polarized:
            return mi.Spectrum(weight)
        return self.mode.value(weight, lobe, mi.BSDFContext(mi.TransportMode.Radiance),
                               leave, -arrive)

    def attenuation(self, si, cos, active):
        """Beer–Lambert along one crossing of the coat at ``cos`` (``None``: no medium)."""
        if self.sigma_a is None:
            return None
        mi = mitsuba_module()
        sigma = mi.UnpolarizedSpectrum(self.sigma_a.eval(si, active))
        # a spectrum (diagonal Mueller matrix in polarized variants)
        return mi.Spectrum(dr.exp(-sigma * self.thickness / dr.maximum(cos, 1e-6)))

    def underside(self, si, arrive, active):
        """``R_in(θ') A(θ')²``: what one reflection at the stack's underside, of light
        travelling up along ``arrive``, and the two crossings of the coat around it leave
        (:meth:`crossing`: a Mueller matrix in polarized variants)."""
        resp = self.top(si, arrive.z, active, inside=True, transmission=False)
        mi = mitsuba_module()
        leave = mi.Vector3f(arrive.x, arrive.y, -arrive.z)
        r = self.crossing(resp.R, resp.reflection, arrive, leave)
        a = self.attenuation(si, arrive.z, active)
        return r if a is None else r * a * a

    def smooth_context(self, mode):
        """The context of the mixture's base strategy and of :meth:`base_pdf` (the same in
        both, so ``pdf`` is the density of ``sample``): the base's non-delta lobes where it
        has delta ones, else Mitsuba's default context."""
        mi = mitsuba_module()
        return base_context(mode, mi.BSDFFlags.Smooth) if self.delta is not None \
            else mi.BSDFContext(mode)

    def tracks_gradients(self, si, active) -> bool:
        """Whether a parameter of the coating or of the nested BSDF carries gradients
        (AD variants; decided when the kernel is traced)."""
        mi = mitsuba_module()
        if not dr.is_diff_v(mi.Float):
            return False
        own = ([self.thickness] + ([self.sigma_a.eval(si, active)] if self.sigma_a else []))
        if self.stack.colour_gradients(si, active) or any(dr.grad_enabled(v) for v in own):
            return True
        params = mi.traverse(self.base)
        return any(dr.is_array_v(params[k]) and dr.grad_enabled(params[k]) for k in params.keys())

    def walk(self, ctx_mode, si, w0, wo_in, seed, active):
        """``Σ_k β_k f_b(w_k, ω_o') cos θ_o'`` from ``w_0 = w0`` (module docstring), the
        PCG32 seeded with ``seed`` (two ``UInt32``).

        Gradients: the walk runs detached, then again with the same random numbers
        (:meth:`_replay`), adding per vertex what the parameters change there, as
        Mitsuba's ``prb`` replays a path: ``dW = Σ_j β_j de_j + Σ_j dlog(g_j r_j) (W -
        W_{≤j})`` with ``e_j`` the base's ``eval`` towards ``ω_o'``, ``g_j r_j`` the step's
        base weight (the base's ``eval`` over its detached pdf at the sampled
        direction: sampling decisions are detached; at a delta vertex, whose ``eval`` is
        0, the replayed sample's weight times its pdf) and underside, and ``W - W_{≤j}``
        what the walk gathered after vertex ``j``. Every term depends on the parameters
        through its own vertex only, the sum-style loop Dr.Jit differentiates in reverse
        mode without storing the trajectory."""
        if not self.tracks_gradients(si, active):
            return self._walk(ctx_mode, si, w0, wo_in, seed, active, None)
        if self.mode.polarized:
            # the walk's sum after vertex j is a matrix product β_j s_j R_j: its derivative
            # needs the suffix R_j, which a forward loop does not have (the scalar replay
            # divides by β_j s_j instead; a Mueller product of depolarizers is singular)
            raise ThinFilmError(f"{self.plugin}: gradients in polarized variants over a walked "
                                f"base ({self.base.class_name()}) are not supported (the "
                                "replay's per-vertex ratios are per wavelength, not per "
                                "Mueller matrix); they are over a pure-delta base and over "
                                "Mitsuba's diffuse without coat_sigma_a (no walk)")
        with dr.suspend_grad():
            total = self._walk(ctx_mode, si, w0, wo_in, seed, active, None)
        surrogate = self._walk(ctx_mode, si, w0, wo_in, seed, active, total)
        return total + (surrogate - dr.detach(surrogate))

    def _walk(self, ctx_mode, si, w0, wo_in, seed, active, total):
        """The walk (``total`` None), or its replay carrying the gradients (``total``: the
        detached walk's sum)."""
        mi = mitsuba_module()
        ctx = mi.BSDFContext(ctx_mode)
        base, max_bounces = self.base, self.max_bounces
        replay = total is not None
        rng = mi.PCG32(size=1, initstate=mi.UInt64(seed[0]), initseq=mi.UInt64(seed[1]))
        zero = dr.zeros(mi.Spectrum)

        def cond(acc, gathered, beta, w, depth, rng, active):
            return active

        def body(acc, gathered, beta, w, depth, rng, active):
            alive = active
            si_b = base_interaction(si, w)
            e = base.eval(ctx, si_b, wo_in, active)
            with dr.suspend_grad(when=replay):
                gathered = dr.select(active, gathered + beta * e, gathered)
                depth = depth + 1
                s1 = rng.next_float32()
                s2 = mi.Point2f(rng.next_float32(), rng.next_float32())
                bs, g = base.sample(ctx, si_b, s1, s2, active)
                cos = bs.wo.z
                active = active & (cos > 0) & (depth < max_bounces) & (bs.pdf > 0)
                # the light that reached the base along -bs.wo left the previous vertex
                # along w_next and reflected at the underside
                w_next = mi.Vector3f(-bs.wo.x, -bs.wo.y, cos)
                step = g * self.underside(si, w_next, active)
            if replay:
                # this vertex's terms (their values do not matter: only their gradients)
                e_r = base.eval(ctx, si_b, bs.wo, active)
                if self.delta is not None:
                    # eval has no delta part: a delta vertex's value is the replayed
                    # sample's weight times its pdf (the lobe's probability), so that the
                    # base's delta parameters (a conductor's eta, k) keep their gradients
                    bs_a, g_a = base.sample(ctx, si_b, s1, s2, active)
                    e_r = dr.select(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta),
                                    g_a * bs_a.pdf, e_r)
                g_r = e_r / dr.detach(dr.select(bs.pdf > 0, bs.pdf, 1.0)) \
                    * self.underside(si, w_next, active)
                live = dr.detach(g_r) != 0
                ratio = dr.select(live, g_r / dr.select(live, dr.detach(g_r), 1.0), 0.0)
                acc = mi.Spectrum(acc + dr.select(active, ratio * (total - gathered), zero)
                                  + dr.select(alive, beta * e, zero))
            else:
                acc = gathered
            with dr.suspend_grad(when=replay):
                beta = dr.select(active, beta * step, zero)
                w = w_next
                q = dr.minimum(dr.max(intensity(beta, self.mode.polarized)), 0.95)
                roulette = active & (depth >= RR_DEPTH)
                u = rng.next_float32()
                active = active & (_not(roulette) | (u < q)) & (q > 0)
                beta = dr.select(roulette, beta / dr.select(q > 0, q, 1.0), beta)
            return acc, gathered, beta, w, depth, rng, active

        acc0, gathered0, beta0 = mi.Spectrum(zero), mi.Spectrum(zero), mi.Spectrum(1.0)
        if self.mode.polarized:
            # Mueller matrices that start as literals (zeros, the identity) fill in one
            # entry per product along the walk, so Dr.Jit would find the loop state still
            # changing when it records the loop a second time (a principled base): start
            # them as evaluated values
            dr.make_opaque(acc0, gathered0, beta0)
        state = (acc0, gathered0, beta0, mi.Vector3f(w0), mi.UInt32(0), rng, mi.Bool(active))
        labels = ("acc", "gathered", "beta", "w", "depth", "rng", "active")
        # max_iterations=-1: the replay is a sum of per-vertex terms (Dr.Jit's fast path
        # for reverse-mode differentiation of such loops)
        return dr.while_loop(state, cond, body, labels=labels,
                             max_iterations=-1 if replay else None)[0]

    def transmitted(self, ctx_mode, si, wo, seed, active, top_i=None):
        """The walk's estimate of the base part of ``f cos θ_o`` (outer ``si.wi``, ``wo``),
        or its closed form (:attr:`form`);
        ``top_i``: the stack's response at ``si.wi`` where the caller has it."""
        mi = mitsuba_module()
        wi_in, ok_i = inward(si.wi, self.eta_f)
        wo_in, ok_o = inward(wo, self.eta_f)
        active = active & ok_i & ok_o
        if top_i is None:
            top_i = self.top(si, si.wi.z, active, inside=False, transmission=True)
        top_o = self.top(si, wo.z, active, inside=False, transmission=True)
        if self.form is not None:
            acc = self.form.sum(ctx_mode, si, wo_in, seed, active)
        else:
            acc = self.walk(ctx_mode, si, wi_in, wo_in, seed, active)
        if self.delta is not None:
            # the light entering along -wo' may make delta round trips (base, underside)
            # before its last non-delta vertex: D at w̄ = (-wo'_x, -wo'_y, wo'_z)
            d = self.delta.round_trips(ctx_mode, si, mi.Vector3f(-wo_in.x, -wo_in.y, wo_in.z),
                                       self.delta.rng(seed), active)
            acc = acc * d
        # light enters along -wo, is refracted along -wo', ..., leaves the base along wi'
        # and the coat along wi (Mueller products right to left)
        leave = self.crossing(top_i.T, top_i.transmission, wi_in, si.wi)
        enter = self.crossing(top_o.T, top_o.transmission, -wo, -wo_in)
        value = leave * acc * enter * (self.inv_eta2 * wo.z / dr.maximum(wo_in.z, 1e-12))
        if self.mode.polarized and ctx_mode != mi.TransportMode.Radiance:
            # importance transport: the chain's intensity for unpolarised light, depolarized
            value = mi.depolarizer(mi.UnpolarizedSpectrum(value[0][0]))
        for a in (self.attenuation(si, wi_in.z, active), self.attenuation(si, wo_in.z, active)):
            if a is not None:
                value = value * a
        return dr.select(active, value, dr.zeros(mi.Spectrum))

    def prob_reflect(self, ctx_mode, si, top_i, active):
        """``P_R``: the spectral mean of the delta lobe against that of ``R + T``, the delta
        lobe's mean estimated as ``R̄ + T̄ b̄`` with ``b̄`` the mean of the base's delta
        reflectance at ``ω_i'`` sampled with fixed numbers (0 for a base without delta
        lobes): a deterministic function of the directions, the same in ``sample`` and
        ``pdf``; detached (a sampling decision divides the weight as a constant)."""
        mi = mitsuba_module()
        pr = spectral_mean(mi.UnpolarizedSpectrum(top_i.R))
        pt = spectral_mean(mi.UnpolarizedSpectrum(top_i.T))
        delta = pr
        if self.delta is not None:
            wi_in, ok = inward(si.wi, self.eta_f)
            delta = pr + pt * self.delta.mean(ctx_mode, si, wi_in, active & ok)
        total = pr + pt
        return dr.detach(dr.select(total > 0, delta / dr.select(total > 0, total, 1.0), 1.0))

    def base_pdf(self, ctx_mode, si, wo, active):
        """The non-delta density at ``wo`` without the factor ``1 - P_R``."""
        ctx = self.smooth_context(ctx_mode)
        wi_in, ok_i = inward(si.wi, self.eta_f)
        wo_in, ok_o = inward(wo, self.eta_f)
        ok = active & ok_i & ok_o & (wo.z > 0)
        p_b = self.base.pdf(ctx, base_interaction(si, wi_in), wo_in, ok)
        jac = self.inv_eta2 * wo.z / dr.maximum(wo_in.z, 1e-12)
        p = (1.0 - self.mix) * p_b * jac + self.mix * wo.z * dr.inv_pi
        return dr.select(ok, p, 0.0)

    def eval_seed(self, wi, wo):
        """A hash of the two directions (pbrt-v4's ``LayeredBxDF`` seeds ``f()`` so)."""
        mi = mitsuba_module()
        a = mi.sample_tea_32(_bits(wi.x) ^ _shl(_bits(wi.z), 7), _bits(wi.y), 4)
        b = mi.sample_tea_32(_bits(wo.x) ^ _shl(_bits(wo.z), 7), _bits(wo.y) ^ a[1], 4)
        return a[0] ^ b[1], b[0]

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
        top_i = self.top(si, si.wi.z, active, inside=False, transmission=True)
        if has_delta and has_base:
            p_r = self.prob_reflect(ctx.mode, si, top_i, active)
        else:
            p_r = mi.Float(1.0 if has_delta else 0.0)
        sel_r = active & (sample1 < p_r)
        sel_b = active & (sample1 >= p_r)
        bs.eta = 1.0
        weight = mi.Spectrum(0.0)
        wo = mi.reflect(si.wi)
        seed = (_bits(sample1) ^ _shl(_bits(sample2.y), 16), _bits(sample2.x))
        seed = mi.sample_tea_32(seed[0], seed[1], 4)
        if has_delta:
            inv_p = dr.rcp(dr.select(p_r > 0, p_r, 1.0))
            delta = self.mode.value(top_i.R * inv_p, top_i.reflection, ctx, si.wi, wo)
            if self.delta is not None:
                wi_in, ok = inward(si.wi, self.eta_f)
                delta = delta + self.delta.chain(ctx.mode, si, top_i, wi_in,
                                                 self.delta.rng(seed), sel_r & ok) * inv_p
            weight = dr.select(sel_r, delta, weight)
        if has_base:
            s = (sample1 - p_r) / dr.select(p_r < 1, 1.0 - p_r, 1.0)
            cosine = sel_b & (s < self.mix)
            s_b = (s - self.mix) / dr.select(self.mix < 1, 1.0 - self.mix, 1.0)
            wi_in, _ = inward(si.wi, self.eta_f)
            ctx_b = self.smooth_context(ctx.mode)
            bs_b, _ = self.base.sample(ctx_b, base_interaction(si, wi_in), dr.clip(s_b, 0.0, 1.0),
                                       sample2, sel_b & _not(cosine))
            out, leaves = outward(bs_b.wo, self.eta_f)
            wo_b = dr.select(cosine, mi.warp.square_to_cosine_hemisphere(sample2), out)
            ok = sel_b & (cosine | (leaves & (bs_b.wo.z > 0) & (bs_b.pdf > 0)))
            wo = dr.select(sel_b, wo_b, wo)
            pdf = (1.0 - p_r) * self.base_pdf(ctx.mode, si, wo, ok)
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
        return self.smooth_context(mode) if has_base \
            else base_context(mode, mi.BSDFFlags.DeltaReflection)

    def _sample_invisible(self, ctx, si, sample1, sample2, active, has_delta, has_base):
        """The nested BSDF's own sample (times the coat's absorption) where the top is
        invisible (no films between equal indices); its delta samples are component 0."""
        mi = mitsuba_module()
        ctx_b = self._invisible_context(ctx.mode, has_delta, has_base)
        bs, w = self.base.sample(ctx_b, si, sample1, sample2, active)
        ok = active & (bs.wo.z > 0)
        bs.sampled_component = dr.select(mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta),
                                         mi.UInt32(0), mi.UInt32(1))
        bs.sampled_type = bs.sampled_type & mi.UInt32(+mi.BSDFFlags.Reflection)
        a = self.attenuation(si, si.wi.z, active)
        if a is not None:
            w = w * a * self.attenuation(si, bs.wo.z, active)
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
                value, pdf = self.base.eval_pdf(ctx_b, si_b, wo, active)
            elif want_value:
                value = self.base.eval(ctx_b, si_b, wo, active)
            else:
                pdf = self.base.pdf(ctx_b, si_b, wo, active)
            a = self.attenuation(si, si.wi.z, active)
            if a is not None and want_value:
                value = value * a * self.attenuation(si, wo.z, active)
            return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)
        top_i = self.top(si, si.wi.z, active, inside=False, transmission=True) \
            if want_value or (want_pdf and has_delta) else None
        if want_value:
            value = self.transmitted(ctx.mode, si, wo, self.eval_seed(si.wi, wo), active, top_i)
        if want_pdf:
            pdf = self.base_pdf(ctx.mode, si, wo, active)
            if has_delta:
                pdf = pdf * (1.0 - self.prob_reflect(ctx.mode, si, top_i, active))
        return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)
