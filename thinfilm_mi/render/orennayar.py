"""The Oren–Nayar base of the coated-diffuse model (``thinfilm_diffuse``'s ``roughness``
and ``roughness_model``; no plugin classes here).

Two base BRDFs of albedo ``ρ`` (``reflectance``) and roughness ``σ`` (radians, the
standard deviation of the facet slope angles; :data:`MAX_ROUGHNESS` at most), with
``A = 1 - 0.5 σ²/(σ² + 0.33)``, ``B = 0.45 σ²/(σ² + 0.09)``, ``μ = cos θ`` and
``s = sin θ_i sin θ_o cos(φ_o - φ_i)`` (``wi.x wo.x + wi.y wo.y``, no trigonometry):

* ``"qualitative"`` (:class:`Qualitative`): the seed's formula (Oren and Nayar 1994, their qualitative model),
  ``f = ρ/π (A + B max(0, cos φ) sin α tan β)``, written as
  ``ρ/π (A + B max(0, s)/max(μ_i, μ_o))`` (``sin α tan β = sin θ_i sin θ_o / cos β``).
  Its directional albedo is ``E(μ) = ρ (A + B h(μ))`` with
  ``π h(μ) = S (θ - S μ) + (2/3) S μ (1 + S + S²)/(1 + S)``, ``S = sin θ``
  (:func:`qualitative_h`; the second term is ``(2/3) tan θ (1 - S³)`` without its
  ``0·∞`` at grazing), and its hemispherical albedo ``Ē = ρ (A + B H)``,
  ``H = 2∫h μ dμ = 2/3 - 64/(45π)`` (:data:`H_AVG`).
* ``"eon"`` (:class:`EON`): the energy-preserving Oren–Nayar model (Portsmouth, Kutz and Hill,
  "EON: A practical energy-preserving rough diffuse BRDF", JCGT 14(1), 2025; OpenPBR's
  ``base_diffuse_roughness``): Fujii's single-scattering lobe
  ``f_ss = ρ/π A_F (1 + r s/t)`` (``s/t = s/max(μ_i, μ_o)`` for ``s > 0``, ``s``
  otherwise; ``A_F = 1/(1 + c_1 r)``, ``c_1 = 1/2 - 2/(3π)``) plus the analytic
  multiple-scattering lobe ``f_ms = ρ_ms/π (1 - E_F(μ_i))(1 - E_F(μ_o))/(1 - Ē_F)``
  with ``E_F(μ) = A_F (1 + r (h(μ) - 2S/(3π)))``, ``Ē_F = A_F (1 + c_2 r)``,
  ``c_2 = 2/3 - 28/(15π)``, ``ρ_ms = ρ² Ē_F/(1 - ρ (1 - Ē_F))``. A white base
  reflects everything at every angle. Its roughness ``r`` (OpenPBR's, in [0, 1]) is
  taken from ``σ`` as ``r = B/A``, the ratio that makes its lobe for ``cos φ > 0`` the
  qualitative model's: ``r`` grows from 0 to 0.777 at ``σ = π/2`` (OpenPBR's ``r``
  above that is out of reach).

:data:`ROUGHNESS_MODELS` holds one object per value of ``roughness_model``
(:func:`roughness_model` looks one up); :class:`OrenNayar` reads and validates the
parameters and gives, per hit, the base's :class:`BaseTerms`, which the coated-diffuse
model (:mod:`thinfilm_mi.render.layered.series`) puts under the films (the model is
written in the plugin's doc block).
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import NamedTuple

import drjit as dr

from thinfilm_mi.errors import ThinFilmError, plugin_boundary
from thinfilm_mi.optics.choices import choose
from thinfilm_mi.render.params import MAX_ROUGHNESS
from thinfilm_mi.render.reader import PluginProperties
from thinfilm_mi.render.textures import mitsuba_module, texture_range, uniform

__all__ = ["ROUGHNESS_MODELS", "RoughnessModel", "Qualitative", "EON", "roughness_model", "MAX_ROUGHNESS",
           "H_AVG", "C1_FON", "C2_FON", "BaseTerms", "OrenNayar", "coefficients", "qualitative_h"]

#: ``2∫h(μ) μ dμ``: the hemispherical mean of the qualitative model's ``B`` term.
H_AVG = 2.0 / 3.0 - 64.0 / (45.0 * math.pi)
#: The EON paper's constants.
C1_FON = 0.5 - 2.0 / (3.0 * math.pi)
C2_FON = 2.0 / 3.0 - 28.0 / (15.0 * math.pi)


class BaseTerms(NamedTuple):
    """The base at one hit, per wavelength or channel: ``pi_f = π f_b(ω_i, ω_o)``,
    ``e_i``, ``e_o``: its directional albedos ``E(μ_i)``, ``E(μ_o)``, and ``e_avg``:
    its hemispherical albedo ``Ē = 2∫E μ dμ`` (all include ``ρ``)."""
    pi_f: object
    e_i: object
    e_o: object
    e_avg: object

    def channel(self, c: int) -> BaseTerms:
        """The terms of colour channel ``c``."""
        return BaseTerms(*(x[c] for x in self))


def coefficients(sigma):
    """The qualitative model's ``A`` and ``B`` at ``σ`` (radians)."""
    s2 = sigma * sigma
    return 1.0 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)


