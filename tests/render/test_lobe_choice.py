"""The lobe choice of the thin-film dielectrics (thinfilm_mi/render/lobe_choice.py),
against the closed forms it implements: reflection drawn with probability ``mean R /
(mean R + mean T)``, and the chosen lobe's weight divided by its probability so that the
expected weight is ``R + T`` per wavelength."""
import mitsuba as mi
import numpy as np

from thinfilm_mi.render.lobe_choice import chosen_weight, reflection_probability


def _spectra():
    """Four lanes of R and T: generic, all transmitted, all reflected, black."""
    R = np.array([[0.1, 0.0, 0.5, 0.0], [0.3, 0.0, 0.7, 0.0],
                  [0.2, 0.0, 0.9, 0.0], [0.6, 0.0, 0.4, 0.0]])
    T = np.array([[0.8, 0.9, 0.0, 0.0], [0.5, 0.6, 0.0, 0.0],
                  [0.7, 0.8, 0.0, 0.0], [0.2, 0.3, 0.0, 0.0]])
    return R, T


def test_probability_and_weights_match_the_closed_forms(llvm):
    R, T = _spectra()
    Rm, Tm = mi.Spectrum(R), mi.Spectrum(T)
    p = np.array(reflection_probability(Rm, Tm))
    pr, pt = R.mean(axis=0), T.mean(axis=0)
    # float32 means and one division: a few ulps of numbers of order 1
    expected = np.array([pr[0] / (pr[0] + pt[0]), 0.0, 1.0, 1.0])
    assert np.allclose(p, expected, rtol=0, atol=1e-6)
    for chose_r in (True, False):
        w = np.array(chosen_weight(mi.Bool(chose_r), mi.Float(p), Rm, Tm))
        with np.errstate(divide="ignore", invalid="ignore"):
            ref = np.where(chose_r, R / np.where(p > 0, p, 1.0), T / np.where(p < 1, 1 - p, 1.0))
        assert np.allclose(w, ref, rtol=1e-6, atol=0)
    # the choice is unbiased: p w_R + (1 - p) w_T = R + T where both lobes can be drawn
    w_r = np.array(chosen_weight(mi.Bool(True), mi.Float(p), Rm, Tm))
    w_t = np.array(chosen_weight(mi.Bool(False), mi.Float(p), Rm, Tm))
    mix = p * w_r + (1 - p) * w_t
    assert np.allclose(mix[:, :3], (R + T)[:, :3], rtol=1e-6, atol=0)
    assert np.all(np.isfinite(w_r)) and np.all(np.isfinite(w_t))
