"""The coating designer's numbers (thinfilm_mi.colour.report, `python -m thinfilm_mi colour`)
against independent computations written here: Fresnel and single-film closed forms for
the spectra, colour-science's own sd_to_XYZ / XYZ_to_Lab / illuminant tables / Planck
for the colorimetry, and the sRGB encoding written out.
"""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest

colour = pytest.importorskip("colour")

from thinfilm_mi import Stack, ThinFilmError  # noqa: E402
from thinfilm_mi.cli import tools as tf_main  # noqa: E402
from thinfilm_mi.colour.cie import delta_e2000  # noqa: E402
from thinfilm_mi.colour.report import (  # noqa: E402
    RECORD_KEYS,
    colour_report,
    integration_wavelengths,
    resolve_illuminant,
    spectrum_colour,
)

# colour-science warns when sd_to_XYZ aligns a table to the requested shape (here on purpose)
pytestmark = pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning")

CMFS_2 = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
CMFS_10 = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"]
CCS_2 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]
CCS_10 = colour.CCS_ILLUMINANTS["CIE 1964 10 Degree Standard Observer"]
#: The report integrates D65 over 360-780 nm at 1 nm (colour-science's D65 table ends at 780 nm).
SHAPE_D65 = colour.SpectralShape(360, 780, 1)


def single_film_R(wl, n0, n1, d, ns):
    """Airy summation for one non-absorbing film at normal incidence."""
    r01, r12 = (n0 - n1) / (n0 + n1), (n1 - ns) / (n1 + ns)
    phase = np.exp(2j * (2 * np.pi * n1 * d / wl))
    return np.abs((r01 + r12 * phase) / (1 + r01 * r12 * phase)) ** 2


def independent_XYZ(R, wl, illuminant_sd, cmfs=CMFS_2, shape=SHAPE_D65):
    """colour-science's own integration of a reflectance SD, scaled to Y(white) = 1."""
    sd = colour.SpectralDistribution(R, wl)
    return colour.sd_to_XYZ(sd, cmfs, illuminant_sd, method="Integration", shape=shape) / 100.0


