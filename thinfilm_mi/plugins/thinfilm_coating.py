r"""
.. _bsdf-thinfilm_coating:

Thin-film coating over any BSDF (:monosp:`thinfilm_coating`)
------------------------------------------------------------

.. shared-rows: dielectric

.. pluginparameters::

 * - bsdf
   - BSDF (nested)
   - The base: any Mitsuba BSDF, ours included (``diffuse``, ``roughconductor``,
     ``principled``, ``measured``, ``roughplastic``, a smooth ``conductor``,
     ``dielectric``, ``plastic``, ``thinfilm_diffuse``...), nested by this name or as the
     one unnamed child. It is evaluated in the coat medium: give it ``int_ior`` as its own
     ``ext_ior`` where it has one. |differentiable| (its own parameters).
 * - layers
   - |string|
   - The film stack from the outside in, ``"MATERIAL THICKNESS_NM; ..."`` (default:
     ``""``, no films: a bare interface between ``ext_ior`` and ``int_ior``).
 * - thin_film_ior, thin_film_thickness
   - |string| or |float|, |float|
   - Shorthand for one film (index or material name, thickness in nm). Not together
     with ``layers``.
 * - int_ior
   - |float| or |string|
   - The coat medium between the films and the base: a real index or a non-absorbing
     material name (default: 1.5).
 * - ext_ior
   - |float| or |string|
   - Exterior index, real (default: 1.000277, air).
 * - coat_sigma_a
   - |spectrum| or |texture|
   - Absorption coefficient of the coat medium per unit of ``coat_thickness``, >= 0
     (default: none, a clear coat). Beer–Lambert along every refracted crossing,
     ``exp(-σ_a d / cos θ')``, as Mitsuba 0.6's ``coating``. |differentiable|.
 * - coat_thickness
   - |float|
   - Thickness ``d`` of the coat medium in the unit of ``coat_sigma_a``, >= 0
     (default: 1). |differentiable|.
 * - alpha, alpha_u, alpha_v
   - |float| or |texture|
   - Roughness of the top interface, isotropic (``alpha``) or along the tangent and
     bitangent (``alpha_u`` and ``alpha_v``), as in Mitsuba's ``roughdielectric``
     (default: 0, a smooth top). The films then lie on its microfacets, as in
     ``thinfilm_roughdielectric``. A rough top needs ``int_ior`` to differ from
     ``ext_ior``; textures must be > 0. |differentiable|.
 * - distribution
   - |string|
   - The rough top's microfacet distribution: ``beckmann`` (default) or ``ggx``.
 * - sample_visible
   - |bool|
   - Sample the rough top's visible normals, as Mitsuba (default: true).
 * - max_bounces
   - |int|
   - Most base vertices of a path, >= 1 (default: 64), in the walk and in the closed
     form alike. Longer paths are dropped: for a Lambertian base of albedo ``ρ`` under an
     underside of hemispherical reflectance ``R̄`` their energy is at most ``(ρ R̄)^N/(1 -
     ρ R̄)`` (1e-14 for white under a bare 1.5 coat).
 * - thickness
   - |float| or |texture|
   - Optional scale on every film's thickness at the hit, e.g. a ``bitmap`` with
     ``raw="true"`` (clamped to >= 0; default: 1). In spectral variants the stack is
     then evaluated exactly (no table); RGB and mono variants tabulate the colour over
     its range, read at load.
 * - tabulate
   - |string| or |bool|
   - ``auto`` (default), ``true`` or ``false``: whether ``R`` (and ``T``) is read from a
     verified table over (angle, wavelength), whose cost does not grow with the films,
     instead of the recursion. ``auto`` tabulates stacks of absorbing films from 4
     films, of other films from 1 (4 between media of constant index) in vectorised
     variants, without a ``thickness`` texture or gradients, where a table within budget
     meets ``table_error``; ``true`` tabulates every stack it can, with 10x the build
     budget. When and why: :ref:`the tables guide <tabulate-policy>`.
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

A smooth thin-film stack between ``ext_ior`` and a clear (or absorbing) coat medium of
index ``int_ior``, over any nested BSDF: an interference clear coat over a ``principled``
paint, a dichroic film over a printed ``diffuse`` label, an AR-coated cover glass, an
oxide over a ``roughconductor`` under a lacquer, a lacquered smooth metal. Component 0 is
the delta reflection: the stack's exact ``R(θ_i)`` (from a table or the recursion as the
other plugins), plus, over a base with a delta reflection, the light that bounces between
it and the stack's underside by delta reflections only, ``T² B_δ/(1 - R_in B_δ)`` (summed
in closed form). Component 1 (absent over a pure-delta base such as ``conductor`` or
``dielectric``: the coating is then a pure delta BSDF) is the light that crosses the
stack, scatters at the base and bounces between the base and the stack's underside (whose
reflectance ``R_in`` includes total internal reflection) before it leaves::

    f = T(θ_i) T(θ_o) (η_e/η_c)² A(θ_i') A(θ_o') [f_b(ω_i', ω_o') + interreflections]

with ``ω'`` the directions refracted into the coat (Snell's law at the mean indices),
``A`` Beer–Lambert and ``(η_e/η_c)²`` the radiance factor of Mitsuba's ``plastic``. The
interreflections are estimated, unbiased for any base, by a position-free random walk
(Guo et al. 2018, pbrt-v4's ``LayeredBxDF``): next-event estimation through the smooth
top at every base vertex, the first vertex's next term also reached from a sample of the
base at the exit direction (the two combined by the power heuristic), the base sampled
between vertices (a sample that would leave through the top is kept half the time and
otherwise turned back into the coat, weighted by that mixture's density, so that trapped
light loses weight at every bounce), Russian roulette after 3 vertices of walks whose
throughput fell below 0.1, at most ``max_bounces`` vertices. ``eval`` seeds its random numbers from a
hash of the directions and ``sample`` from its sample, so both are deterministic. Over
Mitsuba's ``diffuse`` without ``coat_sigma_a``, in spectral and polarized variants, the
walk is replaced by its closed form, ``ρ/π cos θ_o' / (1 - ρ R_dh)`` with the underside's
hemispherical reflectance ``R_dh`` (``thinfilm_diffuse``'s model ``"exact"``): no walk
noise (``thinfilm_mi/render/layered/forms.py``). ``sample`` picks the delta lobe with
a probability from the stack's mean ``R̄``, ``T̄`` and a probe of the base at ``ω_i'`` (its
mean delta reflectance and albedo, from two samples with fixed numbers); otherwise it
draws from a mixture of the base's own non-delta lobes refracted out (those beyond the
critical angle folded back into the escape cone) and a cosine lobe whose share the probe
sets per direction, and weighs the direction by the walk's ``f cos θ_o`` over the
mixture's density, which is what ``pdf``
returns (so ``sample``, ``eval`` and ``pdf`` agree, and MIS weights sum to one). With no
films and ``int_ior`` equal to ``ext_ior`` the plugin returns the nested BSDF itself
(times the coat's absorption). Details: the layered engine, ``thinfilm_mi/render/layered/``
(``nested.py``, ``walk.py``), and the guide ``docs/guides/coating.md``.

**Variants.** Spectral: the stack exact (or tabulated) at the path's wavelengths, the
base in Mitsuba's spectral mode. RGB and mono: the stack's ``R`` and ``T`` integrated
against colour matching per channel (as ``thinfilm_dielectric``), times the base's RGB
per channel: a product of integrals where the physical value is the integral of the
product (``tests/plugins/test_thinfilm_coating.py`` measures the ΔE2000 against the
spectral value: 0.96 for two films over an orange ``diffuse``). Polarized
(``*_spectral_polarized``): the stack's Mueller matrices at every crossing and
reflection (exact amplitudes or their tables, as ``thinfilm_dielectric``) times the
base's, each in Mitsuba's implicit Stokes bases of the directions the light travels, so
the products chain (radiance transport; light tracing gets the chain's intensity,
depolarized). AD: film thicknesses and indices, ``coat_sigma_a`` and
``coat_thickness`` carry gradients (in polarized variants only where no walk runs: over
a pure-delta base and the closed form over ``diffuse``); the nested BSDF's own
parameters keep theirs (they appear under ``bsdf.`` in ``mi.traverse``).

**A rough top** (``alpha`` > 0): component 0 is the top's glossy reflection
(``thinfilm_roughdielectric``'s, exactly); component 1 the light that crosses the top,
estimated by the walk of pbrt-v4's ``LayeredBxDF``: the top's transmission is sampled from
both directions, and at every base vertex two next-event estimates through the rough top
(the light side's sampled direction, the base's own sample) are combined by the power
heuristic; the underside's reflection is sampled between vertices. ``sample`` draws from
a fixed mixture of the top's reflection lobe, the base's lobes refracted out and a cosine
lobe, whose density is what ``pdf`` returns. A delta base under a rough top is glossy.
Details: ``thinfilm_mi/render/layered/rough.py``.

**Bases with delta lobes.** A path's last non-delta base vertex is connected to the exit
direction through the base's ``eval``; the delta round trips after it (light entering,
reflected by the base's delta lobe and the underside, again and again) are summed in closed
form at the exit direction, ``(1 - R_in B_δ)^-1`` (a Mueller inverse in polarized variants).
Exact for bases whose delta reflection is a deterministic function of the directions (every
Mitsuba BSDF with one, ours included); a base that picks its delta lobe at random (a
``blendbsdf`` of a delta and another BSDF) is biased by at most 1e-4 relative in the tested
case (``thinfilm_mi/render/layered/delta.py``). **Not covered.** Light the base transmits (a
``dielectric``'s refraction) is lost (no layer below it).

.. tabs::
    .. code-tab:: xml

        <bsdf type="thinfilm_coating">
            <string name="layers" value="TiO2 120"/>
            <float name="int_ior" value="1.5"/>
            <bsdf type="principled">
                <rgb name="base_color" value="0.6, 0.05, 0.05"/>
                <float name="roughness" value="0.4"/>
            </bsdf>
        </bsdf>

    .. code-tab:: python

        {'type': 'thinfilm_coating', 'layers': 'TiO2 120', 'int_ior': 1.5,
         'bsdf': {'type': 'principled', 'base_color': {'type': 'rgb', 'value': [0.6, 0.05, 0.05]},
                  'roughness': 0.4}}
"""
from __future__ import annotations

