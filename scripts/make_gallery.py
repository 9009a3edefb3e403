"""Render the plugin gallery: a row of small pictures on every plugin's reference page.

    python scripts/make_gallery.py [--only PLUGIN ...]

Each plugin has one parameterised scene, ``scenes/gallery/<plugin>.xml``, rendered once per
value of the parameter its row varies (:data:`GALLERY`) through the package's own loader
(:func:`thinfilm_mi.batch.scene.render_file`, what ``thinfilm-render`` runs), at the
:data:`SETTINGS` every picture shares. The pictures go to :data:`OUT` as 256-colour PNGs
(a few kB each), with ``manifest.json`` recording, per picture, its scene, parameters, size,
spp, variant, seed, label and :func:`digest`: the SHA-256 of the scene's text (with its
``<include>`` files), the plugin's doc block and those settings. The plugin pages show the
rows from the manifest (``docs/_ext/thinfilm_plugins.py``), and
``tests/cross/test_gallery.py`` fails when a picture's digest is no longer that of the scene
and doc block as they stand, naming the command that renders it again.

``--only`` renders the named plugins' rows and keeps the others' entries.
"""
from __future__ import annotations

import argparse
import hashlib
import io
import json
import re
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))   # this checkout's thinfilm_mi, wherever the script is run from
SCENES = REPO / "scenes" / "gallery"
OUT = REPO / "docs" / "plugins" / "gallery"
MANIFEST = OUT / "manifest.json"
PLUGINS = REPO / "thinfilm_mi" / "plugins"
COMMAND = "python scripts/make_gallery.py"

#: what every picture shares; part of each picture's digest
SETTINGS = {"size": [160, 120], "spp": 48, "variant": "llvm_ad_spectral", "seed": 0}
#: the black-body row's lamp luminance (linear, Mitsuba's normalisation): equal for every
#: temperature, so the pictures differ in colour only
BLACKBODY_LUMINANCE = 5.0
#: colours a stored picture keeps (an adaptive palette keeps a 160x120 render to ~15 kB)
PALETTE = 256

__all__ = ["Picture", "GALLERY", "SETTINGS", "COMMAND", "MANIFEST", "OUT", "SCENES",
           "digest", "doc_block", "scene_texts", "blackbody_scale", "render_row", "main"]


@dataclass(frozen=True)
class Picture:
    """One picture of a row: its file stem, caption label and the scene parameters it sets
    (``-D name=value``; :func:`params_of` adds those the script derives)."""

    name: str
    label: str
    params: dict = field(default_factory=dict)


def _bragg(pairs: int) -> str:
    """A quarter-wave TiO2/SiO2 mirror centred near 520 nm, ``2 * pairs`` films."""
    return "; ".join(["TiO2 55; SiO2 89"] * pairs)


#: plugin -> its row. thinfilm_coating's row gains a rough top (a fourth picture over the same
#: base with the top's ``alpha``) once the coating's top interface takes a roughness.
GALLERY: dict[str, list[Picture]] = {
    "thinfilm_conductor": [Picture(f"{t}nm", f"SiO2 {t} nm", {"thickness": str(t)})
                           for t in (100, 200, 300, 400, 500, 600)],
    "thinfilm_dielectric": [
        Picture("1film", "1 film: TiO2 100 nm", {"layers": "TiO2 100"}),
        Picture("3films", "3 films: TiO2 100, SiO2 170, TiO2 100", {"layers": "TiO2 100; SiO2 170; TiO2 100"}),
        Picture("30films", "30 films: (TiO2 55, SiO2 89) ×15, a Bragg mirror", {"layers": _bragg(15)}),
    ],
    "thinfilm_roughdielectric": [Picture(f"alpha{a}", f"α = {a}", {"alpha": a})
                                 for a in ("0.02", "0.1", "0.3", "0.6")],
    "thinfilm_roughconductor": [Picture(f"alpha{a}", f"α = {a}", {"alpha": a})
                                for a in ("0.02", "0.1", "0.3", "0.6")],
    "thinfilm_diffuse": [Picture(m, f'model "{m}"', {"model": m}) for m in ("exact", "single", "multiple")],
    "thinfilm_coating": [Picture(b, f"over {b}", {"base": b})
                         for b in ("diffuse", "roughconductor", "principled")],
    "thinfilm_blackbody": [Picture(f"{t}K", f"{t} K", {"temperature": str(t)})
                           for t in (1500, 2856, 4000, 6500, 10000)],
}


def blackbody_scale(temperature: float) -> float:
    """The ``scale`` that gives a black body at ``temperature`` the luminance
    :data:`BLACKBODY_LUMINANCE` (CIE ``ȳ``, Mitsuba's 1/106.75 normalisation); needs a variant set."""
    import numpy as np

    from thinfilm_mi.colour.cie import colour_weights
    from thinfilm_mi.plugins.thinfilm_blackbody import planck

    weights = colour_weights()
    lam, ybar = weights[:, 0], weights[:, 2]
    luminance = float(np.trapezoid(planck(lam, temperature) * ybar, lam)) / 106.75
    return BLACKBODY_LUMINANCE / luminance


