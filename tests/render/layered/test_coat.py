"""thinfilm_mi.render.layered.coat: Beer–Lambert in the coat medium, exactly, and its
values refused where they are not finite and >= 0."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import coating, interaction  # noqa: E402
from thinfilm_mi.errors import ThinFilmError  # noqa: E402
from thinfilm_mi.render.layered.coat import CoatMedium  # noqa: E402


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


def test_absorbing_coat_is_beer_lambert():
    """``coat_sigma_a`` over ``coat_thickness``: with one bounce the factor is
    ``exp(-σ d (1/μ_i' + 1/μ_o'))`` on the inner cosines, exactly."""
    clear, murky = coating(max_bounces=1), coating(max_bounces=1, coat_sigma_a=0.3,
                                                   coat_thickness=0.5)
    wo = mi.Vector3f(-0.6, 0.0, 0.8)
    ratio = (np.array(murky.eval(mi.BSDFContext(), interaction(0.5), wo), np.float64)
             / np.array(clear.eval(mi.BSDFContext(), interaction(0.5), wo), np.float64))
    mu_i, mu_o = np.sqrt(1 - 0.75 / 2.25), np.sqrt(1 - 0.36 / 2.25)
    np.testing.assert_allclose(ratio, np.exp(-0.15 * (1 / mu_i + 1 / mu_o)), rtol=1e-5)


def test_attenuation_of_one_crossing():
    """``exp(-σ d / μ)`` along one crossing; ``None`` for a clear coat."""
    si = interaction(1.0)
    medium = CoatMedium(mi.load_dict({"type": "uniform", "value": 0.4}), 2.0, "p")
    a = np.array(medium.attenuation(si, mi.Float(0.5), True), np.float64)
    np.testing.assert_allclose(a, np.exp(-0.4 * 2.0 / 0.5), rtol=1e-6)
    assert CoatMedium(None, 1.0, "p").attenuation(si, mi.Float(0.5), True) is None


@pytest.mark.parametrize("thickness, sigma, match", [
    (-1.0, None, "'coat_thickness' must be a finite number >= 0, got -1.0"),
    (float("inf"), None, "'coat_thickness' must be a finite number >= 0, got inf"),
    (1.0, -0.5, "'coat_sigma_a' .* must be finite and >= 0, got -0.5"),
])
def test_bad_values_are_refused_naming_them(thickness, sigma, match):
    tex = None if sigma is None else mi.load_dict({"type": "uniform", "value": sigma})
    with pytest.raises(ThinFilmError, match="p: " + match):
        CoatMedium(tex, thickness, "p")
