"""Documented limits and the errors at them: the number of films (every plugin works
at the limit and refuses one more), the numpy API naming its arguments, the float64
hemispherical terms of deep coatings (a loop, equal to the unrolled recursion), and
command lines that used to end in a traceback or an empty message."""
from __future__ import annotations

from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

mi.set_variant("llvm_ad_spectral")
import thinfilm_mi as tf  # noqa: E402
from thinfilm_mi.batch.scene import root_cause  # noqa: E402
from thinfilm_mi.cli import render as cli  # noqa: E402
from thinfilm_mi.cli.tools import main as module_main  # noqa: E402
from thinfilm_mi.errors import ThinFilmError  # noqa: E402
from thinfilm_mi.materials.stack import MAX_FILMS  # noqa: E402
from thinfilm_mi.tabulate import hemispherical

DEEP = "; ".join(f"{2.3 if i % 2 else 1.38} {60 + i % 7}" for i in range(MAX_FILMS))
PLUGINS = ["thinfilm_conductor", "thinfilm_dielectric", "thinfilm_diffuse",
           "thinfilm_roughconductor", "thinfilm_roughdielectric"]


@pytest.mark.parametrize("plugin", PLUGINS)
def test_every_plugin_works_at_the_film_limit_and_refuses_one_more(plugin):
    bsdf = mi.load_dict({"type": plugin, "layers": DEEP, "tabulate": False})
    si = dr.zeros(mi.SurfaceInteraction3f, 64)
    si.wavelengths = mi.Spectrum(450.0, 520.0, 610.0, 700.0)
    si.wi = mi.Vector3f(0.4, 0.0, float(np.sqrt(1 - 0.16)))
    rng = np.random.default_rng(3)
    _, w = bsdf.sample(mi.BSDFContext(), si, mi.Float(rng.random(64)),
                       mi.Point2f(rng.random((2, 64))))
    w = np.array(w)
    assert np.all(np.isfinite(w)) and np.all(w >= 0) and w.max() > 0
    with pytest.raises(Exception, match=f"{MAX_FILMS + 1} films given, at most {MAX_FILMS}"):
        mi.load_dict({"type": plugin, "layers": DEEP + "; 1.5 10", "tabulate": False})


def test_deep_stack_agrees_with_tmm_at_the_limit():
    """1000 films in float64 (the loop form) against tmm, which does not rescale."""
    import tmm
    d = [60.0 + i % 7 for i in range(MAX_FILMS)]
    n = [2.3 if i % 2 else 1.38 for i in range(MAX_FILMS)]
    st = tf.Stack(list(zip(n, d)), substrate=1.52)
    for wl, th in ((480.0, 0.0), (633.0, 0.6)):
        ref = 0.5 * sum(tmm.coh_tmm(p, [1.0] + n + [1.52], [np.inf] + d + [np.inf], th, wl)["R"]
                        for p in "sp")
        # float64 through 1000 films: ~1e-13 per film
        assert abs(float(st.rt(wl, th).R) - ref) < 1e-9


def test_numpy_stack_errors_name_the_argument():
    with pytest.raises(ThinFilmError, match=r"^layers\[2\] material: .*1e\+30"):
        tf.Stack([(1.5, 10), (1.4, 10), ("1e30", 5)])
    with pytest.raises(ThinFilmError, match=r"^substrate: unknown material 'Auu'"):
        tf.Stack(substrate="Auu")
    with pytest.raises(ThinFilmError, match=r"^ambient: .*nan"):
        tf.Stack(ambient=float("nan"))
    with pytest.raises(ThinFilmError, match=r"^layers: 1001 films given"):
        tf.Stack([(1.5, 1.0)] * (MAX_FILMS + 1))


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


def test_spectrum_with_too_many_wavelengths_is_one_clear_line(capsys):
    rc = module_main(["spectrum", "--layers", "1.46 100", "--wl", "360:830:1e-7"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "--wl" in err[0] and "4700000001 values" in err[0] and "at most" in err[0]


def test_render_with_a_huge_size_is_one_clear_line(capsys, tmp_path):
    scene = Path(__file__).resolve().parent.parent / "scenes" / "demo.xml"
    rc = cli.render_main([str(scene), "--size", "100000x100000", "--spp", "1",
                          "-o", str(tmp_path / "x.exr")])
    err = [l for l in capsys.readouterr().err.strip().splitlines() if "error" in l]
    assert rc == 2 and len(err) == 1
    assert "--size '100000x100000'" in err[0] and "at most" in err[0]


def test_render_failure_reports_the_root_cause():
    try:
        try:
            raise MemoryError("cannot allocate 40 GiB for the film")
        except MemoryError as inner:
            raise RuntimeError("error while performing a custom differentiable operation. "
                               "(see above).") from inner
    except RuntimeError as e:
        assert "40 GiB" in str(root_cause(e))
