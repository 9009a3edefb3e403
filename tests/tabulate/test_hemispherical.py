"""The float64 hemispherical terms (thinfilm_mi/tabulate/hemispherical.py): the loop over
films of deep coatings equals the unrolled recursion, and ``r_dh_partials`` (the
derivative table) against central differences of ``hemispherical_factors`` in float64,
shallow and deep (the film loop) stacks; the table over the thickness scale against the
terms computed directly at scales between its nodes."""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi  # noqa: E402,F401  (registers the plugins)
from tests.support.bsdf import WAVELENGTHS as WL
from tests.support.bsdf import direction, make_si
from thinfilm_mi.render.media import SpectralIndex  # noqa: E402
from thinfilm_mi.tabulate.hemispherical import hemispherical_factors, r_dh_partials  # noqa: E402

# ---------------------------------------------------------------------------
# The derivative table against differences of the float64 hemispherical factors
# ---------------------------------------------------------------------------
PARTIAL_WLS = np.array([380.0, 450.0, 555.5, 700.0, 829.0])


def _partials_case(coating, film_n):
    n0 = np.full(PARTIAL_WLS.size, 1.000277)
    coat = [(np.full(PARTIAL_WLS.size, complex(n)), d) for n, d in coating]
    fn = None if film_n is None else (np.full(PARTIAL_WLS.size, complex(film_n[0])),
                                      film_n[1])
    n_exit = n0 + 0j if fn is None else fn[0]
    return n0, coat, n_exit, fn


@pytest.mark.parametrize("coating,film_n", [
    ([(2.3, 90.0), (1.46, 150.0), (2.3, 60.0)], None),
    ([(2.3, 90.0), (1.46 + 0.01j, 150.0)], (0.4 + 2.4j, 6.0)),
    ([(2.3 if i % 2 else 1.46, 40.0 + 7 * i) for i in range(9)], None),     # the film loop
], ids=["lossless", "absorbing", "nine_films"])


def test_r_dh_partials_match_float64_differences(coating, film_n, monkeypatch):
    """The rows of ``r_dh_partials`` (thickness, Re n, Im n of every film, then film
    N; of the first, middle and last film of a deep stack) against float64
    differences of ``hemispherical_factors``' ``R_dh``; blocks of two wavelengths
    (the blocking of deep stacks) change nothing."""
    from thinfilm_mi.tabulate import hemispherical
    n0, coat, n_exit, fn = _partials_case(coating, film_n)
    P = r_dh_partials(n0, coat, n_exit, fn, wavelengths=PARTIAL_WLS)
    films = list(coat) + ([fn] if fn is not None else [])
    checked = range(len(films)) if len(films) <= 4 else (0, len(films) // 2, len(films) - 1)
    for f in checked:
        for p, delta in enumerate([1e-3, 1e-6, 1e-6j]):
            def r_dh(sign):
                shifted = list(films)
                n, d = shifted[f]
                shifted[f] = (n, d + sign * delta) if p == 0 else (n + sign * delta, d)
                if fn is None:
                    return hemispherical_factors(n0, shifted, n_exit, None, PARTIAL_WLS)[1]
                return hemispherical_factors(n0, shifted[:-1], shifted[-1][0], shifted[-1],
                                             PARTIAL_WLS)[1]
            lossless = p == 2 and np.all(np.imag(films[f][0]) == 0)
            if lossless:     # k = 0: the one-sided (second-order) difference
                fd = (4 * r_dh(1) - r_dh(2) - 3 * r_dh(0)) / (2 * abs(delta))
            else:
                fd = (r_dh(1) - r_dh(-1)) / (2 * abs(delta))
            # float64 differences: truncation and rounding ~1e-8 of the scale (~1)
            np.testing.assert_allclose(P[3 * f + p], fd, rtol=1e-5, atol=1e-7,
                                       err_msg=f"film {f} parameter {p}")
    monkeypatch.setattr(hemispherical, "PARTIALS_LANE_FILMS", 2 * 128 * max(len(coat), 1))
    np.testing.assert_allclose(r_dh_partials(n0, coat, n_exit, fn, wavelengths=PARTIAL_WLS),
                               P, rtol=1e-12, atol=1e-14)



mi.set_variant("llvm_ad_spectral")
from thinfilm_mi.tabulate import hemispherical


def test_hemispherical_terms_of_a_deep_coating_loop_equal_the_unrolled_recursion(monkeypatch):
    """Deep coatings take the loop over films (thinfilm_diffuse loaded 200 films in
    37 s with the unrolled float64 kernel, 0.4 s with the loop); both give the same
    terms to float64 rounding."""
    wl = np.linspace(400.0, 700.0, 7)
    films = [(np.full(wl.size, 1.38 + 0.0j), 90.0), (np.full(wl.size, 2.3 + 0.01j), 60.0),
             (np.full(wl.size, 1.46 + 0j), 200.0), (np.full(wl.size, 0.4 + 2.5j), 8.0),
             (np.full(wl.size, 1.7 + 0j), 45.0)]
    args = (np.full(wl.size, 1.0), films, np.full(wl.size, 1.0 + 0j), None, wl, 32)
    looped = hemispherical.hemispherical_factors(*args)
    monkeypatch.setattr(hemispherical, "LOOP_MIN_FILMS", 10 ** 6)
    unrolled = hemispherical.hemispherical_factors(*args)
    for a, b in zip(looped, unrolled):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_scale_table_against_direct_terms():
    """The table over the scale (linear in s, within SCALE_ABS at the check) against
    the terms computed at scales between its nodes."""
    from thinfilm_mi.tabulate.hemispherical import SCALE_ABS
    b = mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300; Au 4", "model": "exact",
                      "thickness": {"type": "checkerboard", "color0": 0.2, "color1": 1.4}})
    table = b.terms.table
    assert table.s_max == pytest.approx(1.4, rel=1e-6)
    s = np.array([0.37, 0.91, 1.33])
    n = s.size
    si = make_si(n, direction(0.0))
    r, t, _ = table.lookup(si.wavelengths, mi.Float(s))
    from thinfilm_mi.render.layered.factors import ExactFactors
    R, T = ExactFactors(b.coating).hemispherical_scales(np.array(WL), s)
    np.testing.assert_allclose(np.array(r), R.T, atol=SCALE_ABS / 2 + 1e-6)
    np.testing.assert_allclose(np.array(t), T.T, atol=SCALE_ABS / 2 + 1e-6)


