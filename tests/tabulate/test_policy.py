"""The ``tabulate`` policy's prose values come from its constants (thinfilm_mi/tabulate/policy.py)."""
from __future__ import annotations

import pytest

from thinfilm_mi.tabulate import policy


def test_prose_values_are_the_constants():
    values = policy.prose_values()
    assert 2 ** int(values["AUTO_MAX_TEXELS"].split("^")[1]) == policy.AUTO_MAX_TEXELS
    assert 2 ** int(values["MAX_TEXELS"].split("^")[1]) == policy.MAX_TEXELS
    assert float(values["LINEAR_MAX_MIB"]) * 2 ** 20 == 4 * policy.LINEAR_MAX_FLOATS   # float32
    assert int(values["RT_AUTO_MIN_FILMS"]) == policy.RT_AUTO_MIN_FILMS
    assert float(values["REQUESTED_BUDGET_SCALE"]) == policy.REQUESTED_BUDGET_SCALE


def test_fill_replaces_placeholders_and_refuses_unknown_names():
    assert policy.fill("from {policy.MUELLER_AUTO_MIN_FILMS} films, {x}") == \
        f"from {policy.MUELLER_AUTO_MIN_FILMS} films, {{x}}"
    with pytest.raises(KeyError, match=r"\{policy.NO_SUCH\}"):
        policy.fill("{policy.NO_SUCH}")


def test_a_size_that_is_no_power_of_two_is_refused(monkeypatch):
    monkeypatch.setattr(policy, "AUTO_MAX_TEXELS", 3 << 18)
    with pytest.raises(ValueError, match=str(3 << 18)):
        policy.prose_values()
