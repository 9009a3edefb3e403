"""Load-time ranges of bitmap textures (issue 30, section 4): a ``bitmap`` reflectance
of ``thinfilm_diffuse`` holding RGB values of 1.7 and -0.3 must not reach the image.

What a plugin sees of an RGB bitmap depends on the variant: in RGB and mono variants
its texels (mono: their luminance), so they are checked exactly, texel by texel; in
spectral variants Mitsuba's sRGB upsampling (``raw`` false) has already mapped every
texel into a spectrum within [0, 1] (it clips the RGB first), so the albedo the
plugin uses is in range and only a ``raw`` RGB bitmap (no spectrum at all) is refused.
"""
from __future__ import annotations

import re

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins)
from thinfilm_mi.render.textures import LUMINANCE, texture_range

SPECTRAL = "llvm_ad_spectral"


@pytest.fixture(autouse=True)
def _restore_variant():
    yield
    mi.set_variant(SPECTRAL)


def _exr(tmp_path, texels, name="albedo.exr"):
    path = tmp_path / name
    mi.Bitmap(np.asarray(texels, np.float32)).write(str(path))
    return str(path)


def _issue_bitmap(tmp_path):
    """4 x 4 grey 0.5 with the issue's values in two texels: a saturated colour
    (1.7, 0.2, -0.3) and a grey 1.7 (luminance 1.7, for mono variants)."""
    img = np.full((4, 4, 3), 0.5, np.float32)
    img[0, 0] = [1.7, 0.2, -0.3]
    img[2, 3] = [1.7, 1.7, 1.7]
    return img, _exr(tmp_path, img)


def _diffuse(filename, **bitmap):
    """A ``thinfilm_diffuse`` on the bitmap (Mitsuba's loader passes a plugin's
    ThinFilmError on as a RuntimeError holding its type and message)."""
    return mi.load_dict({"type": "thinfilm_diffuse", "layers": "SiO2 300",
                         "reflectance": {"type": "bitmap", "filename": filename, **bitmap}})


@pytest.mark.parametrize("variant", ["llvm_ad_rgb", "llvm_ad_mono", "scalar_rgb"])
@pytest.mark.parametrize("bitmap", [{}, {"raw": True}, {"filter_type": "nearest"}])
def test_out_of_range_rgb_bitmap_is_refused_naming_the_range(variant, bitmap, tmp_path):
    mi.set_variant(variant)
    mi.set_log_level(mi.LogLevel.Error)  # Mitsuba's own warning about the range
    img, path = _issue_bitmap(tmp_path)
    values = img @ LUMINANCE if variant.endswith("mono") else img
    lo, hi = float(values.min()), float(values.max())
    with pytest.raises(RuntimeError) as err:
        _diffuse(path, **bitmap)
    msg = str(err.value)
    assert "ThinFilmError: thinfilm_diffuse: 'reflectance'" in msg and ">= 0 and <= 1.001" in msg, msg
    # the exact texel range (float32 texels; bilinear samples between texel
    # centres found 1.63 for 1.7 before)
    found = [float(x) for x in re.search(r"values in \[(\S+), (\S+)\]", msg).groups()]
    assert found == pytest.approx([lo, hi], abs=1e-6), msg


@pytest.mark.parametrize("variant, channels", [("llvm_ad_rgb", 3), ("llvm_ad_mono", 3),
                                               ("llvm_ad_spectral", 1)])


def test_one_texel_just_out_of_range_is_caught(variant, channels, tmp_path):
    # A single texel at 1.01 among 0.5s: the old 64 x 64 UV grid sampled a 4 x 4
    # bitmap between texel centres and saw at most 0.98, so it was accepted.
    mi.set_variant(variant)
    img = np.full((4, 4, channels), 0.5, np.float32)
    img[1, 2] = 1.01
    with pytest.raises(RuntimeError, match=r"ThinFilmError: .*'reflectance'.*values in \[0\.5, 1\.0099"):
        _diffuse(_exr(tmp_path, img))
    img[1, 2] = 1.0  # in range: accepted
    _diffuse(_exr(tmp_path, img, "ok.exr"))


def test_raw_rgb_bitmap_in_a_spectral_variant_is_refused_at_load(tmp_path):
    # It was accepted, and rendering then failed inside Mitsuba ("queried for a
    # spectrum, but texture conversion into spectra was explicitly disabled").
    mi.set_variant(SPECTRAL)
    _, path = _issue_bitmap(tmp_path)
    with pytest.raises(RuntimeError, match=r"ThinFilmError: .*'reflectance'.*RGB bitmap with raw=true"):
        _diffuse(path, raw=True)


