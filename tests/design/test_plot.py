"""design.plot: the figure of a design."""
from __future__ import annotations

import pytest

from thinfilm_mi.design import evaluate

pytest.importorskip("matplotlib")


def test_figure_with_a_colour_path_through_total_reflection():
    """Light from the substrate (n 1.52) into air is totally reflected beyond 41°: T and
    its XYZ are 0 there, and the chromaticity path of T over 0-85° has a gap, not a
    failure (it raised 'Axis limits cannot be NaN or Inf')."""
    targets = {"substrate": "1.52", "materials": ["1.38", "2.35"],
               "targets": [{"quantity": "colour", "angles": [0, 20], "xy": [0.3, 0.31], "tolerance": 0.01,
                            "of": "T", "side": "back"},
                           {"quantity": "R", "wavelengths": "450:650:50", "value": 0.05, "tolerance": 0.01}]}
    result = evaluate(targets, "1.38 90; 2.35 40")
    fig = result.figure()
    chroma = fig.axes[1]
    lo, hi = chroma.get_xlim()
    assert 0 < lo < hi < 1
    assert any(line.get_label().startswith("T under D65, from the substrate") for line in chroma.get_lines())