def _sin(mu):
    return dr.safe_sqrt((1.0 - mu) * (1.0 + mu))


def qualitative_h(mu):
    """``h(μ)``: the directional albedo of the qualitative model's ``B`` term
    (``(1/π) ∫ max(0, cos φ) sin α tan β μ_o dω_o``), 0 at normal incidence, 1/2 at
    grazing."""
    S = _sin(mu)
    return (S * (dr.acos(dr.clip(mu, -1.0, 1.0)) - S * mu)
            + (2.0 / 3.0) * S * mu * (1.0 + S + S * S) / (1.0 + S)) * dr.inv_pi


def _fon_albedo(mu, r, a_f):
    """``E_F(μ)``: the directional albedo of Fujii's lobe at a white base."""
    return a_f * (1.0 + r * (qualitative_h(mu) - (2.0 / (3.0 * math.pi)) * _sin(mu)))


class RoughnessModel(ABC):
    """One value of ``roughness_model``: the base BRDF at roughness ``σ`` (its
    qualitative coefficients ``a``, ``b``, :func:`coefficients`)."""
    #: the value of ``roughness_model`` that names it
    name = ""

    @abstractmethod
    def terms(self, kd, a, b, mu_i, mu_o, s, t) -> BaseTerms:
        """:class:`BaseTerms` of albedo ``kd`` for ``μ_i``, ``μ_o``, ``s = sin θ_i sin θ_o
        cos(φ_o - φ_i)`` and ``t = max(μ_i, μ_o)`` (module docstring)."""


class Qualitative(RoughnessModel):
    """Oren and Nayar's qualitative model (module docstring)."""
    name = "qualitative"

    def terms(self, kd, a, b, mu_i, mu_o, s, t) -> BaseTerms:
        pi_f = kd * (a + b * dr.maximum(s, 0.0) / t)
        return BaseTerms(pi_f, kd * (a + b * qualitative_h(mu_i)),
                         kd * (a + b * qualitative_h(mu_o)), kd * (a + b * H_AVG))


class EON(RoughnessModel):
    """The energy-preserving Oren–Nayar model, with ``r = B/A`` (module docstring)."""
    name = "eon"

    def terms(self, kd, a, b, mu_i, mu_o, s, t) -> BaseTerms:
        r = b / a
        a_f = dr.rcp(1.0 + C1_FON * r)
        e_fi, e_fo = _fon_albedo(mu_i, r, a_f), _fon_albedo(mu_o, r, a_f)
        e_favg = a_f * (1.0 + C2_FON * r)
        rho_ms = kd * kd * e_favg / (1.0 - kd * (1.0 - e_favg))
        ms = (dr.maximum(1.0 - e_fi, 0.0) * dr.maximum(1.0 - e_fo, 0.0)
              / dr.maximum(1.0 - e_favg, 1e-20))
        pi_f = kd * a_f * (1.0 + r * dr.select(s > 0, s / t, s)) + rho_ms * ms
        return BaseTerms(pi_f, kd * e_fi + rho_ms * (1.0 - e_fi), kd * e_fo + rho_ms * (1.0 - e_fo),
                         kd * e_favg + rho_ms * (1.0 - e_favg))


