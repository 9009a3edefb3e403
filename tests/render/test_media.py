"""A dataset in the render kernel (thinfilm_mi/render/media.py): in spectral variants its
textures hold it on its uniform grid (``regular`` spectra) within the materials' bound of
its own interpolation, an edit of its arrays is resampled onto that grid (gradients
included), and a dataset no grid holds keeps its own knots.

The reference is the dataset's own interpolation (``Material.index``, float64 numpy).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins)
from thinfilm_mi.materials import catalog
from thinfilm_mi.materials.model import RESAMPLE_TOL
from thinfilm_mi.render.media import SpectralIndex
from thinfilm_mi.render.textures import texture_on_grid

# the bound plus float32 storage of values up to ~7 (Al's k): 7 * 2^-24 ~ 4e-7, and of the
# wavelengths (Mitsuba's lerp weight in float32: slope ~0.05/nm * 830 * 2^-24 ~ 3e-6)
TOL = RESAMPLE_TOL + 5e-6
WL = np.random.default_rng(7).uniform(360.0, 830.0, 257)


def textures(index, wl=WL):
    """What the kernel's texture lookups give at ``wl``."""
    return texture_on_grid(index.eta, wl) + 1j * texture_on_grid(index.k, wl)


@pytest.fixture(autouse=True)
def _spectral(llvm):
    yield


@pytest.mark.parametrize("name", ["Au", "Al", "TiO2", "SiO2"])
def test_a_dataset_renders_within_the_bound_of_its_own_interpolation(name):
    index = SpectralIndex.from_material(name, "material")
    assert index.uniform_grid is not None
    assert index.eta.class_name() == "RegularSpectrum"
    got = textures(index)
    want = catalog.resolve(name).index(WL)
    np.testing.assert_allclose(got.real, want.real, rtol=0, atol=TOL)
    np.testing.assert_allclose(got.imag, want.imag, rtol=0, atol=TOL)
    # what the loops' buffers and the tables read is the data itself (float32 storage)
    eta, k = index.data_on(index.knots)
    np.testing.assert_allclose(eta + 1j * k, catalog.resolve(name).index(index.knots),
                               rtol=2e-7, atol=1e-7)
    np.testing.assert_allclose(index.spectral_values(WL), want, rtol=2e-7, atol=1e-7)


def test_an_edit_of_the_arrays_is_resampled_with_its_gradients():
    index = SpectralIndex.from_material("Au", "material")
    before = textures(index)
    values = index.arrays["eta"]["values"] * 1.1
    dr.enable_grad(values)
    index.arrays["eta"]["values"] = values
    index.parameters_changed("thinfilm_conductor", "layers.0.")
    after = textures(index)
    np.testing.assert_allclose(after.real, 1.1 * before.real, rtol=0, atol=1.1 * TOL)
    np.testing.assert_allclose(after.imag, before.imag, rtol=0, atol=1e-7)
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wavelengths = mi.UnpolarizedSpectrum(550.0)
    out = index.eval(si).re[0]
    assert dr.grad_enabled(out)
    dr.backward(out)
    assert float(dr.sum(dr.grad(values))[0]) == pytest.approx(1.0, abs=1e-5)  # lerp weights
    # the edited knots are where the index may bend
    assert index.kinks.size > 0


def test_a_dataset_no_grid_holds_keeps_its_own_knots():
    # Mitsuba's Te-e preset steps by ~0.05 in n within a fraction of a nanometre
    mat = catalog.resolve("mitsuba:Te-e")
    assert mat.uniform_resampling() is None
    index = SpectralIndex.from_material(mat, "material")
    assert index.uniform_grid is None and index.eta.class_name() == "IrregularSpectrum"
    np.testing.assert_allclose(textures(index), mat.index(WL), rtol=2e-6, atol=1e-6)


def test_an_edit_through_mi_traverse_reaches_the_resampled_textures():
    # mi.traverse assigns into the very arrays the index exposed: the index must tell
    # the edit from what it last wrote (a snapshot, not the same objects)
    bsdf = mi.load_dict({"type": "thinfilm_conductor", "material": "Al", "layers": "Au 20",
                         "tabulate": False})
    index = bsdf.stack.indices[0]
    before = textures(index)
    params = mi.traverse(bsdf)
    params["layers.0.k.values"] = params["layers.0.k.values"] * 0.5
    params.update()
    after = textures(index)
    np.testing.assert_allclose(after.imag, 0.5 * before.imag, rtol=0, atol=TOL)
    wl = np.array(params["layers.0.k.wavelengths"])
    params["layers.0.k.wavelengths"] = mi.Float(wl[::-1].copy())
    with pytest.raises(Exception, match="strictly increasing"):
        params.update()
