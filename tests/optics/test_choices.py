"""optics.choices.choose: the one lookup of every registry of options."""
from __future__ import annotations

import pytest

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.choices import choose

REGISTRY = {"front": 1, "back": 2, "Lab": 3}


def test_names_case_insensitive_and_stripped():
    assert choose(REGISTRY, "front", "side") == 1
    assert choose(REGISTRY, "  BACK ", "side") == 2
    assert choose(REGISTRY, "lab", "space") == 3


def test_aliases_are_lower_case_spellings_of_names():
    assert choose(REGISTRY, "Rear", "side", {"rear": "back"}) == 2
    with pytest.raises(ThinFilmError):
        choose(REGISTRY, "rear", "side", {"other": "back"})


def test_error_names_parameter_value_and_choices():
    with pytest.raises(ThinFilmError) as info:
        choose(REGISTRY, "top", "side")
    assert str(info.value) == "side: expected one of front, back, Lab, got 'top'"
    assert isinstance(info.value, ValueError)
    # not a string: its repr is named
    with pytest.raises(ThinFilmError, match=r"got 5$"):
        choose(REGISTRY, 5, "side")