#: The base models by their ``roughness_model`` value; the first is the default.
ROUGHNESS_MODELS = {m.name: m for m in (Qualitative(), EON())}


def roughness_model(value) -> RoughnessModel:
    """The :data:`ROUGHNESS_MODELS` entry named ``value`` (:func:`~thinfilm_mi.optics.choices.choose`:
    case-insensitive); a ``ThinFilmError`` naming ``roughness_model``, the value and the
    choices otherwise."""
    return choose(ROUGHNESS_MODELS, value, "'roughness_model'")


class OrenNayar:
    """``roughness`` (a texture, radians) and ``roughness_model`` of a ``thinfilm_diffuse``,
    read from a :class:`~thinfilm_mi.render.reader.PluginProperties` (or the plugin's bare
    ``mi.Properties``: then read in the boundary of ``plugin``).

    :attr:`rough` says whether the kernel needs the rough base: ``False`` while the
    roughness is 0 everywhere and carries no gradients, so that the plugin then runs
    its Lambertian code unchanged (bit-identical results). :meth:`refresh` recomputes
    it after an edit."""

    def __init__(self, read, plugin: str = "thinfilm_diffuse"):
        #: the plugin, named in the error of a render that :meth:`check_lambertian` refuses
        self.plugin = plugin
        with plugin_boundary(plugin):   # for a caller that passes the bare mi.Properties
            if not isinstance(read, PluginProperties):
                read = PluginProperties(read)
            #: the :class:`RoughnessModel`
            self.model = read.choice("roughness_model", ROUGHNESS_MODELS)
            self.texture = uniform(0.0) if "roughness" not in read else read.texture(
                "roughness", f"a number in [0, {MAX_ROUGHNESS:.6g}] (radians) or a texture",
                "'roughness' (σ, radians)", 0.0, MAX_ROUGHNESS, mono=True, uniform_number=True)
        self.rough = False
        self.refresh()

    def _carries_gradients(self) -> bool:
        mi = mitsuba_module()
        if not dr.is_diff_v(mi.Float):
            return False
        params = mi.traverse(self.texture)
        return any(dr.is_diff_v(params[k]) and dr.grad_enabled(params[k]) for k in params.keys())

    def refresh(self) -> bool:
        """Recompute :attr:`rough` from the texture's values and AD state; whether it changed."""
        rng = texture_range(self.texture, mono=True)
        rough = rng is None or rng[1] != 0.0 or self._carries_gradients()
        changed, self.rough = rough != self.rough, rough
        return changed

    def check_lambertian(self) -> None:
        """Refuse a render that differentiates a zero roughness whose gradients were
        enabled without ``params.update()`` (the kernel would take the Lambertian code)."""
        if not self.rough and self._carries_gradients():
            raise ThinFilmError(f"{self.plugin}: 'roughness' carries gradients, but the BSDF was not "
                                "updated: call params.update() after enabling gradients")

    def traverse(self, callback) -> None:
        callback.put("roughness", self.texture, mitsuba_module().ParamFlags.Differentiable)

    def describe(self) -> str:
        return f"  roughness = {self.texture},\n  roughness_model = {self.model.name},\n"

    def terms(self, si, kd, wo, active) -> BaseTerms:
        """:class:`BaseTerms` at ``si`` for light towards ``wo`` (local frame, upper
        hemisphere) and base albedo ``kd``."""
        wi = si.wi
        mu_i, mu_o = wi.z, wo.z
        sigma = self.texture.eval_1(si, active)
        a, b = coefficients(sigma)
        s = wi.x * wo.x + wi.y * wo.y
        t = dr.maximum(dr.maximum(mu_i, mu_o), 1e-20)
        return self.model.terms(kd, a, b, mu_i, mu_o, s, t)