def test_spectral_albedo_of_an_out_of_range_rgb_bitmap_stays_within_0_1(tmp_path):
    # In a spectral variant the plugin sees the upsampled spectra, which Mitsuba
    # builds from RGB clipped to [0, 1]: the albedo it renders with (eval * pi / cos,
    # no films) is within [0, 1] at every texel centre and wavelength, equal to
    # Mitsuba's own `diffuse` with the same bitmap, so there is no energy gain.
    mi.set_variant(SPECTRAL)
    _, path = _issue_bitmap(tmp_path)
    refl = {"type": "bitmap", "filename": path}
    ours = mi.load_dict({"type": "thinfilm_diffuse", "reflectance": refl})
    theirs = mi.load_dict({"type": "diffuse", "reflectance": refl})
    rng = texture_range(mi.load_dict(refl))
    assert 0.0 <= rng[0] and rng[1] <= 1.0

    u, v = np.meshgrid((np.arange(4) + 0.5) / 4, (np.arange(4) + 0.5) / 4)
    lam = np.linspace(360.0, 830.0, 96).reshape(-1, 4)
    n = u.size * lam.shape[0]
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.uv = mi.Point2f(np.repeat(u.ravel(), lam.shape[0]), np.repeat(v.ravel(), lam.shape[0]))
    si.wavelengths = mi.UnpolarizedSpectrum(*[mi.Float(np.tile(lam[:, c], u.size)) for c in range(4)])
    si.wi = mi.Vector3f(0, 0, 1)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    cos_o = 0.6
    wo = mi.Vector3f(0.8, 0, cos_o)
    ctx = mi.BSDFContext()
    albedo = np.array(ours.eval(ctx, si, wo)[0]) * np.pi / cos_o
    reference = np.array(theirs.eval(ctx, si, wo)[0]) * np.pi / cos_o
    assert albedo.min() >= 0.0 and albedo.max() <= 1.0 + 1e-6
    assert albedo.max() > 0.99            # the clipped 1.7 texels: white
    # float32 evaluations of the same product in two plugins
    np.testing.assert_allclose(albedo, reference, rtol=1e-5, atol=1e-7)


@pytest.mark.parametrize("variant", ["llvm_ad_rgb", "llvm_ad_mono", SPECTRAL])
@pytest.mark.parametrize("raw", [True, False])
@pytest.mark.parametrize("channels", [1, 3])
def test_eight_bit_bitmap_range_is_what_its_lookups_return(variant, raw, channels, tmp_path):
    """An 8-bit PNG is kept as integer codes: its range is the codes / 255 (raw) or
    their sRGB decoding, exactly the values its lookups return at the texel centres
    (a range of 0-255 once made a thickness table cover the wrong scales)."""
    mi.set_variant(variant)
    if channels == 3 and mi.is_spectral and not raw:
        pytest.skip("spectral variants upsample an sRGB bitmap: no texel range (see above)")
    codes = np.array([[[23], [111]], [[200], [254]]], np.uint8).repeat(channels, axis=2)
    codes[0, 0] = np.arange(channels) + 23
    path = str(tmp_path / "codes.png")
    mi.Bitmap(codes, pixel_format=mi.Bitmap.PixelFormat.Y if channels == 1
              else mi.Bitmap.PixelFormat.RGB).write(path)
    tex = mi.load_dict({"type": "bitmap", "filename": path, "raw": raw, "filter_type": "nearest"})
    si = dr.zeros(mi.SurfaceInteraction3f, 4)
    si.uv = mi.Point2f(mi.Float([0.25, 0.75, 0.25, 0.75]), mi.Float([0.25, 0.25, 0.75, 0.75]))
    looked_up = np.array(tex.eval_1(si), np.float64)
    lo, hi = texture_range(tex, mono=True)
    # float32 lookups of the same codes: equal within float32 rounding of the decoding and
    # of the luminance sum (3 products added in another order: ~1e-6 measured, 2e-6 bound)
    np.testing.assert_allclose([lo, hi], [looked_up.min(), looked_up.max()], rtol=2e-6)
    assert hi < 1.0 + 1e-6     # not the codes (254)
