"""RGB and mono renders against the spectral render of the same scene.

In ``*_rgb`` and ``*_mono`` variants the plugins read the film's ``R``/``T``
integrated against CIE 1931 2° colour matching under D65 (linear sRGB, or Y),
which is what Mitsuba's spectral pipeline does with a D65-white emitter and an
RGB film. So a render in ``llvm_ad_rgb`` must show the colours of the same scene
rendered in ``llvm_ad_spectral`` (CIEDE2000 over 4x4-pixel blocks: mean <= 1,
95th percentile <= 3), and ``llvm_ad_mono`` its luminance (within 2 %).

**Scenes** (``mi.load_dict``): a 24x24 perspective view of a unit sphere resting on
a 100 x 100 grey (0.5) Lambertian floor that fills the whole frame (no background
pixels), lit by a ``constant`` emitter of ``rgb`` radiance (1, 1, 1); path tracer,
``max_depth`` 8 (the sphere reflects the floor, the floor receives the light the
sphere reflects or transmits, glass needs 4+ bounces to show the floor through
it). One plugin per scene, on the sphere: a 30-film 2.3/1.46 stack on Al
(``thinfilm_conductor``: cavity resonances ~0.1 nm wide), a single thick film
``SiO2 500`` on Cu (``thinfilm_roughconductor``), a ``2.3 300`` film on glass 1.5
(``thinfilm_dielectric``), 2 films on rough glass 1.5 (``thinfilm_roughdielectric``)
and ``SiO2 500; Au 2`` over an RGB albedo (``thinfilm_diffuse``; also over a grey
one). A control scene has Mitsuba's own ``diffuse`` (grey) on the sphere: it
validates the method (illuminant, film conversion, CIELAB) with no plugin in it.
No area light: a small one makes caustics through the glass sphere whose noise
(fireflies on the floor, 4x4-block ΔE2000 p95 ~1.7 at 256 spp) would dominate.

**Illuminant.** In spectral variants Mitsuba upsamples an emitter's ``rgb``
radiance and multiplies it by the D65 spectrum, so rgb (1, 1, 1) is D65 white; the
RGB film integrates the spectral radiance against the CIE 1931 matching functions
and converts XYZ to linear sRGB, so a perfect white reflector under the emitter
reads (1, 1, 1) in both variants. The control scene checks exactly this: its
ΔE2000 is at the noise floor (0.14 mean, 0.28 p95) and its mono luminance within
0.7 % (noise).

**Comparison.** Both images are linear sRGB. Each is averaged over 4x4-pixel
blocks (36 blocks; the box filter makes a block the mean of its 16 pixels'
samples) in linear RGB, then converted to XYZ with the sRGB matrix and to CIELAB
with the D65 white point. The white reference (``Y_n = 1``) is the exposure of a
perfect white Lambertian reflector under the unoccluded constant emitter, whose
radiance is exactly (1, 1, 1): the images are used unscaled (the grey floor
reads L* ~ 76; the sphere's mirror image of the sky may exceed L* 100, which
CIEDE2000 handles). The statistics run over all 36 blocks: none is background
(the floor fills the frame; the sky appears only in reflections, as a part of
the plugins' response), and floor blocks carry the interreflected light (colour
bleeding, the sphere's shadow and caustic). They are checked again over the 20
blocks the sphere covers at least half of (a coverage render), so that plain
floor blocks cannot dilute an error on the sphere.

**Noise** (measured by rendering every scene with seeds 7 and 8 at 24x24, 2048
spp; 4x4 blocks): ΔE2000 between two spectral renders 0.18-0.31 mean, 0.34-0.61
p95, between two RGB renders 0.04-0.18 mean, 0.13-0.43 p95 (the spectral render
dominates: wavelength sampling adds colour noise). Block luminance: relative
standard deviation 0.13-0.22 % (spectral), 0.17-0.27 % (mono). The image is small
and the spp high on purpose: a block's noise depends only on its 16 x spp samples,
and fewer blocks make the worst block less extreme (at 32x32 and 1024 spp the
worst mono block reached 1.8 % from noise alone; here 0.9 %).

**Known deviation** (``diffuse_rgb_albedo``, model "multiple", xfail): ``thinfilm_diffuse`` in RGB
multiplies the film's integrated transmittances by the albedo *per channel*
(thinfilm_mi/tabulate/diffuse.py), while the spectral render multiplies, per
wavelength, by the albedo's upsampled spectrum. With a saturated albedo under
a coloured film the two differ (4x4 blocks on the sphere: ΔE2000 1.47 mean);
:func:`test_diffuse_rgb_albedo_is_the_per_channel_albedo` shows that this is
the only difference. Mono variants see only the albedo's luminance (Mitsuba
turns an ``rgb`` texture into a uniform spectrum at load), so mono cannot follow
the spectral product either (-1.1 % mean, -3.0 % worst block).

Each (variant, scene) renders once per session (the RGB and the mono tests share
the spectral render); the suite's default variant (``llvm_ad_spectral``) is set
again after every render and at the end of the module.
"""
from __future__ import annotations

