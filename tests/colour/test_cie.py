"""CIE colorimetry (thinfilm_mi/colour/cie.py) against colour-science: the colour
weights (as ``scripts/make_colour_weights.py`` makes them) and the package's one
CIEDE2000 of plain numbers."""
from __future__ import annotations

import numpy as np
import pytest

from tests.support import ROOT
from thinfilm_mi.colour import cie


def test_colour_weights_match_colour_science():
    colour = pytest.importorskip("colour")
    import importlib.util
    path = ROOT / "scripts" / "make_colour_weights.py"
    spec = importlib.util.spec_from_file_location("make_colour_weights", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    # the CSV holds 8 significant digits
    np.testing.assert_allclose(cie.colour_weights(), mod.weights(), rtol=1e-7, atol=1e-12)
    assert colour is not None


def test_delta_e2000_matches_colour_science():
    colour = pytest.importorskip("colour")
    rng = np.random.default_rng(3)
    lab1 = rng.uniform([0, -80, -80], [100, 80, 80], (500, 3))
    lab2 = lab1 + rng.normal(0.0, 3.0, (500, 3))
    ours = cie.delta_e2000(lab1, lab2)
    np.testing.assert_allclose(ours, colour.delta_E(lab1, lab2, method="CIE 2000"),
                               rtol=1e-9, atol=1e-9)



colour = pytest.importorskip("colour")

from thinfilm_mi.colour.cie import delta_e2000  # noqa: E402
from thinfilm_mi.errors import ThinFilmError

# colour-science warns when sd_to_XYZ aligns a table to the requested shape (here on purpose)
pytestmark = [pytest.mark.filterwarnings("ignore::colour.utilities.ColourRuntimeWarning"),
              pytest.mark.usefixtures("llvm")]


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
