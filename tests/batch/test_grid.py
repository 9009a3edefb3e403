"""Sweep grids (thinfilm_mi/batch/grid.py): values, ranges, lists and their errors; axes
names and values checked."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("distributed")


from tests.support.sweep import THICKNESS
from thinfilm_mi.batch import grid  # noqa: E402
from thinfilm_mi.errors import UsageError  # noqa: E402

# --------------------------------------------------------------------------------------
# the grid, without a cluster


def test_values_ranges_lists_and_errors():
    assert grid.parse_values("100:800:25") == tuple(str(v) for v in range(100, 801, 25))
    assert grid.parse_values("100:180:25") == ("100", "125", "150", "175")  # STOP off the grid
    assert grid.parse_values("0.1:0.5:0.1") == ("0.1", "0.2", "0.3", "0.4", "0.5")  # no float noise
    assert grid.parse_values("3:1:-1") == ("3", "2", "1")
    assert grid.parse_values(" Au, Ag ,Cu") == ("Au", "Ag", "Cu")
    assert grid.parse_values("SiO2 500; Au 20") == ("SiO2 500; Au 20",)
    assert grid.parse_values(range(0, 30, 10)) == ("0", "10", "20")
    assert grid.parse_values(np.array([0.5, 1.0])) == ("0.5", "1")
    assert grid.parse_values(2.5) == ("2.5",)
    for bad, word in [("100:800", "START:STOP:STEP"), ("1:5:0", "STEP"), ("5:1:1", "STEP"),
                      ("1,,2", "empty"), ("", "no value"), ("1,2,1", "repeated"),
                      ("0:1e9:1", "more than"), ([], "no value"), (object(), "expected")]:
        with pytest.raises(UsageError, match=word):
            grid.parse_values(bad, "-D x=")


def test_axes_names_and_values_are_checked():
    with pytest.raises(UsageError, match="not a valid parameter name"):
        grid.parse_axes(["2x=1"], "define")
    with pytest.raises(UsageError, match="expected name=VALUES"):
        grid.parse_axes(["thickness"], "define")
    with pytest.raises(UsageError, match="given twice"):
        grid.parse_axes(["a=1", "a=2"], "define")
    with pytest.raises(UsageError, match="must be numbers"):
        grid.parse_axes({THICKNESS: "thick"}, "traverse")
    with pytest.raises(UsageError, match="clash"):
        grid.build_frames(grid.parse_axes(["status=1,2"], "define"))


def test_axis_kinds_registry():
    """-D and -P axes are the AxisKind objects of grid.AXIS_KINDS; parse_axes takes the
    object or its name, and the frames sort the axes' values by it."""
    assert list(grid.AXIS_KINDS) == ["define", "traverse"]
    assert [k.flag for k in grid.AXIS_KINDS.values()] == ["-D", "-P"]
    assert grid.parse_axes(["a=1,2"], grid.DEFINE) == grid.parse_axes(["a=1,2"], "define")
    assert grid.parse_axes([f"{THICKNESS}=1"], "traverse")[0].kind is grid.TRAVERSE
    with pytest.raises(UsageError, match=r"-P 'x': expected name=VALUES, e.g. -P teapot\.bsdf"):
        grid.parse_axes(["x"], grid.TRAVERSE)
    with pytest.raises(ValueError, match="kind: expected one of define, traverse, got 'other'"):
        grid.parse_axes(["a=1"], "other")
    frame = grid.build_frames(grid.parse_axes(["a=1"], grid.DEFINE) + grid.parse_axes(["b.c=2"], grid.TRAVERSE))[0]
    assert (frame.defines, frame.traverse) == ((("a", "1"),), (("b.c", "2"),))