import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins, and again on every variant switch)

colour = pytest.importorskip("colour")

DEFAULT = "llvm_ad_spectral"
SPECTRAL, RGB, MONO = "llvm_ad_spectral", "llvm_ad_rgb", "llvm_ad_mono"

pytestmark = pytest.mark.skipif(
    not {SPECTRAL, RGB, MONO} <= set(mi.variants()), reason="needs the llvm_ad variants")

RES = 24
BLOCK = 4
SPP = 2048
SEED = 7
MAX_DEPTH = 8

#: The requirement: CIEDE2000 over 4x4-pixel blocks, mean <= 1 and 95th percentile <= 3.
#: Measured (seeds 7 and 8) at most 0.53 mean and 1.02 p95 on the passing scenes,
#: against a noise floor of 0.16-0.39 mean (spectral and RGB noise together).
DE_MEAN_MAX = 1.0
DE_P95_MAX = 3.0
#: Mono: each 4x4 block within 2 % of the spectral render's luminance Y. Measured:
#: worst block 0.89 % (seeds 7 and 8) on the passing scenes, all of it noise (the
#: blocks' relative standard deviation is ~0.3 % for mono - spectral: 2 % is ~6 sigma).
MONO_REL_MAX = 0.02
#: Blocks darker than this Y (white = 1) would be left out of the mono check (their
#: relative noise grows); none is in these scenes: the darkest, in the sphere's
#: contact shadow, has Y ~ 0.24. The test asserts that none is left out.
MONO_MIN_Y = 0.05
#: A block is "on the sphere" when the sphere covers at least this fraction of it.
SPHERE_COVERAGE = 0.5
#: spp of the three spectral renders of the per-channel-albedo check (noise 2x the
#: main renders': ΔE2000 0.36-0.45 mean against the RGB render, still far below 1).
CHANNEL_SPP = 512

SRGB = colour.RGB_COLOURSPACES["sRGB"]
RGB_TO_XYZ = SRGB.matrix_RGB_to_XYZ
D65_XY = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]

FILMS_30 = "; ".join(["2.3 60; 1.46 90"] * 15)
ALBEDO = [0.2, 0.45, 0.7]
DIFFUSE_FILMS = "SiO2 500; Au 2"