def srgb_encode(v):
    """IEC 61966-2-1 sRGB encoding, written out."""
    v = np.clip(v, 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


# --------------------------------------------------------------------------------------
# the three numbers


def test_bare_glass_Y_is_fresnel():
    n = 1.52
    fresnel = ((n - 1) / (n + 1)) ** 2  # 0.042580...
    rep = colour_report(Stack([], substrate=n), [0.0], "D65")
    R, T = rep.records()
    # R is flat in wavelength, so Y is R itself: the only error is float64 summation (~1e-15)
    assert R.Y == pytest.approx(fresnel, abs=1e-12)
    assert round(100 * R.Y, 2) == 4.26
    assert R.luminous == pytest.approx(fresnel, abs=1e-12)
    assert T.Y == pytest.approx(1 - fresnel, abs=1e-12)  # a lossless interface
    # a grey: the white's chromaticity, a* = b* = 0, L* from the CIE formula written out
    assert (R.x, R.y) == pytest.approx(tuple(rep.white_xy), abs=1e-12)
    L = 116 * fresnel ** (1 / 3) - 16
    assert (R.L, R.a, R.b) == pytest.approx((L, 0.0, 0.0), abs=1e-9)
    # the swatch: sRGB-encoded grey of linear value Y (a white adapted to D65 stays grey); the
    # 8-bit rounding of colour's D65 white (sRGB (1, 1.00003, 0.99993)) cannot move it by 1
    level = round(255 * float(srgb_encode(fresnel)))
    assert R.srgb == f"#{level:02x}{level:02x}{level:02x}"


def test_quarter_wave_mgf2():
    n0, nf, d, ns = 1.0, 1.38, 99.6, 1.52
    rep = colour_report(Stack([(nf, d)], substrate=ns), [0.0], "D65")
    # at the design wavelength 4 n d (549.8 nm) the quarter-wave closed form (n0 ns - nf^2)^2 / (...)^2
    quarter = ((n0 * ns - nf ** 2) / (n0 * ns + nf ** 2)) ** 2
    assert single_film_R(4 * nf * d, n0, nf, d, ns) == pytest.approx(quarter, rel=1e-12)
    R550 = Stack([(nf, d)], substrate=ns).rt(550.0, 0.0).R
    assert R550 == pytest.approx(single_film_R(550.0, n0, nf, d, ns), abs=1e-12)
    assert round(100 * float(R550), 2) == 1.26
    # the spectrum the report integrated is the Airy formula
    wl = integration_wavelengths("D65")
    np.testing.assert_allclose(rep.spectra["unpolarized", "R"][0], single_film_R(wl, n0, nf, d, ns), atol=1e-12)

    rec = rep.records()[0]
    XYZ = independent_XYZ(single_film_R(wl, n0, nf, d, ns), wl, colour.SDS_ILLUMINANTS["D65"])
    # the same sums in another order: float64 rounding only
    assert (rec.X, rec.Y, rec.Z) == pytest.approx(tuple(XYZ), rel=1e-9)
    xy = colour.XYZ_to_xy(XYZ)
    assert (rec.x, rec.y) == pytest.approx(tuple(xy), abs=1e-9)
    # photopic Y slightly above the 1.26 % minimum: R rises on both sides of 550 nm
    assert R550 < rec.Y < R550 + 0.002
    assert rec.luminous == pytest.approx(rec.Y, abs=1e-12)  # 2°: ȳ is V(λ)
    # purple: the line from the white through xy leaves the diagram through the line of purples,
    # which colour-science reports as a negative (complementary) dominant wavelength
    wl_d = colour.dominant_wavelength(xy, rep.white_xy, CMFS_2)[0]
    assert wl_d < 0, wl_d
    # and in CIELAB: red-ish (a* > 0) and blue-ish (b* < 0)
    assert rec.a > 0 and rec.b < 0
    Lab = colour.XYZ_to_Lab(XYZ, colour.XYZ_to_xy(independent_XYZ(np.ones_like(wl), wl,
                                                                   colour.SDS_ILLUMINANTS["D65"])))
    assert (rec.L, rec.a, rec.b) == pytest.approx(tuple(Lab), abs=1e-7)


# colour's tabulated chromaticities are rounded to 4-5 decimals and integrate over the whole
# table, ours over 360/380-780 nm at 1 nm: agreement to 1e-4; its 2° FL11 entry
# (0.3805, 0.3769) is 2.3e-4 from CIE 15:2004's (0.38052, 0.37713), hence 3e-4 there
@pytest.mark.parametrize("name, key, atol", [("D65", "D65", 1e-4), ("A", "A", 1e-4), ("F11", "FL11", 3e-4)])
def test_perfect_reflector_is_the_illuminants_white(name, key, atol):
    wl = integration_wavelengths(name)
    shape = colour.SpectralShape(wl[0], wl[-1], 1)
    sd = colour.SDS_ILLUMINANTS[key]
    for observer, cmfs, ccs in ((2, CMFS_2, CCS_2), (10, CMFS_10, CCS_10)):
        c = spectrum_colour(np.ones_like(wl), wl, name, observer)
        white = colour.sd_to_XYZ(sd, cmfs, method="Integration", shape=shape)  # an emitter's XYZ
        np.testing.assert_allclose(c.XYZ, white / white[1], rtol=1e-9)
        np.testing.assert_allclose(c.xy, ccs[key], atol=atol)
        assert c.Lab == pytest.approx([100.0, 0.0, 0.0], abs=1e-9)
        assert c.hex == "#ffffff"  # adapted to D65, a white is white
    # a Stack that reflects almost everything: substrate n = 1e-3 + 1000i, the edge of
    # the accepted index range (R = 1 - 4n/(n^2 + k^2) ~ 1 - 4e-9 at normal incidence,
    # below 1 - 6e-9 at 45 deg)
    rep = colour_report(Stack([], substrate="1e-3+1000j"), [0, 45], name)
    for r in rep.records():
        if r.quantity == "R":
            assert (r.x, r.y, r.Y) == pytest.approx((*rep.white_xy, 1.0), abs=1e-8)
        else:  # (almost) nothing enters: black, at the white's chromaticity
            assert r.Y == pytest.approx(0.0, abs=1e-8) and r.srgb == "#000000"
            assert (r.x, r.y) == pytest.approx(tuple(rep.white_xy), abs=1e-6)


def test_blackbody_illuminant_is_planck():
    ill = resolve_illuminant("blackbody:2856")
    assert ill.temperature == 2856.0
    ref = colour.sd_blackbody(2856, colour.SpectralShape(360, 830, 1))
    np.testing.assert_array_equal(ill.sd.values, ref.values)
    assert resolve_illuminant(" Blackbody : 2856 K ").name == "blackbody:2856"
    wl = integration_wavelengths("blackbody:2856")
    assert (wl[0], wl[-1]) == (360.0, 830.0)
    white = spectrum_colour(np.ones_like(wl), wl, "blackbody:2856").xy
    np.testing.assert_allclose(white, colour.XYZ_to_xy(colour.sd_to_XYZ(ref, CMFS_2, method="Integration")),
                               atol=1e-12)
    # CIE A is a 2856 K Planckian with the old c2 = 1.435e-2 (2863.6 K today): within 1e-4
    np.testing.assert_allclose(white, CCS_2["A"], atol=1e-4)
    # a hotter body is bluer
    assert spectrum_colour(np.ones_like(wl), wl, "blackbody:6500").xy[0] < white[0] - 0.1


def test_observers_and_luminous_Y():
    stack = Stack("1.46 500", substrate=1.6)
    r2 = colour_report(stack, [0, 40], "D65", observer=2)
    r10 = colour_report(stack, [0, 40], "D65", observer=10)
    wl = integration_wavelengths("D65")
    R = r2.spectra["unpolarized", "R"]
    for j in range(2):
        XYZ10 = independent_XYZ(R[j], wl, colour.SDS_ILLUMINANTS["D65"], cmfs=CMFS_10)
        np.testing.assert_allclose(r10.colours["unpolarized", "R"].XYZ[j], XYZ10, rtol=1e-9)
    xy2, xy10 = r2.colours["unpolarized", "R"].xy, r10.colours["unpolarized", "R"].xy
    assert np.abs(xy2 - xy10).max() > 1e-3  # a coloured film: the two observers disagree
    # the luminous Y is V(λ)-weighted whatever the observer: the 10° report's Yv is the 2° Y
    for key in r2.colours:
        np.testing.assert_allclose(r10.colours[key].luminous, r2.colours[key].XYZ[:, 1], atol=1e-12)
        assert np.abs(r10.colours[key].luminous - r10.colours[key].XYZ[:, 1]).max() > 1e-4
    # the sRGB swatch is always from the 2° XYZ (sRGB is defined on it)
    assert [r.srgb for r in r10.records()] == [r.srgb for r in r2.records()]


def test_s_and_p():
    stack = Stack("1.46 500; 0.42+2.47j 20", substrate=1.6)
    rep = colour_report(stack, [0, 60], "A", polarizations="both")
    assert rep.polarizations == ("s", "p")
    full = colour_report(stack, [0, 60], "A", polarizations=["unpolarized", "s", "p"])
    for q in ("R", "T"):
        s, p, u = (full.colours[k, q] for k in ("s", "p", "unpolarized"))
        np.testing.assert_allclose(u.XYZ, (s.XYZ + p.XYZ) / 2, rtol=1e-12)  # XYZ is linear
        np.testing.assert_allclose(s.XYZ[0], p.XYZ[0], rtol=1e-9)  # normal incidence
        assert np.abs(s.XYZ[1] - p.XYZ[1]).max() > 1e-3
        np.testing.assert_allclose(rep.colours["s", q].XYZ, s.XYZ, rtol=1e-12)
    res = stack.rt(integration_wavelengths("A"), math.radians(60))
    np.testing.assert_allclose(full.spectra["p", "T"][1], res.Tp, atol=1e-12)
    assert [d["polarization"] for d in rep.as_dicts()[:4]] == ["s", "s", "p", "p"]


def test_as_lit_swatch_is_not_adapted():
    wl = integration_wavelengths("A")
    lit = spectrum_colour(np.ones_like(wl), wl, "A", chromatic_adaptation=None)
    r, g, b = lit.rgb
    assert r == pytest.approx(1.0) and r > g > b + 0.3  # a white under a 2856 K lamp is orange
    # the unadapted linear sRGB is colour's XYZ -> sRGB matrix applied to the white's XYZ
    M = colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB
    np.testing.assert_allclose(lit.rgb_linear, M @ lit.XYZ, atol=1e-9)


# --------------------------------------------------------------------------------------
# bad input


@pytest.mark.parametrize("kwargs, match", [
    ({"illuminant": "D50"}, "illuminant.*'D50'"),
    ({"illuminant": ""}, "illuminant"),
    ({"illuminant": 65}, "illuminant.*65"),
    ({"illuminant": None}, "illuminant.*None"),
    ({"illuminant": "blackbody:0"}, "temperature.*> 0 K, got 0"),
    ({"illuminant": "blackbody:-300"}, "temperature.*got -300"),
    ({"illuminant": "blackbody:nan"}, "temperature.*nan"),
    ({"illuminant": "blackbody:inf"}, "temperature.*inf"),
    ({"illuminant": "blackbody:hot"}, "temperature.*'hot'"),
    ({"angles": 90}, r"angles.*\[0, 90\).*got 90"),
    ({"angles": [0, 95]}, "angles.*got 95"),
    ({"angles": -1}, "angles.*got -1"),
    ({"angles": [0, float("nan")]}, "angles.*got nan"),
    ({"angles": []}, "angles"),
    ({"angles": "ten"}, "angles.*'ten'"),
    ({"observer": 5}, "observer.*5"),
    ({"observer": "2 degrees"}, "observer.*'2 degrees'"),
    ({"polarizations": "q"}, "polarizations.*'q'"),
    ({"polarizations": []}, "polarizations"),
    ({"chromatic_adaptation": "nope"}, "chromatic_adaptation.*'nope'"),
])


def test_bad_input_names_the_parameter(kwargs, match):
    args = {"angles": 0.0, **kwargs}
    with pytest.raises(ThinFilmError, match=match):
        colour_report(Stack("1.38 99.6", substrate=1.52), **args)


def test_bad_spectra():
    wl = integration_wavelengths("D65")
    with pytest.raises(ThinFilmError, match="values"):
        spectrum_colour(np.full(wl.size, np.nan))
    with pytest.raises(ThinFilmError, match="values"):
        spectrum_colour(np.ones(10))
    with pytest.raises(ThinFilmError, match="wavelengths.*cover"):
        spectrum_colour(np.ones(5), [400, 450, 500, 550, 600])
    with pytest.raises(ThinFilmError, match="stack"):
        colour_report("1.38 99.6", 0.0)
    # another grid is interpolated: a constant spectrum on a 5 nm grid is the same colour
    coarse = np.arange(360.0, 781.0, 5.0)
    np.testing.assert_allclose(spectrum_colour(np.full(coarse.size, 0.3), coarse).XYZ,
                               spectrum_colour(np.full(wl.size, 0.3)).XYZ, rtol=1e-12)


# --------------------------------------------------------------------------------------
# command line


ARGS = ["colour", "--layers", "1.38 99.6", "--substrate", "1.52", "--angles", "0:80:20",
        "--illuminant", "D65"]


def test_cli_json_and_csv(tmp_path, capsys):
    out_csv = tmp_path / "colour.csv"
    assert tf_main.main(ARGS + ["--json", "--csv", str(out_csv)]) == 0
    records = json.loads(capsys.readouterr().out)
    assert len(records) == 5 * 2
    assert all(list(r) == list(RECORD_KEYS) for r in records)
    assert [(r["angle"], r["quantity"]) for r in records[:4]] == [(0, "R"), (0, "T"), (20, "R"), (20, "T")]
    api = colour_report(Stack("1.38 99.6", substrate=1.52), [0, 20, 40, 60, 80], "D65").as_dicts()
    assert records == json.loads(json.dumps(api))  # the CLI prints the API's records
    assert all(0 <= r["Y"] <= 1 and r["srgb"].startswith("#") and len(r["srgb"]) == 7 for r in records)
    with open(out_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == list(RECORD_KEYS)
    assert len(rows) == len(records)
    for row, rec in zip(rows, records):
        assert row["quantity"] == rec["quantity"] and row["srgb"] == rec["srgb"]
        for k in ("angle", "X", "Y", "Z", "x", "y", "L", "a", "b"):
            assert float(row[k]) == rec[k]  # repr round-trips float64 exactly


def test_cli_table_and_polarization(capsys):
    assert tf_main.main(ARGS) == 0
    out = capsys.readouterr().out
    rows = [l.split() for l in out.splitlines() if l.strip() and not l.startswith("#")]
    assert rows[0][:3] == ["angle", "qty", "X%"] and rows[0][-1] == "Yv%"
    assert len(rows) == 1 + 10
    assert rows[1][:2] == ["0", "R"] and float(rows[1][3]) == pytest.approx(1.302, abs=1e-3)
    assert tf_main.main(ARGS + ["--polarization", "s,p", "--json", "--observer", "10"]) == 0
    records = json.loads(capsys.readouterr().out)
    assert len(records) == 5 * 2 * 2
    assert list(records[0])[:3] == ["angle", "quantity", "polarization"]


@pytest.mark.parametrize("extra, word", [
    (["--illuminant", "D50"], "illuminant"),
    (["--illuminant", "blackbody:0"], "temperature"),
    (["--angles", "0,90"], "--angles"),
    (["--angles", "0:x"], "--angles"),
    (["--polarization", "circular"], "polarizations"),
    (["--observer", "5"], "--observer"),
])


def test_cli_bad_input_is_one_line(extra, word, capsys):
    assert tf_main.main(ARGS + extra) == 2
    err = [l for l in capsys.readouterr().err.splitlines() if l.strip()]
    assert len(err) == 1 and "error:" in err[0] and word in err[0], err


def test_cli_figure_opens(tmp_path, capsys):
    import matplotlib.image

    fig = tmp_path / "sub" / "colour.png"
    assert tf_main.main(ARGS + ["--plot", str(fig), "--illuminant", "blackbody:2856"]) == 0
    assert str(fig) in capsys.readouterr().err
    img = matplotlib.image.imread(fig)
    assert img.shape[0] > 500 and img.shape[1] > 1000 and img.shape[2] in (3, 4)
    rgb = img[..., :3]
    # not blank: many pixels differ from the white background, in more than one colour
    assert (rgb.min(axis=-1) < 0.9).mean() > 0.02
    assert len(np.unique((rgb * 255).astype(np.uint8).reshape(-1, 3), axis=0)) > 50


def test_parse_angles_ranges():
    np.testing.assert_array_equal(tf_main.parse_angles("0:80:10"), np.arange(0, 81, 10.0))
    np.testing.assert_array_equal(tf_main.parse_angles("0, 30 60"), [0.0, 30.0, 60.0])
    np.testing.assert_array_equal(tf_main.parse_angles("90"), [90.0])  # spectrum allows grazing
    from thinfilm_mi.errors import UsageError

    with pytest.raises(UsageError, match=r"--angles.*\[0, 90\)"):
        tf_main.parse_angles("90", below_90=True)


def test_delta_e2000_equals_colour_science():
    """The package's one CIEDE2000 of plain numbers against colour-science's on many
    random L*a*b* pairs: near and far (every hue branch), achromatic (a = b = 0, where the
    hue is undefined) and identical pairs. The tolerance: the same closed form in float64
    (measured bit-identical with colour-science 0.4.7); 1e-10 allows a few ulp of terms up
    to ~250 should another colour-science release order the operations differently, and is
    far below any ΔE2000 the package compares with (≥ 0.01). Not compared: hues exactly
    opposite (|Δh'| = 180°, e.g. integer Lab), where the formula's mean hue jumps by 180°
    and the last bit of ``arctan2`` (which differs between numpy's strided and contiguous
    loops) picks the branch, in colour-science as here."""
    rng = np.random.default_rng(11)
    n = 20000
    A = np.column_stack([rng.uniform(0, 100, n), rng.uniform(-128, 128, n), rng.uniform(-128, 128, n)])
    grey = A * np.array([1.0, 0.0, 0.0])
    pairs = [(A, A + rng.normal(0, 3, A.shape)), (A, A[::-1]), (grey, grey[::-1]), (A, grey), (A, A)]
    for X, Y in pairs:
        np.testing.assert_allclose(delta_e2000(X, Y), colour.delta_E(X, Y, method="CIE 2000"), rtol=0, atol=1e-10)
    assert delta_e2000(A[:7].reshape(7, 1, 3), A[:7]).shape == (7, 7)       # broadcasts as numpy does


def test_channel_sets_registry():
    """colour.cie.CHANNELS: the mono weights are the luminance Y of the rgb ones (the Y row
    of the inverse of the XYZ -> linear sRGB matrix applied to them); an unknown set is named."""
    import mitsuba as mi

    from thinfilm_mi.colour import cie

    if mi.variant() is None:            # the matrix comes from Mitsuba (any variant)
        mi.set_variant("scalar_rgb")
    assert list(cie.CHANNELS) == ["rgb", "mono"]
    wl = np.linspace(360.0, 830.0, 235)
    rgb, mono = cie.channel_weights("rgb", wl), cie.channel_weights(cie.CHANNELS["mono"], wl)
    assert rgb.shape == (3, wl.size) and mono.shape == (1, wl.size)
    y_row = np.linalg.inv(cie.xyz_to_srgb_matrix())[1]
    # a float64 3x3 inverse and product: agreement to rounding of terms up to ~1.1
    np.testing.assert_allclose(y_row @ rgb, mono[0], rtol=0, atol=1e-12)
    with pytest.raises(ThinFilmError, match="channels: expected one of rgb, mono, got 'xyz'"):
        cie.channel_weights("xyz", wl)
