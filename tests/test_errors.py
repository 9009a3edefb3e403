"""The plugin boundary (``errors.plugin_boundary``): a plugin's name joins an error once.

Through Mitsuba, every plugin constructor and parameter update is covered by
``tests/cross/test_bad_input.py`` and ``tests/cross/test_param_edits.py``.
"""
from __future__ import annotations

import pytest

from thinfilm_mi.errors import MaterialError, ThinFilmError, plugin_boundary


def test_the_name_is_put_in_front_once_and_the_exception_kept():
    error = MaterialError("'eta' must be finite, got nan")
    with pytest.raises(MaterialError) as err:
        with plugin_boundary("thinfilm_conductor"):
            with plugin_boundary("thinfilm_conductor"):   # a boundary inside another
                raise error
    assert err.value is error
    assert str(err.value) == "thinfilm_conductor: 'eta' must be finite, got nan"


@pytest.mark.parametrize("exc", [ThinFilmError("thinfilm_coating: 'x' is bad"), TypeError("'x' is bad")])
def test_a_named_message_is_left_and_a_type_error_named(exc):
    with pytest.raises(type(exc)) as err:
        with plugin_boundary("thinfilm_coating"):
            raise exc
    assert str(err.value) == "thinfilm_coating: 'x' is bad"


def test_other_exceptions_and_odd_arguments_pass_unchanged():
    with pytest.raises(RuntimeError, match=r"^kernel$"):
        with plugin_boundary("thinfilm_conductor"):
            raise RuntimeError("kernel")
    error = ValueError("a", 2)
    with pytest.raises(ValueError) as err:
        with plugin_boundary("thinfilm_conductor"):
            raise error
    assert err.value.args == ("a", 2)