#: The sphere's BSDF per scene (plain dicts: nothing variant-specific in them).
CASES = {
    "control_mitsuba_diffuse": {"type": "diffuse",
                                "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}},
    "conductor_30_films": {"type": "thinfilm_conductor", "material": "Al",
                           "layers": FILMS_30},
    "roughconductor_SiO2_500": {"type": "thinfilm_roughconductor", "material": "Cu",
                                "alpha": 0.2, "layers": "SiO2 500"},
    "dielectric": {"type": "thinfilm_dielectric", "int_ior": 1.5, "layers": "2.3 300"},
    "roughdielectric": {"type": "thinfilm_roughdielectric", "int_ior": 1.5, "alpha": 0.15,
                        "layers": "2.3 150; 1.46 100"},
    "diffuse_grey_albedo": {"type": "thinfilm_diffuse",
                            "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]},
                            "layers": DIFFUSE_FILMS},
    # the paper's model, whose transmittance (into bulk gold) is strongly coloured: the
    # known deviation below; "exact" (the default) transmits ~0.9 flat through 2 nm of
    # gold and passes both bounds (measured XPASS when this case used the default)
    "diffuse_rgb_albedo": {"type": "thinfilm_diffuse", "model": "multiple",
                           "reflectance": {"type": "rgb", "value": ALBEDO},
                           "layers": DIFFUSE_FILMS},
}

_RGB_ALBEDO_XFAIL = pytest.mark.xfail(strict=True, reason=(
    "thinfilm_diffuse in RGB variants multiplies the film's integrated transmittance "
    "by the albedo per channel, the spectral render by its upsampled spectrum: "
    "ΔE2000 1.06 mean over all blocks, 1.47 mean over the sphere's blocks "
    "(test_diffuse_rgb_albedo_is_the_per_channel_albedo: the only difference)"))
_MONO_ALBEDO_XFAIL = pytest.mark.xfail(strict=True, reason=(
    "mono variants give the plugin only the albedo's luminance (Mitsuba turns an rgb "
    "texture into a uniform spectrum), so the spectral film x albedo product cannot be "
    "followed: -1.1 % mean, -3.0 % worst block"))


def _params(xfail_mark):
    return [pytest.param(c, marks=xfail_mark) if c == "diffuse_rgb_albedo" else c
            for c in CASES]


# ---------------------------------------------------------------------------
# Scenes and renders
# ---------------------------------------------------------------------------
def scene_dict(bsdf: dict, spp: int = SPP, seed: int = SEED, coverage: bool = False) -> dict:
    """The test scene in the current variant. ``coverage=True``: the sphere's pixel
    coverage instead (the sphere emits 1, nothing else lights or reflects)."""
    T = mi.ScalarTransform4f
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
    ball = {"type": "sphere", "center": [0.0, 0.0, 1.0], "radius": 1.0, "bsdf": bsdf}
    if coverage:
        ball = {**ball, "bsdf": black,
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1.0] * 3}}}
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 1 if coverage else MAX_DEPTH},
        "sensor": {
            "type": "perspective", "fov": 30.0,
            "to_world": T().look_at(origin=[0.0, -4.2, 2.6], target=[0.0, 0.0, 0.85],
                                    up=[0.0, 0.0, 1.0]),
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
            "film": {"type": "hdrfilm", "width": RES, "height": RES,
                     "rfilter": {"type": "box"},
                     "pixel_format": "luminance" if mi.is_monochromatic else "rgb"},
        },
        # 100 x 100: no ray from the camera misses the floor (no background pixels).
        "floor": {"type": "rectangle", "to_world": T().scale(50.0),
                  "bsdf": black if coverage else
                  {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5] * 3}}},
        "ball": ball,
    }
    if not coverage:
        d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    return d


def render(variant: str, bsdf: dict, **kw) -> np.ndarray:
    """Render the scene in ``variant`` (H x W x channels, float64); the suite's default
    variant is set again afterwards, also on failure."""
    try:
        mi.set_variant(variant)  # thinfilm_mi's variant callback registers the plugins
        img = mi.render(mi.load_dict(scene_dict(bsdf, **kw)))
        return np.array(img, dtype=np.float64).reshape(RES, RES, -1)
    finally:
        mi.set_variant(DEFAULT)


def blocks(img: np.ndarray) -> np.ndarray:
    """Mean of each BLOCK x BLOCK block, in linear units: (blocks, channels)."""
    h, w, c = img.shape
    return img.reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK, c).mean(axis=(1, 3)).reshape(-1, c)


def lab(rgb_blocks: np.ndarray) -> np.ndarray:
    """Linear sRGB (white = 1) to CIELAB (D65 white point, Y_n = 1)."""
    return colour.XYZ_to_Lab(rgb_blocks @ RGB_TO_XYZ.T, D65_XY)


