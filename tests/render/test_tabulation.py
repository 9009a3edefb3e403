"""thinfilm_mi.render.tabulation: the ``tabulate`` option's objects, the route of a
stack, and the table cache's key (the table store on disk is keyed by it: its bytes
are checked against a SHA-1 written out here)."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

from thinfilm_mi.render import tabulation
from thinfilm_mi.tabulate import policy


def test_tabulate_values_and_their_options():
    """``"auto"``, ``true`` and ``false`` (as the plugins' properties give them) map to
    their options; anything else is refused with the value in the message."""
    assert tabulation.tabulate_option("auto") is tabulation.AUTO
    assert tabulation.tabulate_option(True) is tabulation.ALWAYS
    assert tabulation.tabulate_option(False) is tabulation.NEVER
    assert tabulation.tabulate_option(tabulation.AUTO) is tabulation.AUTO
    for bad in ("true", "yes", 1, None):
        with pytest.raises(ValueError, match=repr(bad)):
            tabulation.tabulate_option(bad)
    # what each option does: auto builds where a table pays, true always (more budget)
    assert (tabulation.AUTO.builds, tabulation.AUTO.selective, tabulation.AUTO.required) \
        == (True, True, False)
    assert (tabulation.ALWAYS.builds, tabulation.ALWAYS.required) == (True, True)
    assert tabulation.ALWAYS.budget_scale == policy.REQUESTED_BUDGET_SCALE
    assert not tabulation.NEVER.builds and not tabulation.NEVER.required


def test_route_of_the_sides():
    """Every side from a table, none, or some; the route equals its string."""
    assert tabulation.Route.of([True, True]) is tabulation.Route.TABLE == "table"
    assert tabulation.Route.of([]) is tabulation.Route.EXACT == "exact"
    assert tabulation.Route.of([False, False]) is tabulation.Route.EXACT
    assert tabulation.Route.of([True, False]) is tabulation.Route.MIXED == "mixed"
    assert str(tabulation.Route.MIXED) == "mixed"


def test_table_key_bytes():
    """The key hashes the media's values, then the films' (thickness, incoherent), then
    the settings, each as the cache has always hashed them: a stored table keeps its key."""
    media = [np.linspace(1.0, 2.0, 5), np.zeros(5)]
    films = [(None, 100.0, False), (None, 2.5e4, True)]
    settings = ("llvm_ad_spectral", False, False, False, 1e-3, 1.0, 1 << 19, 1.0, "powers")
    h = hashlib.sha1()
    for v in media:
        h.update(v.tobytes())
    h.update(repr([(100.0, False), (25000.0, True)]).encode())
    h.update(repr(settings).encode())
    key = tabulation.table_key(media, films, settings)
    assert key == h.hexdigest()
    assert tabulation.table_key(media, [(None, 101.0, False), films[1]], settings) != key
