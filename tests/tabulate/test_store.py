"""The table store on disk (``thinfilm_mi.tabulate.store``): built tables kept between
processes.

* A band-limited table built in one process is read by the next (a subprocess here),
  and a table from the store gives the same image as the one built, bit for bit
  (1 spp, box filter, the same seed).
* A stack found not tabulable is stored too (the next process skips the build).
* ``thinfilm_diffuse``'s factor table (``FactorTable``) likewise: its buffers and
  layout read back bit for bit, the same image; a damaged file is rebuilt.
* Damaged files, files from other code, an unwritable directory and ``off`` never
  raise: a damaged file is removed and the table rebuilt.
* The store is bounded: the least recently used files go first.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import mitsuba as mi
import numpy as np
import pytest

import thinfilm_mi  # noqa: F401  (registers the plugins)
from tests.support.stacks import benchmark_layers, sphere_scene
from thinfilm_mi.render import stack_build
from thinfilm_mi.tabulate import store


@pytest.fixture(autouse=True)
def _variant():
    mi.set_variant("llvm_ad_spectral")
    import thinfilm_mi  # noqa: F401,F811
    yield


@pytest.fixture
def tables(tmp_path, monkeypatch):
    """The store on, in a temporary directory, and this process's cache empty."""
    path = tmp_path / "tables"
    monkeypatch.setenv(store.ENVIRONMENT, str(path))
    stack_build.TABLE_CACHE.clear()
    yield path
    stack_build.TABLE_CACHE.clear()


BSDF = {"type": "thinfilm_conductor", "material": "Al", "layers": benchmark_layers(10)}


def _values(bsdf) -> np.ndarray:
    return np.array(bsdf.stack.plan[False].table.texture.tensor())


def test_a_stored_table_is_read_back_bit_for_bit_and_renders_the_same_image(tables):
    built = mi.load_dict(sphere_scene(BSDF))
    first = built.shapes()[0].bsdf()
    assert first.stack.plan[False].build_report["result"] == "table"
    assert first.stack.plan[False].build_report["resolution"] == 1.0     # band-limited
    assert len(list(tables.glob("*.npz"))) == 1
    image = np.array(mi.render(built, seed=3))

    stack_build.TABLE_CACHE.clear()
    again = mi.load_dict(sphere_scene(BSDF))
    second = again.shapes()[0].bsdf()
    report = second.stack.plan[False].build_report
    assert report["result"] == "from the table store"
    assert report["build"]["result"] == "table" and report["build"]["points"] > 0
    np.testing.assert_array_equal(_values(second), _values(first))
    assert second.stack.plan[False].table.error == first.stack.plan[False].table.error
    np.testing.assert_array_equal(np.array(mi.render(again, seed=3)), image)


def test_a_later_process_reads_the_table(tables):
    """The store's point: a new process (the same code) does not build again."""
    mi.load_dict(BSDF)
    code = textwrap.dedent(f"""
        import json, mitsuba as mi
        mi.set_variant("llvm_ad_spectral")
        import thinfilm_mi
        b = mi.load_dict({BSDF!r})
        print(json.dumps(b.stack.plan[False].build_report["result"]))
    """)
    env = dict(os.environ, **{store.ENVIRONMENT: str(tables)})
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == "from the table store"


def test_a_stack_found_not_tabulable_is_stored_too(tables):
    """Exact values only (``spectral_resolution`` 0): the 10-film stack's probe (5.6e4
    evaluations) rejects it; the next load takes the verdict from the store."""
    d = dict(BSDF, spectral_resolution=0.0)
    b = mi.load_dict(d)
    assert b.stack.mode() == "exact"
    assert b.stack.plan[False].build_report["result"] == "rejected by the probe"
    stack_build.TABLE_CACHE.clear()
    b = mi.load_dict(d)
    report = b.stack.plan[False].build_report
    assert b.stack.mode() == "exact"
    assert report["result"] == "from the table store"
    assert report["build"]["result"] == "rejected by the probe"


def test_cheap_builds_are_not_stored(tables):
    b = mi.load_dict({"type": "thinfilm_conductor", "material": "Al", "layers": "1.46 120; 2.3 80"})
    assert b.stack.mode() == "table"
    assert b.stack.plan[False].build_report["points"] < stack_build.STORE_MIN_POINTS
    assert not tables.exists() or not list(tables.glob("*.npz"))


@pytest.mark.parametrize("damage", ["garbage", "truncated", "wrong shape", "nan",
                                    "unknown interpolation", "resampling not the shape's"])
