r"""
.. _bsdf-thinfilm_diffuse:

Thin-film coated diffuse surface (:monosp:`thinfilm_diffuse`)
-------------------------------------------------------------

.. shared-rows: diffuse
.. pluginparameters::

 * - reflectance
   - |spectrum| or |texture|
   - Albedo ``k_d`` of the diffuse base, in [0, 1] (default: 0.5).
 * - layers
   - |string|
   - The film stack from the outside in, ``"MATERIAL THICKNESS_NM; ..."``, e.g.
     ``"SiO2 500; Au 2"``. The innermost film is normally the paper's absorbing
     film (a thin metal or semiconductor). Default: ``""`` (no films: exactly
     Mitsuba's ``diffuse``; with model ``"exact"`` and a ``base_ior`` unlike
     ``ext_ior``, the bare interface over the base, as Mitsuba's ``plastic`` with
     ``nonlinear=true``).
 * - thin_film_ior, thin_film_thickness
   - |string| or |float|, |float|
   - Shorthand for one film (index or material name, thickness in nm). Not
     together with ``layers``.
 * - ext_ior
   - |float| or |string|
   - Exterior index, real (default: 1.000277, air).
 * - model
   - |string|
   - ``"exact"`` (default; see **Which model**): the whole stack, coherent, over a
     base medium; ``"single"``: the paper's first-order model as published (Hirayama
     et al., sec. 2.4, eq. 8-10; its figures); ``"multiple"``: the paper's model plus
     the interreflection between the base and the coating.
 * - base_ior
   - |float| or |string|
   - Model ``"exact"`` only: the real index of the medium between the films and
     the base (default: ``ext_ior``).
 * - thickness
   - |float| or |texture|
   - Optional scale on every film's thickness at the hit, e.g. a ``bitmap`` with
     ``raw="true"`` (clamped to >= 0; default: 1). ``R_dh``, ``T_hemi`` (RGB/mono: the
     integrated diffuse term) are tabulated over its range, read at load.
 * - roughness
   - |float| or |texture|
   - Oren–Nayar roughness ``σ`` of the base (radians, the standard deviation of the
     facet slope angles), in [0, π/2] (default: 0, Lambert). |differentiable|.
 * - roughness_model
   - |string|
   - ``"qualitative"`` (default): Oren and Nayar's qualitative formula;
     ``"eon"``: energy-preserving (OpenPBR's). See **Rough base**.
 * - tabulate
   - |string| or |bool|
   - ``auto`` (default), ``true`` or ``false``: whether ``R`` (and ``T``) is read from a
     verified table over (angle, wavelength), whose cost does not grow with the films,
     instead of the recursion. ``auto`` tabulates a coating from 5 films (films that do
     not absorb, whose table holds ``R`` alone, from 1) in vectorised variants, without
     a ``thickness`` texture or gradients, where a table within budget meets
     ``table_error``; ``true`` tabulates every stack it can, with 10x the build budget.
     When and why: :ref:`the tables guide <tabulate-policy>`.
 * - table_error
   - |float|
   - Target max abs error of a table in ``R`` and ``T`` (default: 0.001).
 * - spectral_resolution
   - |float|
   - Spectral resolution (nm) tables may assume where no table resolves the exact values
     (deep stacks on a metal): ``R`` and ``T`` are then tabulated convolved with a
     Gaussian in wavenumber of this standard deviation at 560 nm, if that keeps the
     colour (default: 1; 0: exact values only). Under lasers or line spectra narrower
     than this pass 0; see :ref:`the tables guide <tabulate-policy>`.
 * - coherence_thickness
   - |float|
   - Films thicker than this (nm) are averaged incoherently, as tmm's ``inc_tmm`` does,
     instead of showing ~1 nm fringes no broadband light shows (default: 5000).

A diffuse base (Lambertian, or Oren–Nayar with ``roughness``) under a stack of thin
films, after Hirayama et al. section 2.4 (the layered engine's smooth top over a diffuse
bottom and its ``model`` registry: ``thinfilm_mi/render/layered/models.py``). Component 0 is the delta reflection of the
coating, component 1 the diffuse lobe; the films are evaluated at the path's wavelengths
in the render kernel (float32), for unpolarised light. In ``*_spectral_polarized``
variants component 0 is the Mueller matrix of the coating's amplitudes (exact or
tabulated, see ``tabulate``; rotated as Mitsuba's ``conductor`` does) and component 1
is Mitsuba's ``depolarizer`` of the value below, as ``diffuse``.

**The two parts of the stack.** With films ``1..N`` (outside in) and an
*absorbing* innermost film ``N`` (``k > 0`` somewhere in 360-830 nm), the
stack is split as in the paper's table step: the *coating* is films
``1..N-1`` with film ``N`` as its (semi-infinite) exit medium, and film ``N``
only attenuates. Then, for an angle ``θ`` measured in the ambient medium,

* ``k_r(θ)``, ``k_t(θ)``: reflectance and transmittance (power entering film
  ``N``, appendix A-21) of the coating over film ``N`` (eq. 5-6);
* ``k_a(θ)``: the attenuation through film ``N`` along the refracted direction
  (appendix A-18, ``exp(-4π Im(q_N) d_N / λ)`` with ``q_N = n̂_N cos θ_N``, the
  same tangential wave vector ``n_0 sin θ``; see ``optics.film_attenuation``
  for the A-7 sign typo);
* ``t(θ) = k_t(θ) k_a(θ)``: the power fraction of light arriving at ``θ`` that
  reaches the base (eq. 10).

If the innermost film does not absorb (or there are no films), there is no film ``N``:
the coating is the whole stack, its exit medium is the base medium (index ``ext_ior``,
see below), ``k_a = 1``, and ``k_r``, ``t = k_t`` are the exact composite reflectance
and transmittance of all films. With no films ``k_r = 0`` and ``t = 1``, and every model
*is* Mitsuba's ``diffuse``, bit for bit (the kernel does no stack work there), except
model ``"exact"`` over a ``base_ior`` unlike ``ext_ior``: no films there is still the
interface between the two media, the limit of a film of vanishing thickness (its albedo
is ``plastic``'s with ``nonlinear=true``, up to that plugin's fitted ``F_dr``).

**model = "single"** (eq. 8-10). With ``ω_i`` the viewing direction (the
paper's ``θ_i``) and ``ω_o`` the light direction (``θ_l``)::

    specular (component 0):  k_r(θ_i)                                 (eq. 8, I_r term)
    diffuse  (component 1):  f = k_t(θ_i) k_a(θ_i) · k_d/π · k_a(θ_l) k_t(θ_l)
                             (eval returns f cos θ_l)                  (eq. 8-10)

Eq. 10 gives the light reaching the base, ``L' = k_a k_t(θ_l) L``; eq. 9 lets
the base reflect ``k_d L' cos θ_l'`` and crosses film ``N`` again (second
``k_a``, taken along the viewing direction's refracted path: ``k_a(θ_i)``);
eq. 8 multiplies by ``k_t(θ_i)`` for the exit. The paper writes ``k_t`` and
``k_r`` as functions of the viewing angle ``θ_i``; the exit factor
``k_t(θ_i) k_a(θ_i)`` is the transmission of light *leaving* towards the
viewer, equal by reciprocity to that of light arriving from the viewer. Since
``k_t`` is a ratio of normal fluxes (A-19), ``L' cos θ_l'`` in eq. 9 is read as
the irradiance on the base, ``k_a k_t(θ_l) L cos θ_l`` per unit solid angle of
the light: the cosine is that of the light direction outside, which is what
Mitsuba multiplies by. The ``1/π`` is the Lambert normalisation of ``k_d``
(the paper's ``k_d`` is an albedo, as in ``diffuse``). **No** ``(n_N/n_0)^2``
radiance scaling is applied: the paper applies none (eq. 10), the index of an
absorbing film ``N`` defines no radiance invariant, and the base is treated as
radiating into a medium matched to the ambient (index ``ext_ior``), for which
the factor is exactly 1 — which is also what makes the film-free case equal to
``diffuse``. The resulting ``f`` is symmetric in ``ω_i, ω_o`` (reciprocal).

**model = "multiple"** keeps the same ``k_r`` and ``t`` and adds the
light that the coating reflects back onto the base, summed as a geometric
series as Mitsuba's ``plastic`` does for a bare interface::

    f = t(θ_i) t(θ_l) · k_d / (π (1 - k_d R_dh))

``R_dh = 2 ∫ R_up(μ) μ dμ`` is the coating's hemispherical reflectance seen
from the base (``μ = cos θ`` in the ambient parametrisation of the internal
directions, which is exact for the base medium ``ext_ior``). Without film
``N``, ``R_up`` is the exact reflectance of the reversed stack lit from the
base medium; with film ``N``, ``R_up = k_a^2 k_r`` (down and up through film
``N``, the coating reflecting alike from both sides: exact for a lossless
coating, and ``R_up + t <= k_r + k_t <= 1`` in any case). ``R_dh`` is computed
per wavelength at load time (and when a film is edited) with the float64 core over a
Gauss-Legendre rule and stored as a ``regular`` spectrum (and in the model's table, see
below); in AD variants its derivatives
too (see **Gradients**). The internal light is Lambertian (the base re-diffuses all it
receives), so the exit factor is the same ``t(θ)`` and the radiance scaling ``1/η^2`` of
``plastic`` is 1 (matched base medium). The albedo for light from ``θ_i`` is
``k_r + t(θ_i) k_d T_hemi/(1 - k_d R_dh)`` with ``T_hemi = 2∫ t μ dμ``: for a
lossless stack ``T_hemi = 1 - R_dh`` and a white base gives exactly 1; for any
stack it is at most ``k_r + t <= 1``. ``"single"`` is the first term of the
series, hence never brighter than ``"multiple"``.

**Rough base** (``roughness`` ``σ > 0``; ``thinfilm_mi/render/orennayar.py``). The base
BRDF ``f_b`` is Oren–Nayar's: ``"qualitative"``, with ``μ = cos θ``,
``A = 1 - 0.5σ²/(σ²+0.33)``, ``B = 0.45σ²/(σ²+0.09)``, ``α = max(θ_i, θ_o)``,
``β = min(θ_i, θ_o)``::

    f_b = k_d/π · (A + B · max(0, cos(φ_o - φ_i)) · sin α · tan β)

or ``"eon"`` (Portsmouth, Kutz, Hill 2025), Fujii's lobe plus an analytic
multiple-scattering lobe, with OpenPBR's roughness ``r = B/A`` (0.78 at ``σ = π/2``).
``E(μ) = ∫ f_b μ_o dω_o`` is its directional albedo and ``Ē = 2∫E μ dμ`` its
hemispherical one, both in closed form (qualitative: ``k_d (A + B h(μ))``, ``Ē = k_d (A +
B (2/3 - 64/(45π)))``; EON: ``k_d`` for ``k_d = 1``). The base medium is matched to the
ambient, so the directions at the base are the outside ones (the ambient
parametrisation used above) and light crosses the films as for a Lambertian base::

    f = t(θ_i) t(θ_o) · [f_b(ω_i, ω_o) + E(μ_i) E(μ_o) R_dh / (π (1 - Ē R_dh))]

The first term crossed the coating once each way; the second is the series of the
light the coating sends back. Its assumption (exact for Lambert, where it
is ``"multiple"`` above) is that the light leaving the base after its first bounce is
reflected by the coating as if it were cosine-distributed (``R_dh``) and that all light
sent back reaches the base as diffuse light, which the base re-emits with the exitance
profile ``E(μ_o)/π`` (by reciprocity, its reflection of uniform light) and re-reflects
with ``Ē``. ``"single"`` keeps the first term. ``f`` is symmetric in ``ω_i, ω_o``
(reciprocal). Energy (``benchmarks/orennayar_energy.py``): the qualitative formula loses
light (a white base at ``σ = π/2`` reflects 0.56 at normal incidence, 0.65 on average) and
gains up to 0.8 % towards grazing for ``σ < 0.33``; EON reflects all of it. Under lossless
films the second term's cosine assumption leaves a white EON base's albedo within
[0.987, 1.011] (most at ``σ = π/2`` and normal incidence, where the base's lobe favours
the normal and escapes more than ``R_dh`` assumes); under the absorbing films measured
it stays below 1. Sampling is cosine-weighted (weight ``π f``). RGB/mono variants combine
the terms of the colour table of a textured ``reflectance`` (its expansion in ``R_dh``)
with ``f_b``, ``E``, ``Ē`` per channel; polarized ones depolarize, as for Lambert. While
``roughness`` is 0 everywhere without gradients the Lambertian code runs.

**model = "exact"** (default). Every film, absorbing or not, is part of one coherent stack
between the ambient and a base medium of index ``n_b`` (``base_ior``); the base
is Lambertian in that medium. Specular part: the stack's exact ``R(θ_i)``.
Diffuse part: ``f = t(θ_i) t(θ_o) k_d / (π (1 - k_d R_dh))`` with ``t = T n_0/n_b``
(``T``: the exact transmittance into the base medium; the two factors ``n_0/n_b``
are ``plastic``'s radiance factor ``1/η²``) and ``R_dh = 2∫R_up μ dμ`` over the
base medium's directions (``R_up``: the reversed stack lit from the base; total
reflection beyond its critical angle, frustrated by absorbing films). Assumes
a smooth, parallel stack, incoherent light in the base and a base that re-diffuses
all it receives. The albedo ``R + t k_d T_hemi/(1 - k_d R_dh)`` (``T_hemi = 2∫T_up μ
dμ``) is at most 1 (``R + T <= 1`` for the same stack), 1 for a lossless stack on a
white base; ``f`` is symmetric. Where film ``N`` is a few nm of metal the paper's
models treat it as bulk: for ``SiO2 300; Au 4`` their diffuse term is 20-500x darker.
**Which model** (``benchmarks/diffuse_models.py``): under ``SiO2 300; Au 4`` a white base's
diffuse albedo at normal incidence is 0.61-0.90 over 450-680 nm ("exact", = tmm's), 0.22-0.0015
("single"); the Fig. 9/10 scenes differ by 13-27 % per pixel (3-10x the noise). Hence the
default; the Fig. 9/10 scenes name ``"single"``, their figures' model.

**Specular part.** The paper's models use the paper's ``k_r`` (coating over film
``N``; the exact full-stack reflectance when there is no absorbing film ``N``).
The exact reflectance of *all* films over the base medium is not used with an
absorbing film ``N``: paired with the first-order ``t`` it can exceed energy
conservation (e.g. 50 nm Si, where the thin-film reflectance in the red is far
above that of bulk Si while ``k_t`` is that of bulk Si).

**Sampling.** Component 0 is chosen with probability proportional to the
spectral mean of ``k_r(θ_i)``, component 1 proportional to that of its albedo
estimate ``t(θ_i) k_d T_hemi [/(1 - k_d R_dh)]``; the diffuse direction is
cosine-weighted and its pdf is multiplied by the selection probability, as in
``plastic``. When the context enables one component only, the other one's
stack work is skipped. Thicknesses (``layers.N.thickness``) are opaque and
exposed to ``mi.traverse``; ``R_dh`` and ``T_hemi`` are recomputed when they change.
The selection probability is a detached sampling decision (the weight's gradient
is that of ``k_r``, resp. the diffuse term), so ``T_hemi`` needs no derivatives.

**The model's table** (spectral vectorised variants, ``tabulate`` ``auto`` or ``true``).
The kernel reads ``k_r`` and ``t`` at every angle and wavelength, with ``R_dh`` and
``T_hemi``, from one table of the model instead of the stack's recursion or tables:
bilinear over (``sqrt(cos θ)``, wavelength), verified within ``table_error`` as the
stack's tables are (outside the grazing sliver; a finer wavelength step towards grazing
incidence where a cavity of the films needs it; ``thinfilm_mi/tabulate/factors.py``). One
read at ``θ_i`` serves ``eval_pdf`` and ``sample`` (Mitsuba calls them back to back), one
read of ``t`` each ``θ_o``. Where no such table fits in 2^21 floats (e.g. a free-standing
"SiO2 500" in model ``"exact"``, or films of ~5 µm) the stack is read as ``tabulate``
says; where a film parameter carries gradients, or under a ``thickness`` texture, every
film is evaluated exactly. Polarized variants read ``k_r`` and ``t`` from it, and the
shape of the delta lobe's Mueller matrix (its entries over ``M00``) from the stack.

**RGB and mono variants** (``*_rgb``, ``*_mono``; polarized ones are refused).
``k_r`` is the spectral reflectance integrated against colour matching (CIE 1931 2°
under D65 to linear sRGB, a perfect reflector (1, 1, 1); the luminance Y in mono),
as the other plugins do, so RGB and spectral renders agree. The diffuse term is the
spectral *product* integrated: ``π f_c = ∫ ŵ_c(λ) t(λ, θ_i) t(λ, θ_o) G(k_d,c,
R_dh(λ)) dλ`` with ``G = k_d`` ("single") or ``k_d / (1 - k_d R_dh)`` ("multiple"),
not a product of integrated factors (the fringes of ``t(θ_i)`` and ``t(θ_o)`` line
up at some angles and cancel at others), tabulated over both angles at scene load
(``thinfilm_mi/tabulate/diffuse.py``). ``reflectance`` is a colour and enters per
channel, as in Mitsuba's ``diffuse``: a constant one is integrated exactly with the
series; a texture through a Chebyshev expansion of ``G`` in ``R_dh`` (relative error
<= 1e-5). Thickness and index gradients in ``llvm_ad_rgb`` are those of an unbiased
estimate of the same integrals at stratified wavelengths per hit (the value stays
the table's), ``R_dh`` with its derivatives at those wavelengths as below. The
gradient with respect to a constant ``reflectance`` treats the series as constant
(exact for "single") unless a film parameter carries gradients too (then it is the
estimate's); through a texture it is exact. Under a ``thickness`` texture varying over
the surface the table is 3-D, over ``(θ_i, θ_o, s)``, ``s`` in the texture's range, cubic
over nodes uniform in ``sqrt(s)``, within 3e-3 of ``π f`` at their midpoints (at most 128
MiB, else refused; ``tabulate/diffuse.py``); the texture's gradient is the table's.

**Gradients.** Film thicknesses and indices (``layers.N.thickness``,
``layers.N.eta``/``k``): in spectral variants exact, per wavelength, for both
models. ``k_r`` and ``t`` are differentiated in the kernel (every film evaluated
exactly, not from a table, where a parameter carries gradients); ``R_dh``
("multiple") takes its derivatives from a table of ``∂R_dh/∂x`` over 360-830 nm
(1 nm, linear like ``R_dh``) for every film's thickness, ``Re n`` and ``Im n``,
computed by reverse-mode AD through the same float64 quadrature when a film
parameter carries gradients: at the ``params.update()`` that enables them and at each
later edit of the films (~0.06 s for 3 films, ~0.2 s for 30), never at scene load. A
render differentiating a film parameter whose gradients were enabled without
``params.update()`` is refused with that advice, never silently biased. The kernel adds
``Σ ∂R_dh/∂x (x - detach(x))`` to ``R_dh`` (the chain rule through any index texture:
``R_dh(λ)`` depends on the indices at ``λ`` only). At ``k = 0`` the derivative with respect to ``k`` is the
one-sided one (loss). Differentiate with ``path`` (the whole sample is
differentiated, both components). Mitsuba's ``prb`` family samples detached and
re-evaluates ``eval`` at the sampled direction for the derivative; ``eval`` holds
only the diffuse part, so for paths that took the delta specular component ``prb``
uses the diffuse term's derivative where ``k_r``'s belongs (a thickness gradient of
+5.4e-4 where ``path`` and a finite difference give -1.5e-4, in
``tests/plugins/test_thinfilm_diffuse.py``'s scene), as it does for Mitsuba's own
``plastic``. A BSDF cannot tell ``prb`` from ``path`` (both trace ``sample`` with
gradients suspended in their primal pass and ``eval`` with gradients later), so
there is no run-time warning.

.. tabs::
    .. code-tab:: xml

        <bsdf type="thinfilm_diffuse">
            <rgb name="reflectance" value="0.8, 0.1, 0.1"/>
            <string name="layers" value="SiO2 500; Au 2"/>
        </bsdf>

    .. code-tab:: python

        {'type': 'thinfilm_diffuse', 'layers': 'SiO2 500; Au 2',
         'reflectance': {'type': 'rgb', 'value': [0.8, 0.1, 0.1]}}
"""
from __future__ import annotations