@pytest.mark.parametrize("films", [1, 24])
def test_paper_terms_over_scales_are_the_terms_of_scaled_films(films):
    """The paper's hemispherical terms over thickness scales (a texture's table) and at one
    scale (no texture) are one computation: at each scale they equal the one-scale terms of
    the films scaled, bit for bit (each thickness times a scale is the same float64
    product; 24 films run the loop over the films)."""
    from thinfilm_mi.materials.model import GRID
    from thinfilm_mi.tabulate.hemispherical import DEFAULT_NODES, hemispherical_factors, paper_terms
    wl = GRID[::23]

    def index(material):
        return SpectralIndex.from_material(material, "x").spectral_values(wl)
    coating = [(index("SiO2") if i % 2 else index("TiO2"), 90.0 + i) for i in range(films)]
    gold, n0, scales = index("Au"), np.full(wl.size, 1.0), [0.0, 0.35, 1.0, 1.5]
    R, T = paper_terms(n0, coating, gold, (gold, 4.0), wl, scales, DEFAULT_NODES)
    for k, s in enumerate(scales):
        t1, r1 = hemispherical_factors(n0, [(n, d * s) for n, d in coating], gold, (gold, 4.0 * s), wl)
        assert np.array_equal(R[k], r1) and np.array_equal(T[k], t1), s
    assert np.all(T[1:] > 0) and np.all(R[1:] > 0)


@pytest.mark.parametrize("thickness", [6000.0, 1e9, 1e30])
def test_incoherent_films_are_averaged_like_tmm_inc_tmm(thickness):
    """A film marked incoherent (as the kernel marks one beyond ``coherence_thickness``)
    enters the terms of model "exact" as tmm's ``inc_tmm`` averages it: the terms equal the
    same rule (:func:`base_rule`) summed over ``inc_tmm``'s ``R`` and ``T`` of the reversed
    stack lit from the base. Its phase never enters: 1e30 nm gives the terms of 6000 nm
    (computed coherently, they were up to 1e-2 off at these thicknesses, or NaN)."""
    import tmm

    from thinfilm_mi.tabulate.hemispherical import base_rule, exact_hemispherical
    wl = np.array([400.0, 560.0, 760.0])
    n_amb, n_base, metal = np.ones(wl.size), np.full(wl.size, 1.5), 0.4 + 2.5j
    # (a film of index above the base's: tmm's inc_tmm gives R < 0 where the light is
    # evanescent in an incoherent film, which ours sends back whole)
    films = [(np.full(wl.size, 1.6 + 0j), thickness), (np.full(wl.size, metal), 5.0)]
    R, T = exact_hemispherical(n_amb, films, n_base, wl, nodes=32, incoherent=[True, False])
    mu, weight = base_rule(n_amb, n_base, 32)
    ref = np.zeros((2, wl.size))
    for k, lam in enumerate(wl):
        for m, (c, w) in enumerate(zip(mu[k], weight[k])):
            out = [tmm.inc_tmm(p, [1.5, metal, 1.6, 1.0], [np.inf, 5.0, 6000.0, np.inf],
                               ["i", "c", "i", "i"], np.arccos(c), lam) for p in "sp"]
            ref[:, k] += w * 0.5 * np.array([out[0]["R"] + out[1]["R"], out[0]["T"] + out[1]["T"]])
    assert np.all(np.isfinite(R)) and np.all(np.isfinite(T))
    # float64 on both sides; tmm's 1e-30 floor on P and our clamps act at rounding level
    np.testing.assert_allclose(R[0], ref[0], rtol=0, atol=1e-10)
    np.testing.assert_allclose(T[0], ref[1], rtol=0, atol=1e-10)
