"""Suite-wide settings: no table store, and no variant left behind by a test; and the
fixtures that test modules of several folders share.

The tests mirror the package (``tests/optics/`` tests ``thinfilm_mi/optics/`` and so on;
``tests/cross/`` holds the checks that cut across it); helpers they share live in
``tests/support/``.

The table store on disk (:mod:`thinfilm_mi.tabulate.store`) is turned off for the
suite: tests that count builds or read build reports must see this process's builds,
whatever earlier runs left in ``~/.cache``. ``tests/tabulate/test_store.py`` turns it on
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
    over the workers (``tests/render/test_orennayar.py`` then failed with scalar ``mi.Float``)."""
    previous = mi.variant()
    yield
    if previous is not None and mi.variant() != previous:
        mi.set_variant(previous)


@pytest.fixture
def llvm():
    """The test runs in ``llvm_ad_spectral`` (``_restore_variant`` puts back the one found)."""
    mi.set_variant("llvm_ad_spectral")


@pytest.fixture
def real_path_calls(monkeypatch):
    """Counts the calls of the real-amplitude loop (so a test knows it ran)."""
    from thinfilm_mi.optics import core as optics

    calls = []
    original = optics.stack_rt_loop_real

    def spy(*args, **kw):
        calls.append(kw.get("films_max"))
        return original(*args, **kw)
    monkeypatch.setattr(optics, "stack_rt_loop_real", spy)
    return calls


# The Dask sweeps (tests/batch/test_sweeps.py, tests/cli/test_sweep.py, tests/batch/test_worker.py):
# a scene file and a local cluster of two workers per module. (tests/cli/test_render.py
# has a `scene` of its own.)

@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """The sweeps' scene file (:data:`tests.support.sweep.SCENE`)."""
    from tests.support.sweep import SCENE

    path = tmp_path_factory.mktemp("sweep_scene") / "coated_sphere.xml"
    path.write_text(SCENE)
    return path


@pytest.fixture(scope="module")
def cluster():
    pytest.importorskip("distributed")
    from thinfilm_mi.batch import sweeps

    cluster = sweeps.local_cluster(2)
    yield cluster
    cluster.close(timeout=60)


@pytest.fixture
def client(cluster):
    from distributed import Client

    with Client(cluster, timeout="60s") as client:
        # a worker killed by an earlier test is restarted by its nanny: wait for it
        client.wait_for_workers(2, timeout=60)
        yield client
