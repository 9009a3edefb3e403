"""Fixtures shared by the plugin test modules."""
import mitsuba as mi
import pytest

from tests.support.specular import VARIANTS


@pytest.fixture(params=VARIANTS)
def variant(request):
    """Each variant the specular plugins' checks run in (set for the test)."""
    mi.set_variant(request.param)
    return request.param