import mitsuba as mi

from thinfilm_mi.errors import ThinFilmError, plugin_boundary
from thinfilm_mi.render import modes
from thinfilm_mi.render.kernel import build_stack
from thinfilm_mi.render.layered.bottom import NestedBottom
from thinfilm_mi.render.layered.coat import CoatMedium
from thinfilm_mi.render.layered.engine import layered
from thinfilm_mi.render.layered.top import RoughTop, SmoothTop
from thinfilm_mi.render.layered.walk import DEFAULT_MAX_BOUNCES
from thinfilm_mi.render.media import DEFAULT_EXT_IOR
from thinfilm_mi.render.microfacet import DISTRIBUTIONS, Microfacet
from thinfilm_mi.render.params import MAX_ALPHA, ParameterGuard
from thinfilm_mi.render.reader import PluginProperties, finite_number
from thinfilm_mi.render.variant import check_variant

__all__ = ["NAME", "ThinFilmCoating"]

NAME = "thinfilm_coating"
#: the coat medium's default index (the issue's; a clear lacquer)
DEFAULT_COAT_IOR = 1.5


def coat_roughness(read, interior, ambient):
    """The top's roughness: a :class:`~thinfilm_mi.render.microfacet.Microfacet` read from
    ``read``, or ``None`` for a smooth top, where no roughness is given or every one is a
    number equal to 0. A rough top needs a refraction (the ``interior`` and ``ambient``
    media's mean indices differ), as ``thinfilm_roughdielectric``."""
    names = [n for n in ("alpha", "alpha_u", "alpha_v") if n in read]
    values = [read.value(n) for n in names]
    numbers = [finite_number(f"'{n}'", v, 0.0, MAX_ALPHA, also=" or a texture")
               for n, v in zip(names, values)
               if isinstance(v, (int, float)) and not isinstance(v, bool)]
    if len(numbers) == len(names) and not any(numbers):
        read.choice("distribution", DISTRIBUTIONS)
        read.boolean("sample_visible", True)
        return None
    microfacet = Microfacet(read)
    if interior.mean_real() == ambient.mean_real():
        raise ThinFilmError(f"a rough top ({', '.join(f'{n}={v!r}' for n, v in zip(names, values))}) "
                            f"needs 'int_ior' ({interior.label}) and 'ext_ior' "
                            f"({ambient.label}) to differ: a rough interface without "
                            "refraction is undefined")
    return microfacet