def params_of(plugin: str, picture: Picture) -> dict[str, str]:
    """The scene parameters of a picture: its own, plus the black body's ``scale``."""
    params = dict(picture.params)
    if plugin == "thinfilm_blackbody":
        params["scale"] = f"{blackbody_scale(float(params['temperature'])):.4g}"
    return params


def doc_block(plugin: str) -> str:
    """The doc block of a plugin, as its reference page reads it (``docs/_ext/thinfilm_plugins.py``)."""
    sys.path.insert(0, str(REPO / "docs" / "_ext"))
    try:
        import thinfilm_plugins
    finally:
        sys.path.pop(0)
    return thinfilm_plugins.doc_block(PLUGINS / f"{plugin}.py")


def scene_texts(scene: Path) -> dict[str, str]:
    """The text of a scene file and of the files it ``<include>``\\ s (recursively), by path
    relative to the repository."""
    texts: dict[str, str] = {}
    todo = [scene]
    while todo:
        path = todo.pop()
        key = path.resolve().relative_to(REPO).as_posix()
        if key in texts:
            continue
        texts[key] = path.read_text(encoding="utf-8")
        todo += [SCENES / name for name in re.findall(r'<include\s+filename="([^"]+)"', texts[key])]
    return texts


def digest(plugin: str, params: dict[str, str], settings: dict = SETTINGS) -> str:
    """SHA-256 of what a picture depends on: the scene's texts, the plugin's doc block, the
    shared settings and the picture's parameters."""
    payload = {"scene": scene_texts(SCENES / f"{plugin}.xml"), "doc": doc_block(plugin),
               "settings": settings, "params": params,
               "script": {"blackbody_luminance": BLACKBODY_LUMINANCE, "palette": PALETTE}}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode("utf-8")).hexdigest()


def small_png(image, channels) -> bytes:
    """A clipped sRGB PNG of a linear image (the renderer's preview), with an adaptive palette."""
    from PIL import Image

    from thinfilm_mi.batch import exr

    with tempfile.TemporaryDirectory() as tmp:
        path = exr.write_png(Path(tmp) / "preview.png", image, channels)
        picture = Image.open(path).convert("RGB")
        picture.load()
    out = io.BytesIO()
    picture.quantize(colors=PALETTE, method=Image.Quantize.MEDIANCUT).save(out, format="PNG", optimize=True)
    return out.getvalue()


def render_row(plugin: str) -> list[dict]:
    """Render a plugin's row into :data:`OUT`; its manifest entries."""
    from thinfilm_mi.batch.scene import render_file

    scene = SCENES / f"{plugin}.xml"
    entries = []
    with tempfile.TemporaryDirectory() as tmp:
        for picture in GALLERY[plugin]:
            params = params_of(plugin, picture)
            result = render_file(scene, Path(tmp) / "render.exr", spp=SETTINGS["spp"],
                                 size=tuple(SETTINGS["size"]), variant=SETTINGS["variant"],
                                 params=params, seed=SETTINGS["seed"])
            data = small_png(result.image, result.channels)
            png = f"{plugin}-{picture.name}.png"
            (OUT / png).write_bytes(data)
            entries.append({"png": png, "label": picture.label,
                            "scene": scene.relative_to(REPO).as_posix(), "params": params,
                            **SETTINGS, "digest": digest(plugin, params),
                            "png_sha256": hashlib.sha256(data).hexdigest()})
            print(f"{png}: {result.render_time:.1f} s, {len(data) / 1024:.0f} kB", flush=True)
    return entries


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=sorted(GALLERY), metavar="PLUGIN",
                        help="render only these plugins' rows (the others' entries are kept)")
    args = parser.parse_args(argv)
    from thinfilm_mi.batch.scene import setup_variant

    setup_variant(SETTINGS["variant"])   # the black body's scale reads its plugin module
    OUT.mkdir(parents=True, exist_ok=True)
    manifest = json.loads(MANIFEST.read_text(encoding="utf-8")) if MANIFEST.is_file() else {}
    start = time.perf_counter()
    for plugin in args.only or sorted(GALLERY):
        for old in OUT.glob(f"{plugin}-*.png"):
            old.unlink()
        manifest[plugin] = render_row(plugin)
    manifest = {p: manifest[p] for p in sorted(manifest) if p in GALLERY}
    MANIFEST.write_text(json.dumps(manifest, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"{MANIFEST.relative_to(REPO)}: {sum(map(len, manifest.values()))} pictures "
          f"in {time.perf_counter() - start:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
