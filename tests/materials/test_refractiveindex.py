"""refractiveindex.info pages (thinfilm_mi/materials/refractiveindex.py): each DATA type of
``RII_DATA_TYPES`` gives its parts, an unknown or empty type names the entry."""
from __future__ import annotations

import pytest

from thinfilm_mi.errors import MaterialError
from thinfilm_mi.materials import sources


def test_rii_data_types(tmp_path):
    """Each DATA type of sources.RII_DATA_TYPES gives its parts: ``tabulated nk`` both n and k
    (the first entry that gives a part wins); an unknown or empty type names the entry."""
    nk = tmp_path / "nk.yml"
    nk.write_text("DATA:\n  - type: tabulated nk\n    data: |\n        0.4 1.5 0.1\n        0.8 1.7 0.3\n"
                  "  - type: tabulated k\n    data: |\n        0.4 9.0\n        0.8 9.0\n")
    mat = sources.load_file(nk)
    assert abs(mat.index(600.0) - (1.6 + 0.2j)) < 1e-12  # linear between the two rows
    for bad_type in ("''", "formula", "formula 2 3", "tabulated"):
        bad = tmp_path / "bad.yml"
        bad.write_text(f"DATA:\n  - type: {bad_type}\n    data: |\n        0.5 1.0\n")
        with pytest.raises(MaterialError, match=r"DATA\[0\].*unsupported data type"):
            sources.load_file(bad)
