"""thinfilm_mi.render.layered.delta: the delta-base chain against ``tmm`` (the stacks' and a
conductor's Fresnel reflectances: ``R + T² ρ / (1 - R_in ρ)``), and the stated bias of a
base that picks its delta lobe at random.
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401
from tests.support.layered import STACKS, WLS, coating, interaction, tmm_rt  # noqa: E402


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")


@pytest.mark.parametrize("layers", list(STACKS.values()), ids=list(STACKS))
def test_smooth_conductor_base_is_the_closed_form(layers):
    """A smooth ``conductor`` (``eta`` 2, ``k`` 3, relative to the coat) under a coat: a
    pure delta BSDF whose weight is ``R + T² ρ / (1 - R_in ρ)`` (the stack's ``R`` and
    ``T`` from outside at θ, its ``R_in`` from the coat at θ', the conductor's ``ρ`` at
    θ': unpolarised, as the spectral variant composes them), every term from ``tmm`` in
    float64. No noise (the delta chain is summed in closed form); float32: 2e-5. The stack
    is evaluated exactly whatever ``auto`` would choose: this checks the composition, not a
    table's error (tests/tabulate)."""
    b = coating(layers=layers, bsdf={"type": "conductor", "eta": 2.0, "k": 3.0}, tabulate=False)
    assert b.component_count() == 1 and not b.flags() & mi.BSDFFlags.Smooth
    films = [f.split() for f in layers.split(";") if f.strip()]
    n = [1.0, *(complex(f[0]) for f in films), 1.5]
    d = [float(f[1]) for f in films]
    for cos in (1.0, 0.5, 0.17):
        bs, w = b.sample(mi.BSDFContext(), interaction(cos), 0.3, mi.Point2f(0.5, 0.5))
        np.testing.assert_allclose(np.array(bs.wo)[:, 0],
                                   [-np.sqrt(1 - cos * cos), 0.0, cos], atol=1e-6)
        cos_in = float(np.sqrt(1 - (1 - cos * cos) / 1.5 ** 2))
        want = []
        for wl in WLS:
            r, t = tmm_rt(n, d, cos, wl)
            r_in, _ = tmm_rt(n[::-1], d[::-1], cos_in, wl)
            rho, _ = tmm_rt([1.0, 2.0 + 3.0j], [], cos_in, wl)
            want.append(r + t * t * rho / (1 - r_in * rho))
        np.testing.assert_allclose(np.array(w, np.float64)[:, 0], want, atol=2e-5)


def test_a_randomly_picked_delta_lobe_has_the_stated_bias():
    """A base that picks its delta lobe at random (``blendbsdf`` of a ``conductor`` and a
    black ``diffuse``, weight 0.5: ``B_δ`` is ``ρ`` or 0): the round trips' estimate ``1 +
    M_1 (1 + M_2 (1 - M_3)^-1)`` (``TAIL_LEVELS`` = 2) has the expectation ``1 + m (1 + m
    E[(1 - M)^-1])``, ``m = U ρ/2``, where the truth is ``(1 - m)^-1``. Over 2^16 samples of
    the delta lobe its mean is that expectation within 4σ, and the bias it leaves,
    ``T² (ρ/2) m² (E[(1 - M)^-1] - (1 - m)^-1)``, is < 1e-4 at cos θ 1, 0.5 and 0.17 (one
    closed form of one sample, ``E[ρ/2 (1 - M)^-1]``, was 1-3 % off). ``tmm`` for every
    factor (unpolarised, as above)."""
    b = coating(bsdf={"type": "blendbsdf", "weight": 0.5,
                      "bsdf_0": {"type": "conductor", "eta": 2.0, "k": 3.0},
                      "bsdf_1": {"type": "diffuse", "reflectance": 0.0}})
    ctx = mi.BSDFContext()
    ctx.component = 0
    n = 1 << 16
    rng = np.random.default_rng(3)
    for cos in (1.0, 0.5, 0.17):
        _, w = b.sample(ctx, interaction(cos, n), mi.Float(rng.random(n, dtype=np.float32)),
                        mi.Point2f(rng.random(n, dtype=np.float32),
                                   rng.random(n, dtype=np.float32)))
        w = np.array(w, np.float64)[0]
        cos_in = float(np.sqrt(1 - (1 - cos * cos) / 1.5 ** 2))
        r, t = tmm_rt([1.0, 1.5], [], cos, WLS[0])
        u, _ = tmm_rt([1.5, 1.0], [], cos_in, WLS[0])
        rho, _ = tmm_rt([1.0, 2.0 + 3.0j], [], cos_in, WLS[0])
        m = u * rho / 2
        closed = 0.5 / (1 - u * rho) + 0.5          # E[(1 - M)^-1], M = U ρ or 0
        expected = r + t * t * rho / 2 * (1 + m * (1 + m * closed))
        exact = r + t * t * rho / 2 / (1 - m)
        assert abs(w.mean() - expected) <= 4 * w.std() / np.sqrt(n), (cos, w.mean(), expected)
        assert 0 < expected - exact < 1e-4 * exact, (cos, expected, exact)