import mitsuba as mi

from thinfilm_mi.errors import ThinFilmError, plugin_boundary
from thinfilm_mi.render import modes
from thinfilm_mi.render.layered.bottom import DiffuseBottom, albedo
from thinfilm_mi.render.layered.engine import layered
from thinfilm_mi.render.layered.models import DIFFUSE_MODELS
from thinfilm_mi.render.layered.series import series_parts
from thinfilm_mi.render.media import DEFAULT_EXT_IOR
from thinfilm_mi.render.orennayar import OrenNayar
from thinfilm_mi.render.params import ParameterGuard
from thinfilm_mi.render.reader import PluginProperties
from thinfilm_mi.render.variant import check_variant

__all__ = ["ThinFilmDiffuse", "NAME"]

NAME = "thinfilm_diffuse"


class ThinFilmDiffuse(mi.BSDF):
    """The ``thinfilm_diffuse`` plugin: its properties read into a
    :class:`~thinfilm_mi.render.layered.engine.Layered` (:attr:`layered`): a smooth top over
    a diffuse bottom, summed by the model's closed form, which does the work."""

    def __init__(self, props):
        with plugin_boundary(NAME):
            check_variant(NAME)
            read = PluginProperties(props)
            model = read.choice("model", DIFFUSE_MODELS)
            ext = read.index("ext_ior", DEFAULT_EXT_IOR)
            if "base_ior" in read and not model.takes_base_ior:
                names = " or ".join(repr(m) for m, o in DIFFUSE_MODELS.items() if o.takes_base_ior)
                raise ThinFilmError(f"'base_ior' is a parameter of model {names} only "
                                    f"(model is {model.name!r})")
            base = read.index("base_ior", None) if "base_ior" in read else ext
            spec = read.stack_spec(base, ext)   # the films over the diffuse base's medium
            reflectance = albedo(read)
            rough = OrenNayar(read, NAME)   # roughness: render/orennayar.py
            read.check_unqueried()
            mode = modes.current()
            top, film_n, own = series_parts(model, spec.films, spec.ambient, spec.substrate,
                                            dict(spec.options, plugin=NAME), mode)
            #: the layered engine (render/layered/): the films over the diffuse base
            self.layered = layered(top, DiffuseBottom(reflectance, rough), film_n, mode, NAME,
                                   **own)
        # registered once complete: from here on every thread's symbolic calls trace it
        mi.BSDF.__init__(self, props)
        self.m_components = self.layered.components()
        self.m_flags = self.m_components[0] | self.m_components[1]
        self.guard = ParameterGuard(self, NAME)

    # the model's parts, for inspection
    coated = property(lambda self: self.layered.estimator,
                      doc="The estimator (:class:`~thinfilm_mi.render.layered.series.SeriesEstimator`).")
    model = property(lambda self: self.coated.model, doc="The :class:`DiffuseModel`.")
    coating = property(lambda self: self.coated.coating, doc="The top's ``KernelStack``.")
    film_n = property(lambda self: self.coated.film_n, doc="The paper's absorbing film N, or ``None``.")
    base = property(lambda self: self.layered.bottom.roughness, doc="The base's ``OrenNayar`` roughness.")
    terms = property(lambda self: self.coated.terms, doc="Spectral variants: ``R_dh``, ``T_hemi``.")
    colour = property(lambda self: self.coated.colour, doc="RGB/mono variants: the diffuse table.")
    r_dh_grad = property(lambda self: self.coated.r_dh_grad, doc="``R_dh``'s derivative table or ``None``.")

    def sample(self, ctx, si, sample1, sample2, active=True):
        return self.layered.sample(ctx, si, sample1, sample2, active)

    def eval(self, ctx, si, wo, active=True):
        return self.layered.eval(ctx, si, wo, active)

    def pdf(self, ctx, si, wo, active=True):
        return self.layered.pdf(ctx, si, wo, active)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.layered.eval_pdf(ctx, si, wo, active)

    def traverse(self, callback):
        self.layered.traverse(callback)

    def parameters_changed(self, keys):
        self.guard.changed(self, self.layered.parameters_changed, keys)

    def to_string(self):
        return f"ThinFilmDiffuse[\n{self.coated.describe()}]"