def delta_e(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """CIEDE2000 per 4x4 block between two linear sRGB images."""
    return colour.delta_E(lab(blocks(a)), lab(blocks(b)), method="CIE 2000")


def luminance(rgb_blocks: np.ndarray) -> np.ndarray:
    """Y of linear sRGB (the sRGB -> XYZ matrix's middle row)."""
    return rgb_blocks @ RGB_TO_XYZ[1]


_CACHE: dict = {}


def rendered(variant: str, case: str) -> np.ndarray:
    """Each (variant, scene) renders once per session."""
    key = (variant, case)
    if key not in _CACHE:
        _CACHE[key] = render(variant, CASES[case])
    return _CACHE[key]


def sphere_blocks() -> np.ndarray:
    """Blocks mostly covered by the sphere (coverage render: 64 spp, RGB)."""
    if "coverage" not in _CACHE:
        img = render(RGB, CASES["control_mitsuba_diffuse"], spp=64, coverage=True)
        _CACHE["coverage"] = blocks(img)[:, 1] >= SPHERE_COVERAGE
    return _CACHE["coverage"]


def assert_colours_match(reference: np.ndarray, other: np.ndarray, what: str) -> None:
    """Mean <= 1 and p95 <= 3 of the blocks' ΔE2000, over all blocks and over the
    sphere's blocks."""
    assert np.all(np.isfinite(reference)) and np.all(np.isfinite(other)), what
    de = delta_e(reference, other)
    for name, sel in (("all blocks", slice(None)), ("sphere blocks", sphere_blocks())):
        mean, p95 = float(de[sel].mean()), float(np.percentile(de[sel], 95))
        assert mean <= DE_MEAN_MAX and p95 <= DE_P95_MAX, (
            f"{what}, {name}: ΔE2000 mean {mean:.3f} (max {DE_MEAN_MAX}), "
            f"p95 {p95:.3f} (max {DE_P95_MAX}), worst block {de[sel].max():.2f}")


@pytest.fixture(scope="module", autouse=True)
def default_variant():
    yield
    mi.set_variant(DEFAULT)
    _CACHE.clear()


# ---------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------
def test_framing_has_no_background_and_a_large_sphere():
    """What the statistics rely on: the sphere covers 20 of the 36 blocks (at least
    half of each), and no block shows the background (the floor catches every
    camera ray: with the sphere and the floor black and the sky off, the sphere's
    emission is all there is, and the floor blocks read 0)."""
    on_sphere = sphere_blocks()
    assert 0.3 <= on_sphere.mean() <= 0.8, on_sphere.mean()
    # Background check: the floor alone, lit by the sky, seen without the sphere.
    try:
        mi.set_variant(RGB)
        d = scene_dict(CASES["control_mitsuba_diffuse"], spp=4)
        del d["ball"]
        d["floor"]["bsdf"] = {"type": "diffuse",
                              "reflectance": {"type": "rgb", "value": [0.0] * 3}}
        img = np.array(mi.render(mi.load_dict(d)))
    finally:
        mi.set_variant(DEFAULT)
    assert np.all(img == 0.0), "the sky is visible from the camera: background pixels"


@pytest.mark.slow
@pytest.mark.parametrize("case", _params(_RGB_ALBEDO_XFAIL))
def test_rgb_matches_spectral(case):
    """llvm_ad_rgb against llvm_ad_spectral: ΔE2000 of 4x4 blocks at 2048 spp,
    mean <= 1 and p95 <= 3 over all blocks, and over the sphere's blocks.

    Measured, mean/p95 over all blocks | over the sphere's blocks, seed 7 (seed 8):

    ======================= ========================= =========================
    scene                   all blocks                sphere blocks
    ======================= ========================= =========================
    control (Mitsuba)       0.14/0.28 (0.17/0.32)     0.14/0.22 (0.17/0.29)
    conductor, 30 films     0.13/0.27 (0.16/0.31)     0.12/0.26 (0.16/0.25)
    roughconductor SiO2 500 0.13/0.28 (0.16/0.29)     0.13/0.23 (0.16/0.29)
    dielectric 2.3 300      0.30/0.61 (0.30/0.57)     0.36/0.68 (0.32/0.59)
    roughdielectric         0.37/0.88 (0.39/0.96)     0.51/0.94 (0.52/1.02)
    diffuse, grey albedo    0.20/0.45 (0.19/0.49)     0.23/0.57 (0.20/0.50)
    diffuse, RGB albedo     1.06/1.97 (1.06/1.94)     1.48/2.15 (1.46/1.95)  xfail
    ======================= ========================= =========================

    Noise floor (two seeds, same variant): spectral 0.18-0.31 mean, RGB 0.04-0.18;
    the dielectrics are the noisiest (light through the glass onto the floor).
    """
    assert_colours_match(rendered(SPECTRAL, case), rendered(RGB, case), case)


@pytest.mark.slow
@pytest.mark.parametrize("case", _params(_MONO_ALBEDO_XFAIL))
def test_mono_matches_spectral_luminance(case):
    """llvm_ad_mono against Y of the llvm_ad_spectral render (sRGB -> XYZ), per 4x4
    block: within 2 % relative on every block with Y >= 0.05 (all of them here).

    Measured worst block (mean signed error), seed 7 | seed 8: control 0.66 %
    (+0.01 %) | 0.87 %; conductor, 30 films 0.71 % (+0.04 %) | 0.63 %; roughconductor
    0.59 % (-0.07 %) | 0.61 %; dielectric 0.70 % (+0.16 %) | 0.88 %; roughdielectric
    0.82 % (+0.10 %) | 0.89 %; diffuse, grey albedo 0.51 % (-0.04 %) | 0.67 %;
    diffuse, RGB albedo 2.95 % (-1.10 %) | 3.03 % (xfail). Noise: relative
    standard deviation of a block 0.13-0.22 % (spectral), 0.17-0.27 % (mono)."""
    y_spec = luminance(blocks(rendered(SPECTRAL, case)))
    mono = rendered(MONO, case)
    assert mono.shape[-1] == 1 and np.all(np.isfinite(mono))
    y_mono = blocks(mono)[:, 0]
    keep = y_spec >= MONO_MIN_Y
    assert keep.all(), f"{case}: {np.sum(~keep)} blocks darker than Y = {MONO_MIN_Y}"
    rel = np.abs(y_mono / y_spec - 1.0)
    worst = int(np.argmax(rel))
    assert rel.max() <= MONO_REL_MAX, (
        f"{case}: mono vs spectral luminance, worst block {worst}: Y {y_spec[worst]:.4f} "
        f"vs {y_mono[worst]:.4f} ({rel.max():.4f}); mean abs error {rel.mean():.4f}")


@pytest.mark.slow
def test_diffuse_rgb_albedo_is_the_per_channel_albedo():
    """The cause of the ``diffuse_rgb_albedo`` xfail, checked: the RGB render equals,
    channel by channel, spectral renders with a *grey* albedo equal to that channel
    (channel c of the spectral render with albedo ALBEDO[c] everywhere), so the
    plugin renders its per-channel convention correctly and the only difference
    from the spectral render is the albedo's upsampled spectrum.

    Measured (512 spp for the three spectral renders), seed 7 (seed 8): ΔE2000
    0.38 mean / 0.83 p95 (0.38/0.75) over all blocks, 0.45/0.86 (0.36/0.59) on the
    sphere: the noise floor. The spectral render with the upsampled albedo is
    1.06/1.97 and 1.48/2.15 from the same RGB render.
    """
    per_channel = np.zeros((RES, RES, 3))
    for c in range(3):
        grey = {"type": "rgb", "value": [ALBEDO[c]] * 3}
        img = render(SPECTRAL, {**CASES["diffuse_rgb_albedo"], "reflectance": grey},
                     spp=CHANNEL_SPP)
        per_channel[..., c] = img[..., c]
    assert_colours_match(per_channel, rendered(RGB, "diffuse_rgb_albedo"),
                         "per-channel grey albedos (spectral) vs RGB")
