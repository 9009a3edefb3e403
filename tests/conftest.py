"""Suite-wide settings: no table store, and no variant left behind by a test.

The table store on disk (:mod:`thinfilm_mi.tabulate.store`) is turned off for the
suite: tests that count builds or read build reports must see this process's builds,
whatever earlier runs left in ``~/.cache``. ``tests/test_table_store.py`` turns it on
in a temporary directory.
"""
import os

os.environ["THINFILM_MI_TABLE_CACHE"] = "off"


import mitsuba as mi  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _restore_variant():
    """A test that switches Mitsuba's variant leaves the next one the variant it found.

    Modules set their variant when imported (collection) or in module fixtures; a test
    that switched to, say, ``scalar_rgb`` without switching back left it for whatever test
    ran next in that process, which with pytest-xdist depends on how tests are spread
    over the workers (``tests/test_orennayar.py`` then failed with scalar ``mi.Float``)."""
    previous = mi.variant()
    yield
    if previous is not None and mi.variant() != previous:
        mi.set_variant(previous)
