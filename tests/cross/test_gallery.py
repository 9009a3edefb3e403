"""The plugin gallery: every plugin page's row of pictures is of its scene as it stands.

``scripts/make_gallery.py`` renders ``scenes/gallery/<plugin>.xml`` once per picture of the
plugin's row and records, in ``docs/plugins/gallery/manifest.json``, a digest of the scene's
texts, the plugin's doc block and the settings; the pages show the rows
(``docs/_ext/thinfilm_plugins.py``). Here, without rendering: every plugin has a row, the
manifest holds the pictures the script defines, each PNG is the one recorded and small, and
each digest is today's (a scene, include or doc block edited after its pictures were made
fails, naming the command that renders them again); and every gallery scene loads at every
picture's parameters (a 4x4 film, no render: ~2 s in all).
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import sys

import pytest

from tests.support import ROOT

_spec = importlib.util.spec_from_file_location("make_gallery", ROOT / "scripts" / "make_gallery.py")
gallery = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = gallery   # its dataclass looks its module up
_spec.loader.exec_module(gallery)

PLUGINS = sorted(p.stem for p in (ROOT / "thinfilm_mi" / "plugins").glob("thinfilm_*.py"))
#: the largest stored picture (a 160x120 render with a 256-colour palette is 12-20 kB)
MAX_PICTURE_KB = 40
#: all pictures together: a guard against bloat, not a target (31 pictures take ~0.55 MB)
MAX_GALLERY_KB = 1024


def _manifest() -> dict:
    return json.loads(gallery.MANIFEST.read_text(encoding="utf-8"))


def _regenerate(plugin: str) -> str:
    return f"{gallery.COMMAND} --only {plugin}"


def test_every_plugin_has_a_row_and_a_scene():
    assert sorted(gallery.GALLERY) == PLUGINS
    assert sorted(_manifest()) == PLUGINS, f"the manifest's rows: run {gallery.COMMAND}"
    assert sorted(p.stem for p in gallery.SCENES.glob("*.xml")) == PLUGINS


@pytest.mark.parametrize("plugin", PLUGINS)
def test_pictures_are_of_the_scene_and_doc_block_as_they_stand(plugin):
    entries = _manifest()[plugin]
    pictures = gallery.GALLERY[plugin]
    assert [e["png"] for e in entries] == [f"{plugin}-{p.name}.png" for p in pictures], (
        f"{plugin}: the row changed in the script: run {_regenerate(plugin)}")
    for entry, picture in zip(entries, pictures):
        settings = {k: entry[k] for k in gallery.SETTINGS}
        assert settings == gallery.SETTINGS and entry["label"] == picture.label, (
            f"{entry['png']}: rendered with other settings: run {_regenerate(plugin)}")
        assert picture.params.items() <= entry["params"].items(), (
            f"{entry['png']}: rendered with {entry['params']}, the script sets {picture.params}: "
            f"run {_regenerate(plugin)}")
        assert entry["digest"] == gallery.digest(plugin, entry["params"]), (
            f"{entry['png']} is older than {entry['scene']} (or its includes) or the doc block of "
            f"thinfilm_mi/plugins/{plugin}.py: run {_regenerate(plugin)}")
        data = (gallery.OUT / entry["png"]).read_bytes()
        assert hashlib.sha256(data).hexdigest() == entry["png_sha256"], (
            f"{entry['png']} is not the picture the script stored: run {_regenerate(plugin)}")
        assert len(data) <= MAX_PICTURE_KB * 1024, (entry["png"], len(data))


def test_the_gallery_stays_small_and_holds_no_stray_picture():
    listed = {e["png"] for row in _manifest().values() for e in row}
    stored = {p.name for p in gallery.OUT.glob("*.png")}
    assert stored == listed, f"pictures not in the manifest: {sorted(stored - listed)}"
    assert sum((gallery.OUT / n).stat().st_size for n in stored) <= MAX_GALLERY_KB * 1024


def test_an_edited_scene_or_doc_block_changes_the_digest(monkeypatch):
    params = _manifest()["thinfilm_conductor"][0]["params"]
    before = gallery.digest("thinfilm_conductor", params)
    texts = gallery.scene_texts
    monkeypatch.setattr(gallery, "scene_texts", lambda scene: {
        k: v + ("<!-- edited -->" if k.endswith("stage.xml") else "") for k, v in texts(scene).items()})
    assert gallery.digest("thinfilm_conductor", params) != before   # an include counts
    monkeypatch.undo()
    monkeypatch.setattr(gallery, "doc_block", lambda plugin: "edited")
    assert gallery.digest("thinfilm_conductor", params) != before


@pytest.mark.parametrize("plugin", PLUGINS)
def test_each_page_shows_its_row_after_the_parameter_table(plugin):
    sys.path.insert(0, str(ROOT / "docs" / "_ext"))
    try:
        import thinfilm_plugins as ext
    finally:
        sys.path.pop(0)
    doc = ext.doc_block(ROOT / "thinfilm_mi" / "plugins" / f"{plugin}.py")
    lines = ext.with_gallery(doc).splitlines()
    at = lines.index(".. plugingallery::")
    table = lines.index(".. pluginparameters::")
    assert table < at and lines[at + 2:] == doc.splitlines()[at:], plugin   # inserted, nothing lost
    assert all(not line.strip() or line[:1].isspace() for line in lines[table + 1:at]), plugin
    assert lines[at + 2].strip() and not lines[at + 2][:1].isspace(), plugin   # the text after the table


def test_every_gallery_scene_loads_at_every_picture():
    import mitsuba as mi

    from thinfilm_mi.batch.scene import load_scene, setup_variant

    setup_variant("llvm_ad_spectral")
    for plugin, row in _manifest().items():
        for entry in row:
            scene = load_scene(ROOT / entry["scene"], entry["params"], size=(4, 4), spp=1)
            assert isinstance(scene, mi.Scene) and scene.shapes(), entry["png"]