def test_a_damaged_file_is_removed_and_the_table_rebuilt(tables, damage):
    mi.load_dict(BSDF)
    (path,) = tables.glob("*.npz")
    if damage == "garbage":
        path.write_bytes(b"not a table")
    elif damage == "truncated":
        path.write_bytes(path.read_bytes()[:1000])
    else:
        with np.load(path) as f:
            values, meta = np.array(f["values"]), np.array(f["meta"])
        plain = json.loads(bytes(meta).decode())
        assert plain["interpolation"] == "linear"     # the 10-film table is read bilinearly
        if damage == "wrong shape":
            values = values[:, :, :0]
        elif damage == "nan":
            values = np.where(values > 0.5, np.nan, values)
        elif damage == "unknown interpolation":
            plain["interpolation"] = "nearest"
        else:   # factors whose fine grid the values are not
            plain["resampling"] = [plain["resampling"][0] + 1, plain["resampling"][1]]
        meta = np.frombuffer(json.dumps(plain).encode(), dtype=np.uint8)
        with open(path, "wb") as fh:
            np.savez(fh, values=values.astype(np.float32), meta=meta)
    stack_build.TABLE_CACHE.clear()
    b = mi.load_dict(BSDF)
    assert b.stack.plan[False].build_report["result"] == "table"     # built again
    (path,) = tables.glob("*.npz")                                    # and stored again
    stack_build.TABLE_CACHE.clear()
    assert mi.load_dict(BSDF).stack.plan[False].build_report["result"] == "from the table store"


def test_tables_of_other_code_are_not_read(tables, monkeypatch):
    mi.load_dict(BSDF)
    stack_build.TABLE_CACHE.clear()
    monkeypatch.setattr(store, "code_fingerprint", lambda: "other code")
    assert mi.load_dict(BSDF).stack.plan[False].build_report["result"] == "table"
    assert len(list(tables.glob("*.npz"))) == 2


@pytest.mark.parametrize("setting", ["off", "0", "", "OFF"])
def test_off_turns_the_store_off(monkeypatch, setting):
    monkeypatch.setenv(store.ENVIRONMENT, setting)
    assert store.default_store() is None


def test_the_default_directory_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv(store.ENVIRONMENT, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert store.default_store().directory == tmp_path / "thinfilm-mi" / "tables"


def test_an_unwritable_store_is_skipped(tmp_path, monkeypatch):
    blocker = tmp_path / "a file"
    blocker.write_text("not a directory")
    monkeypatch.setenv(store.ENVIRONMENT, str(blocker / "tables"))
    stack_build.TABLE_CACHE.clear()
    b = mi.load_dict(BSDF)
    assert b.stack.plan[False].build_report["result"] == "table"
    stack_build.TABLE_CACHE.clear()


def test_the_store_is_bounded_least_recently_used_first(tmp_path):
    s = store.TableStore(tmp_path, max_bytes=3000)
    report = {"result": "rejected by the probe", "points": 1}
    seen = set()
    for i in range(12):       # each file ~500 bytes; used at times 1000, 1001, ...
        s.put(f"key {i}", None, report)
        (new,) = set(tmp_path.glob("*.npz")) - seen
        os.utime(new, (1000 + i, 1000 + i))
        seen = set(tmp_path.glob("*.npz"))
    assert sum(p.stat().st_size for p in tmp_path.glob("*.npz")) <= 3000
    assert s.get("key 11")[0]           # the newest stays
    assert not s.get("key 0")[0]        # the oldest went


DIFFUSE = {"type": "thinfilm_diffuse", "layers": "SiO2 500; Au 5"}


def _factor_buffers(bsdf) -> dict:
    return bsdf.coated.table.arrays()


def test_a_stored_factor_table_is_read_back_bit_for_bit_and_renders_the_same_image(tables):
    """``thinfilm_diffuse``'s factor table (5.4e5 evaluations, 0.09 s): stored at its
    build, read back by a load with an empty cache (as a fresh process would), its
    buffers and layout bit for bit, and the same image (1 spp, box filter, one seed)."""
    built = mi.load_dict(sphere_scene(DIFFUSE))
    first = built.shapes()[0].bsdf()
    assert first.coated.table.report["result"] == "table"
    assert first.coated.table.report["points"] >= stack_build.STORE_MIN_POINTS
    assert len(list(tables.glob("*.npz"))) == 1
    image = np.array(mi.render(built, seed=3))

    stack_build.TABLE_CACHE.clear()
    again = mi.load_dict(sphere_scene(DIFFUSE))
    second = again.shapes()[0].bsdf()
    report = second.coated.table.report
    assert report["result"] == "from the table store"
    assert report["build"]["result"] == "table" and report["build"]["points"] > 0
    assert second.coated.table.layout() == first.coated.table.layout()
    for name, values in _factor_buffers(first).items():
        np.testing.assert_array_equal(_factor_buffers(second)[name], values)
    np.testing.assert_array_equal(np.array(mi.render(again, seed=3)), image)


@pytest.mark.parametrize("damage", ["nan", "short buffer", "wrong layout", "not a layout"])
def test_a_damaged_factor_table_file_is_removed_and_the_table_rebuilt(tables, damage):
    mi.load_dict(DIFFUSE)
    (path,) = tables.glob("*.npz")
    with np.load(path) as f:
        arrays = {k: np.array(f[k]) for k in f.files}
    meta = json.loads(bytes(arrays["meta"]).decode())
    if damage == "nan":
        arrays["transmittance"][7] = np.nan
    elif damage == "short buffer":
        arrays["reflectance"] = arrays["reflectance"][:-1]
    elif damage == "wrong layout":
        meta["factors"]["nu"] += 1
    else:
        meta["factors"] = "table"
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    stack_build.TABLE_CACHE.clear()
    assert mi.load_dict(DIFFUSE).coated.table.report["result"] == "table"      # built again
    stack_build.TABLE_CACHE.clear()
    assert mi.load_dict(DIFFUSE).coated.table.report["result"] == "from the table store"
