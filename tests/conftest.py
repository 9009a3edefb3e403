"""Suite-wide settings.

The table store on disk (:mod:`thinfilm_mi.tabulate.store`) is turned off for the
suite: tests that count builds or read build reports must see this process's builds,
whatever earlier runs left in ``~/.cache``. ``tests/test_table_store.py`` turns it on
in a temporary directory.
"""
import os

os.environ["THINFILM_MI_TABLE_CACHE"] = "off"