def coat_top(stack, mode, microfacet):
    """The top: ``stack`` on the microfacets ``microfacet`` (a
    :class:`~thinfilm_mi.render.layered.top.RoughTop`), or the smooth
    :class:`~thinfilm_mi.render.layered.top.SmoothTop` where it is ``None``
    (:func:`coat_roughness`)."""
    return SmoothTop(stack, mode) if microfacet is None else RoughTop(stack, mode, microfacet)


class ThinFilmCoating(mi.BSDF):
    """The ``thinfilm_coating`` plugin: its properties read into a
    :class:`~thinfilm_mi.render.layered.engine.Layered` (:attr:`layered`): a smooth or rough
    top over the nested BSDF, which does the work."""

    def __init__(self, props):
        with plugin_boundary(NAME):
            check_variant(NAME)
            mode = modes.current()
            read = PluginProperties(props)
            base = read.nested_bsdf()
            interior, ambient = read.indices(("int_ior", DEFAULT_COAT_IOR), ("ext_ior", DEFAULT_EXT_IOR))
            spec = read.stack_spec(interior, ambient)
            microfacet = coat_roughness(read, interior, ambient)
            sigma_a = read.factor("coat_sigma_a")
            thickness = read.number("coat_thickness", 1.0, 0.0)
            bounces = read.integer("max_bounces", DEFAULT_MAX_BOUNCES, 1)
            read.check_unqueried()
            stack = build_stack(spec, sides={False: True, True: False}, plugin=NAME)
            top = coat_top(stack, mode, microfacet)
            #: the layered engine (render/layered/): the top over the nested BSDF
            self.layered = layered(top, NestedBottom(base), CoatMedium(sigma_a, thickness, NAME),
                                   mode, NAME, max_bounces=bounces)
        # smooth top: component 0 the stack's reflection and the base's all-delta chains,
        # component 1 absent over a pure-delta base (a pure delta BSDF); rough top:
        # component 0 the top's glossy reflection, component 1 the light that crosses it
        components = self.layered.components()
        flags = mi.BSDFFlags.Empty
        for component in components:
            flags = flags | component
        # registered once complete: from here on every thread's symbolic calls trace it
        mi.BSDF.__init__(self, props)
        # (m_components is a copy when read back: assigned whole)
        self.m_components, self.m_flags = components, flags
        self.guard = ParameterGuard(self, NAME)

    coating = property(lambda self: self.layered.estimator,
                       doc="The estimator (:class:`~thinfilm_mi.render.layered.nested.NestedEstimator`, "
                           "or :class:`~thinfilm_mi.render.layered.rough.RoughEstimator` under a rough top).")

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
        return f"ThinFilmCoating[\n{self.coating.describe()}]"
