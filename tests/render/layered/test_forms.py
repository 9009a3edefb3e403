"""thinfilm_mi.render.layered.forms: the closed form over a Lambertian base is the walk's
expectation, and ``thinfilm_diffuse``'s model ``"exact"`` (the same series over a film
stack, an independent implementation: its own factors and quadrature). Monte Carlo
tolerances are 4 standard errors of the mean (``tests/support/layered.py``).
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import (  # noqa: E402
    LOSSLESS,
    STACKS,
    albedo,
    coating,
    diffuse_albedo_quadrature,
    interaction,
)


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


@pytest.mark.parametrize("layers", ["", LOSSLESS], ids=["bare", "lossless"])
def test_lambertian_closed_form_is_the_walks_expectation(layers):
    """Over ``diffuse`` the base part is the closed form ``ρ/π cos θ_o' / (1 - ρ R_dh)``
    (``thinfilm_mi/render/layered/forms.py``); a blend of two ``diffuse`` (the same
    Lambertian, unknown to the registry) is walked. Over 2^14 random direction pairs at
    cos θ_i 0.7 the walk minus the closed form has mean 0 within 4σ of its spread, and the
    closed form returns the same value for other random numbers (no noise)."""
    base = {"type": "diffuse", "reflectance": 0.5}
    closed = coating(layers=layers, bsdf=base)
    walked = coating(layers=layers, bsdf={"type": "blendbsdf", "weight": 0.5,
                                          "bsdf_0": base, "bsdf_1": base})
    assert closed.coating.form is not None and walked.coating.form is None
    n = 1 << 14
    rng = np.random.default_rng(5)
    mu, phi = rng.uniform(0.02, 1, n), rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - mu ** 2)
    wo = mi.Vector3f(mi.Float(s * np.cos(phi)), mi.Float(s * np.sin(phi)), mi.Float(mu))
    si = interaction(0.7, n)
    a = np.array(closed.eval(mi.BSDFContext(), si, wo), np.float64)
    d = np.array(walked.eval(mi.BSDFContext(), si, wo), np.float64) - a
    assert np.all(np.abs(d.mean(axis=1)) <= 4 * d.std(axis=1) / np.sqrt(n)), d.mean(axis=1)
    seeds = [(mi.UInt32(np.arange(n, dtype=np.uint32) + k), mi.UInt32(np.full(n, 7 * k + 1, np.uint32)))
             for k in (1, 2)]
    runs = [np.array(b.coating.transmitted(mi.TransportMode.Radiance, si, wo, seed, mi.Bool(True)),
                     np.float64) for b in (closed, walked) for seed in seeds]
    np.testing.assert_array_equal(runs[0], runs[1])   # other random numbers, the same value
    assert np.any(runs[2] != runs[3])                 # (the walk's change)


@pytest.mark.parametrize("layers", list(STACKS.values()), ids=list(STACKS))
def test_films_over_diffuse_are_thinfilm_diffuse_exact(layers):
    """Check 3: films over ``diffuse`` equal ``thinfilm_diffuse`` ``model="exact"`` with
    ``base_ior`` = ``int_ior`` (its series in closed form, deterministic: its delta ``R``
    plus the quadrature of its ``eval``), at cos θ 1, 0.5 and 0.17. Bare (no films over
    a base medium unlike the ambient: an interface), lossless and absorbing stacks."""
    ours_bsdf = coating(layers=layers)
    ref = mi.load_dict({"type": "thinfilm_diffuse", "model": "exact", "base_ior": 1.5,
                        "ext_ior": 1.0, "layers": layers, "reflectance": 0.5})
    ctx = mi.BSDFContext()
    ctx.component = 0
    for cos in (1.0, 0.5, 0.17):
        ours, tol = albedo(ours_bsdf, cos)
        _, spec = ref.sample(ctx, interaction(cos), 0.5, mi.Point2f(0.5, 0.5))
        want = np.array(spec, np.float64)[:, 0] + diffuse_albedo_quadrature(ref, cos, 256)
        # 4σ of ours + the stacks' float32 evaluation (1e-5) and the reference's R_dh
        # quadrature (its Gauss-Legendre rule: 1e-6)
        np.testing.assert_allclose(ours, want, atol=tol.max() + 2e-5)
