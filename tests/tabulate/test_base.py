"""Table building blocks (thinfilm_mi/tabulate/base.py): ghost nodes, the B-spline
coefficients of the clamped system, and the byte-bounded table cache."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi as tf
from thinfilm_mi.render import media as media_mod
from thinfilm_mi.render import stack_build
from thinfilm_mi.tabulate import axes

pytestmark = pytest.mark.usefixtures("llvm")


def test_ghost_nodes():
    """Mirrored ends copy the nodes beyond the end node; extrapolated ends continue
    the cubic through the last four nodes exactly; given ends are kept in order."""
    from thinfilm_mi.tabulate import base as tabulate_base
    x = np.arange(10.0)
    f = x ** 3 - 2 * x
    out = tabulate_base.with_ghosts(f, axes.MIRROR, axes.EXTRAPOLATE)
    assert np.array_equal(out[:3], f[[3, 2, 1]])
    xr = np.arange(10.0, 13.0)
    assert np.allclose(out[-3:], xr ** 3 - 2 * xr, rtol=0, atol=1e-9)
    out = tabulate_base.with_ghosts(f, axes.EXTRAPOLATE, axes.MIRROR)
    xl = np.arange(-3.0, 0.0)
    assert np.allclose(out[:3], xl ** 3 - 2 * xl, rtol=0, atol=1e-9)
    assert np.array_equal(out[-3:], f[[8, 7, 6]])
    out = tabulate_base.with_ghosts(f, np.array([1.0, 2.0, 3.0]), np.array([7.0, 8.0, 9.0]))
    assert np.array_equal(out, np.concatenate([[1, 2, 3], f, [7, 8, 9]]))


@pytest.mark.parametrize("n", [2, 3, 16, 33, 700])
def test_bspline_coefficients_solve_the_clamped_system(n):
    """The recursive-filter solution against a dense solve of the clamped system
    (c[i-1] + 4 c[i] + c[i+1]) / 6 = f[i], c[-1] = c[0], c[n] = c[n-1]: the
    filters' truncation (|pole|^32 = 5e-19) and rounding leave ~1e-15."""
    from thinfilm_mi.tabulate import base as tabulate_base
    A = (np.diag(np.full(n, 4.0)) + np.diag(np.ones(n - 1), 1) + np.diag(np.ones(n - 1), -1)) / 6
    A[0, 0] += 1.0 / 6.0
    A[-1, -1] += 1.0 / 6.0
    f = np.random.default_rng(n).uniform(-1.0, 1.0, (n, 5, 2))
    ref = np.linalg.solve(A, f.reshape(n, -1)).reshape(f.shape)
    assert np.max(np.abs(tabulate_base.bspline_coefficients(f, axis=0) - ref)) < 1e-13
    assert np.max(np.abs(tabulate_base.bspline_coefficients(np.moveaxis(f, 0, 1), axis=1)
                         - np.moveaxis(ref, 0, 1))) < 1e-13


def test_table_cache_is_bounded_in_bytes_least_recently_used_first_out(monkeypatch):
    """Thousands of distinct tables (a sweep, an optimisation) must not pile up: the
    shared cache holds at most ``max_bytes`` of texture data (here what about three of
    the test's tables take instead of 64 MiB, so that a few exceed it) and evicts the
    least recently used. Tables still used by a BSDF stay valid (the BSDF holds them)."""
    from thinfilm_mi.tabulate import base as tabulate_base
    monkeypatch.setattr(stack_build, "TABLE_CACHE", tabulate_base.TableCache())
    one = mi.load_dict({"type": "thinfilm_conductor", "material": "Al",
                        "layers": "1.46 150; 2.3 60", "tabulate": True}).stack.plan[False].table
    cache = tabulate_base.TableCache(max_bytes=int(3.5 * one.nbytes))
    monkeypatch.setattr(stack_build, "TABLE_CACHE", cache)
    bsdfs = []
    for i in range(12):
        bsdfs.append(mi.load_dict({"type": "thinfilm_conductor", "material": "Al",
                                   "layers": f"1.46 {150 + 7 * i}; 2.3 60",
                                   "tabulate": True}))
        assert bsdfs[-1].stack.mode() == "table"
        assert cache.nbytes <= cache.max_bytes
        assert cache.nbytes == sum(t.nbytes for t in cache._items.values() if t is not None)
    sizes = [b.stack.plan[False].table.nbytes for b in bsdfs]
    assert sum(sizes) > cache.max_bytes, "the test needs more tables than the bound holds"
    assert len(cache) < len(bsdfs)
    # the newest table is kept; an identical stack shares it
    again = mi.load_dict({"type": "thinfilm_conductor", "material": "Al",
                          "layers": f"1.46 {150 + 7 * 11}; 2.3 60", "tabulate": True})
    assert again.stack.plan[False].table is bsdfs[-1].stack.plan[False].table
    # the evicted first table still evaluates through its BSDF
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.Spectrum([450.0, 520.0, 610.0, 700.0])
    R = np.array(bsdfs[0].stack.reflectance(si, mi.Float(0.8)), dtype=np.float64)
    ref = tf.Stack("1.46 150; 2.3 60", substrate="Al", ambient=media_mod.DEFAULT_EXT_IOR)
    np.testing.assert_allclose(R.ravel(), ref.rt(np.array([450.0, 520.0, 610.0, 700.0]),
                                                 np.arccos(0.8)).R,
                               atol=1.5 * bsdfs[0].stack.plan[False].table.error + 1e-5)


@pytest.mark.parametrize("kind", ["tiled", "random", "one", "repeats"])
def test_unique_wavelengths_is_numpys_unique(kind):
    """The builds' sort of their wavelengths returns exactly ``np.unique``'s arrays
    (so a build's points, and its table, are the same bits)."""
    from thinfilm_mi.tabulate.base import unique_wavelengths

    rng = np.random.default_rng(3)
    wl = {"tiled": np.tile(360.0 + 0.5 * np.arange(941), 7)[5:-3],
          "random": rng.choice(360.0 + 470.0 * rng.random(200), 5000),
          "one": np.array([550.0]),
          "repeats": np.array([600.0, 400.0, 600.0, 400.0, 500.0])}[kind]
    values, inverse = unique_wavelengths(wl)
    expected_values, expected_inverse = np.unique(wl, return_inverse=True)
    np.testing.assert_array_equal(values, expected_values)
    np.testing.assert_array_equal(inverse, expected_inverse.ravel())
