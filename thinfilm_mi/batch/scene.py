"""Loading and rendering a scene file: the library behind ``thinfilm-render``
(:mod:`thinfilm_mi.cli.render`) and the sweeps (:mod:`thinfilm_mi.batch.sweeps`).

:func:`render_file` does, in order:

1. ``params`` become the XML ``$name`` parameters (as
   ``mitsuba.load_file(path, name=value)``; ``-D name=value`` on the command
   line, :func:`parse_defines`); a name the scene does not declare is an
   error, as in Mitsuba.
2. For an ``llvm_*`` variant, :func:`thinfilm_mi.require_llvm` checks that
   Dr.Jit loaded an LLVM that can compile our kernels. A scene that needs a
   polarized variant (:data:`POLARIZED_PLUGINS`: Mitsuba's ``stokes``
   integrator, which unpolarized variants refuse, or a ``polarizer``,
   ``retarder`` or ``circular`` BSDF, which they reduce to neutral filters),
   found by parsing the file with its ``<include>`` files and parameters, is
   rendered in the polarized variant of the requested one's family
   (:func:`scene_variant`), said in one line on stderr. Then the variant is
   set and the thin-film plugins are registered (:func:`setup_variant`;
   registration follows later variant switches).
3. The scene is loaded (:func:`load_scene`) with Mitsuba's scene-graph parser
   (:mod:`mitsuba.parser`: ``parse_file`` -> edit -> ``transform_all`` ->
   ``instantiate``, which is what ``load_file`` does internally). Between
   parsing and instantiation ``size`` sets ``width``/``height`` of every
   film node (adding an ``hdrfilm`` to a sensor that has none, and dropping
   crop settings that would no longer fit) and ``spp`` sets
   ``sample_count`` of every sampler node. Editing the parsed graph works for
   any scene, whether or not it declares ``$resx``/``$resy``/``$spp``, and
   the sensor is built once with the final size (aspect ratio, field of
   view and crop window consistent), which is not guaranteed when a loaded
   film is resized afterwards through ``mi.traverse``.
4. The samples are rendered in passes (:func:`render_scene`:
   ``mi.render(scene, spp=k, seed=...)`` with a different seed per pass) and
   averaged, weighted by each pass's sample count, with a progress bar
   (:func:`progress_bar`). A pass holds at most ``max_pass_samples`` samples
   (image pixels x spp; default 2^22) so large renders do not build huge
   wavefronts.
5. The result is written as a linear float32 EXR (the film's channels; the
   header, :func:`output_attributes`, records the scene, variant, spp, seed,
   size, parameters and render time) and an 8-bit sRGB PNG preview beside it
   (clipped, no other tone mapping; :mod:`thinfilm_mi.batch.exr`).

Errors: :class:`~thinfilm_mi.errors.UsageError` for a bad scene, parameter or
machine set-up, :class:`~thinfilm_mi.errors.RenderFailure` for a failure while
rendering or writing; their messages are one line (:func:`one_line`). Nothing
here imports Dask or matplotlib.
"""
from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence, TextIO

import numpy as np
from tqdm import tqdm

from thinfilm_mi.batch import exr
from thinfilm_mi.errors import RenderError, RenderFailure, UsageError
from thinfilm_mi.render import gc_guard

#: the prefix of the messages a render prints on stderr (the console script's name)
PROG = "thinfilm-render"
DEFAULT_VARIANT = "llvm_ad_spectral"
#: folder of the outputs of :func:`render_file` when none is named
DEFAULT_OUT_DIR = "out"
#: samples (pixels x spp) rendered by one mi.render call at most
DEFAULT_MAX_PASS_SAMPLES = 1 << 22
#: largest film accepted by --size: 2^28 pixels (16384 x 16384) already need ~10 GiB
#: of film and image buffers in a spectral variant; 100000x100000 failed deep in
#: Mitsuba's film allocation with no message
MAX_PIXELS = 1 << 28
#: a render is split into at least this many passes (when spp allows)
MIN_PASSES = 8

__all__ = [
    "render_file", "render_scene", "load_scene", "RenderResult", "output_attributes",
    "default_output", "setup_llvm_only", "setup_variant", "scene_plugins", "scene_variant",
    "polarized_variant", "POLARIZED_PLUGINS", "parse_defines", "parse_size", "plan_passes",
    "pass_seed", "progress_bar", "one_line", "root_cause", "PROG", "DEFAULT_VARIANT",
    "DEFAULT_OUT_DIR", "DEFAULT_MAX_PASS_SAMPLES", "MAX_PIXELS", "MIN_PASSES",
]


# --------------------------------------------------------------------------------------
# messages

_CPP_LOCATION = re.compile(r"\[[\w.\-/\\]+\.(?:cpp|h|py):\d+\]\s*")


def one_line(message: str) -> str:
    """Condense an exception message (Mitsuba's, possibly holding a Python
    traceback from a plugin) into one readable line."""
    text = _CPP_LOCATION.sub("", str(message))
    marker = "Traceback (most recent call last):"
    if marker in text:
        head, _, tail = text.partition(marker)
        text = head + _exception_text(tail)
    text = re.sub(r"\s*\n\s*-\s*", " ", text)  # Mitsuba's "  - item" lists
    text = " ".join(text.split())
    return text or "unknown error"


def _exception_text(traceback_text: str) -> str:
    """The exception (type and whole message, which may span lines) that ends a
    formatted Python traceback: what follows its last ``File "..."`` frame line
    and that frame's source lines (indented by 4 spaces or more)."""
    lines = traceback_text.splitlines()
    frames = [i for i, line in enumerate(lines) if line.lstrip().startswith('File "')]
    start = frames[-1] + 1 if frames else 0
    while start < len(lines) and (lines[start].startswith("    ") or not lines[start].strip()):
        start += 1
    rest = [line.strip() for line in lines[start:] if line.strip()]
    if rest:
        return " ".join(rest)
    tail = [line.strip() for line in lines if line.strip()]
    return tail[-1] if tail else ""


def root_cause(e: BaseException) -> BaseException:
    """The innermost exception of a chain: Dr.Jit's custom operations (``mi.render``)
    wrap the real error in one that only says "(see above)"."""
    seen = set()
    while (e.__cause__ or e.__context__) is not None and id(e) not in seen:
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return e


# --------------------------------------------------------------------------------------
# parameters and sizes as text (-D name=value, --size WxH)


def parse_defines(items: Sequence[str] | None) -> dict[str, str]:
    """``["name=value", ...]`` -> ``{"name": "value"}``; names are XML parameter names."""
    params: dict[str, str] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep:
            raise UsageError(f"-D {item!r}: expected name=value, e.g. -D thickness=250")
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise UsageError(f"-D {item!r}: {name!r} is not a valid parameter name "
                             "(letters, digits and '_', not starting with a digit)")
        params[name] = value
    return params


def parse_size(text: str | None) -> tuple[int, int] | None:
    """``"WxH"`` -> ``(W, H)``, both positive integers."""
    if text is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX*,]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) <= 0 or int(m.group(2)) <= 0:
        raise UsageError(f"--size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. --size 640x480")
    w, h = int(m.group(1)), int(m.group(2))
    if w * h > MAX_PIXELS:
        raise UsageError(f"--size {text!r}: {w * h} pixels; at most {MAX_PIXELS} "
                         f"(e.g. {int(math.isqrt(MAX_PIXELS))}x{int(math.isqrt(MAX_PIXELS))})")
    return w, h


# --------------------------------------------------------------------------------------
# set-up and scene loading


def setup_llvm_only() -> None:
    """:func:`thinfilm_mi.require_llvm`, its :class:`~thinfilm_mi.LLVMVersionError`
    (which says how to fix the machine) turned into a one-line :class:`UsageError`."""
    from thinfilm_mi.llvm import LLVMVersionError, require_llvm

    try:
        require_llvm()
    except LLVMVersionError as e:
        raise UsageError(str(e)) from e


def setup_variant(variant: str) -> None:
    """Check LLVM (``llvm_*`` variants), set the Mitsuba variant and register the
    thin-film plugins for it."""
    from thinfilm_mi.plugins import register

    if variant.startswith("llvm_"):
        setup_llvm_only()

    import mitsuba as mi

    available = list(mi.variants())
    if variant not in available:
        raise UsageError(f"--variant {variant!r}: not available in this Mitsuba build; "
                         f"choose one of {', '.join(available)}")
    mi.set_variant(variant)
    register()


def _children(props, nodes) -> list[int]:
    """Indices of the nodes a node's properties refer to."""
    import mitsuba as mi

    out = []
    for key in props.keys():
        if props.type(key) == mi.Properties.Type.ResolvedReference:
            out.append(props[key].index())
    return out


def _apply_overrides(state, size: tuple[int, int] | None, spp: int | None,
                     log: Callable[[str], None]) -> None:
    """Set film size and sampler sample counts in a parsed (not yet
    transformed) scene graph."""
    import mitsuba as mi

    nodes = state.nodes
    if size is not None:
        width, height = size
        for i in range(len(nodes)):
            node = nodes[i]
            if node.type != mi.ObjectType.Sensor:
                continue
            films = [j for j in _children(node.props, nodes) if nodes[j].type == mi.ObjectType.Film]
            if films:
                continue
            film = mi.parser.SceneNode()
            film.type = mi.ObjectType.Film
            film.file_index = node.file_index
            film.offset = node.offset
            film.props.set_plugin_name("hdrfilm")
            nodes.append(film)
            node.props["film"] = mi.Properties.ResolvedReference(len(nodes) - 1)
            log(f"--size: sensor '{node.props.plugin_name()}' has no film; added an hdrfilm")
        for node in nodes:
            if node.type != mi.ObjectType.Film:
                continue
            props = node.props
            props["width"] = width
            props["height"] = height
            dropped = [k for k in ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height",
                                   "cropOffsetX", "cropOffsetY", "cropWidth", "cropHeight")
                       if k in props]
            for k in dropped:
                del props[k]
            if dropped:
                log(f"--size: removed the film's crop window ({', '.join(dropped)})")
    if spp is not None:
        for node in nodes:
            if node.type != mi.ObjectType.Sampler:
                continue
            for k in ("sample_count", "sampleCount"):
                if k in node.props:
                    del node.props[k]
            node.props["sample_count"] = int(spp)


@contextlib.contextmanager
def _files_beside(path: Path):
    """Like ``mi.load_file``: files named in the scene (includes, meshes, textures,
    data) are looked up next to the scene file first; the search path is restored after."""
    import mitsuba as mi

    resolver = mi.file_resolver()
    saved = [str(p) for p in resolver]
    resolver.prepend(str(path.resolve().parent))
    try:
        yield
    finally:
        resolver.clear()
        for p in saved:
            resolver.append(p)


#: Mitsuba plugins that act on polarization only, by (object type, plugin name): the
#: ``stokes`` integrator refuses unpolarized variants, and in them the polarizers and
#: retarders are neutral filters (what they do to the image is lost)
POLARIZED_PLUGINS = {
    ("Integrator", "stokes"): "the 'stokes' integrator",
    ("BSDF", "polarizer"): "a 'polarizer' BSDF",
    ("BSDF", "retarder"): "a 'retarder' BSDF",
    ("BSDF", "circular"): "a 'circular' polarizer BSDF",
}


def scene_plugins(path: str | os.PathLike, params: Mapping[str, str] | None = None,
                  variant: str = DEFAULT_VARIANT) -> list[tuple[str, str]]:
    """``(object type, plugin name)`` of every object a scene file declares, its
    ``<include>`` files and ``$name`` parameters resolved by Mitsuba's own parser
    (nothing is instantiated and no variant needs to be set). Raises what the
    parser raises for a malformed scene."""
    import mitsuba as mi

    path = Path(path)
    with _files_beside(path):
        state = mi.parser.parse_file(mi.parser.ParserConfig(variant), str(path),
                                     **dict(params or {}))
    return [(node.type.name, node.props.plugin_name()) for node in state.nodes]


def polarized_variant(variant: str, thin_films: bool = True,
                      available: Sequence[str] | None = None) -> str:
    """The polarized variant of ``variant``'s family: ``X_spectral`` ->
    ``X_spectral_polarized``; ``X_rgb``/``X_mono`` -> ``X_spectral_polarized``
    when the scene has thin-film plugins (they refuse polarized RGB/mono
    variants: a Mueller matrix integrated over wavelengths is not one built from
    integrated amplitudes), else ``X_rgb_polarized``/``X_mono_polarized`` where
    ``available`` has it. A polarized variant is returned unchanged."""
    m = re.fullmatch(r"(.+?)_(spectral|rgb|mono)(_polarized)?", variant)
    if m is None or m.group(3):
        return variant
    own = f"{m.group(1)}_{m.group(2)}_polarized"
    if not thin_films and (available is None or own in available):
        return own
    return f"{m.group(1)}_spectral_polarized"


def scene_variant(path: str | os.PathLike, params: Mapping[str, str] | None,
                  variant: str) -> tuple[str, str | None]:
    """The variant to render the scene file ``path`` in, and a one-line notice when
    it is not ``variant``: the polarized variant of its family
    (:func:`polarized_variant`) when the scene holds a plugin of
    :data:`POLARIZED_PLUGINS` and ``variant`` is not polarized. A scene that does
    not parse keeps ``variant`` (loading it then reports the error)."""
    import mitsuba as mi

    from thinfilm_mi.plugins import PLUGINS, TEXTURES

    available = list(mi.variants())
    if variant not in available or variant.endswith("_polarized"):
        return variant, None
    try:
        plugins = scene_plugins(path, params, variant)
    except Exception:  # noqa: BLE001 - load_scene reports it
        return variant, None
    needs = [POLARIZED_PLUGINS[p] for p in plugins if p in POLARIZED_PLUGINS]
    if not needs:
        return variant, None
    thin_films = any(name in PLUGINS or name in TEXTURES for _, name in plugins)
    target = polarized_variant(variant, thin_films, available)
    if target not in available:
        raise UsageError(f"{path} uses {needs[0]}, which needs a polarized variant, and "
                         f"{target} is not available in this Mitsuba build "
                         f"(choose one of {', '.join(v for v in available if 'polarized' in v)})")
    return target, (f"{path} uses {needs[0]}, which needs a polarized variant: "
                    f"rendering it in {target} instead of {variant}")


def load_scene(path: str | os.PathLike, params: Mapping[str, str] | None = None,
               size: tuple[int, int] | None = None, spp: int | None = None,
               variant: str | None = None, log: Callable[[str], None] | None = None):
    """Load a scene file with ``$name`` parameters and optional film size /
    sample count overrides (see the module docstring). The variant must be set."""
    import mitsuba as mi

    log = log or (lambda msg: None)
    path = Path(path)
    if not path.exists():
        raise UsageError(f"scene file not found: {path}")
    if not path.is_file():
        raise UsageError(f"scene file is not a file: {path}")
    config = mi.parser.ParserConfig(variant or mi.variant())
    try:
        with _files_beside(path), gc_guard.loading():   # not beside another thread's render
            state = mi.parser.parse_file(config, str(path), **dict(params or {}))
            _apply_overrides(state, size, spp, log)
            # our constructors one after the other, never one nested in another's kernel
            # wait on a loader thread (render/gc_guard.py)
            config.parallel = not gc_guard.parsed_names_ours(state)
            mi.parser.transform_all(config, state)
            scene = mi.parser.instantiate(config, state)
            if not config.parallel:
                gc_guard.after_serial_load()
    except RenderError:
        raise
    except Exception as e:  # Mitsuba reports parse, parameter and plugin errors as exceptions
        raise UsageError(f"cannot load scene {path}: {one_line(e)}") from e
    if not isinstance(scene, mi.Scene):
        raise UsageError(f"{path} describes a {type(scene).__name__}, not a <scene>")
    return scene


# --------------------------------------------------------------------------------------
# rendering


def plan_passes(spp: int, pixels: int, max_pass_samples: int = DEFAULT_MAX_PASS_SAMPLES,
                min_passes: int = MIN_PASSES) -> list[int]:
    """Samples per pixel of each pass: at least ``min(spp, min_passes)`` passes,
    none above ``max_pass_samples`` samples (when one spp fits), sizes
    differing by at most one, summing to ``spp``."""
    if spp < 1:
        raise UsageError(f"--spp must be >= 1, got {spp}")
    per_pass_cap = max(1, max_pass_samples // max(1, pixels))
    n = max(min(spp, min_passes), math.ceil(spp / per_pass_cap))
    base, extra = divmod(spp, n)
    return [base + 1] * extra + [base] * (n - extra)


def progress_bar(stream: TextIO | None, total: int, unit: str, desc: str = PROG, initial: int = 0):
    """The progress bar of renders and sweeps: a :class:`tqdm.tqdm` on ``stream``,
    redrawn in place, shown only when ``stream`` is a terminal (no bar at all when
    it is None). A log gets no bar; the command's summary line says the same."""
    return tqdm(total=total, unit=unit, desc=desc, initial=initial, file=stream,
                disable=True if stream is None else None, leave=True, dynamic_ncols=True)


def pass_seed(seed: int, index: int) -> int:
    """The seed of pass ``index``: distinct per pass and for nearby base seeds."""
    return (int(seed) * 0x9E3779B1 + index * 0x85EBCA77 + index) & 0xFFFFFFFF


@dataclass
class RenderResult:
    """What :func:`render_file` produced."""

    image: np.ndarray              # H x W x C, linear, float32
    channels: list[str]
    spp: int
    passes: int
    render_time: float             # seconds, rendering only
    load_time: float               # seconds, scene loading
    exr_path: Path | None = None
    png_path: Path | None = None
    attributes: dict[str, Any] = field(default_factory=dict)

    @property
    def size(self) -> tuple[int, int]:
        return int(self.image.shape[1]), int(self.image.shape[0])

    @property
    def samples_per_second(self) -> float:
        w, h = self.size
        return w * h * self.spp / self.render_time if self.render_time > 0 else float("inf")


def _film_channels(film, count: int) -> list[str]:
    try:
        names = [f.name for f in film.bitmap().struct_()]
    except Exception:  # no developed bitmap: fall back to generic names
        names = []
    if len(names) == count:
        return names
    if count == 3:
        return ["R", "G", "B"]
    if count == 4:
        return ["R", "G", "B", "A"]
    return [f"C{i}" for i in range(count)]


def render_scene(scene, spp: int, seed: int = 0, sensor: int = 0,
                 max_pass_samples: int = DEFAULT_MAX_PASS_SAMPLES,
                 progress: TextIO | None = None) -> tuple[np.ndarray, list[str], int, float]:
    """Render ``scene`` in passes; returns ``(image, channels, passes, seconds)``."""
    import drjit as dr
    import mitsuba as mi

    sensors = scene.sensors()
    if not 0 <= sensor < len(sensors):
        raise UsageError(f"--sensor {sensor}: the scene has {len(sensors)} sensor(s)")
    film = sensors[sensor].film()
    w, h = (int(v) for v in film.crop_size())
    plan = plan_passes(spp, w * h, max_pass_samples)
    accum = None
    done = 0
    t0 = time.perf_counter()
    with progress_bar(progress, total=spp, unit="spp") as bar:
        for i, k in enumerate(plan):
            img = mi.render(scene, spp=k, seed=pass_seed(seed, i), sensor=sensor)
            dr.eval(img)
            arr = np.array(img, dtype=np.float64)
            accum = arr * k if accum is None else accum + arr * k
            done += k
            bar.set_postfix_str(f"pass {i + 1}/{len(plan)}", refresh=False)
            bar.update(k)
    seconds = time.perf_counter() - t0
    image = (accum / done).astype(np.float32)
    if image.ndim == 2:
        image = image[:, :, None]
    return image, _film_channels(film, image.shape[2]), len(plan), seconds


def default_output(scene: str | os.PathLike, out_dir: str | os.PathLike = DEFAULT_OUT_DIR) -> Path:
    """``out_dir/<scene-stem>.exr``: where a render goes when no output is named."""
    return Path(out_dir) / (Path(scene).stem + ".exr")


def render_file(scene_path: str | os.PathLike, output: str | os.PathLike | None = None, *,
                spp: int | None = None, size: tuple[int, int] | None = None,
                variant: str = DEFAULT_VARIANT, params: Mapping[str, str] | None = None,
                seed: int = 0, sensor: int = 0,
                max_pass_samples: int = DEFAULT_MAX_PASS_SAMPLES,
                progress: TextIO | None = None, verbose: bool = False) -> RenderResult:
    """Load, render and write ``scene_path`` (the work of ``thinfilm-render``).

    ``output``: the EXR (default :func:`default_output`); the PNG preview goes
    beside it. ``progress``: the stream of the progress bar (:func:`progress_bar`),
    None for none. A change of variant (a polarized scene) is said on stderr;
    ``verbose`` adds the edits of ``size``/``spp`` and keeps Mitsuba's warnings.

    Raises :class:`UsageError` for a bad scene or parameter and
    :class:`RenderFailure` when rendering or writing fails.
    """
    if spp is not None and spp < 1:
        raise UsageError(f"--spp must be >= 1, got {spp}")
    if max_pass_samples < 1:
        raise UsageError(f"--max-pass-samples must be >= 1, got {max_pass_samples}")
    out = Path(output) if output is not None else default_output(scene_path)
    if out.suffix.lower() != ".exr":
        raise UsageError(f"-o {str(out)!r}: the output must be an .exr file")
    scene_file = Path(scene_path)
    if not scene_file.is_file():
        raise UsageError(f"scene file not found: {scene_file}")

    def log(msg: str) -> None:
        if verbose:
            print(f"{PROG}: {msg}", file=sys.stderr)

    if variant.startswith("llvm_"):
        setup_llvm_only()
    variant, notice = scene_variant(scene_file, params, variant)
    if notice:
        print(f"{PROG}: {notice}", file=sys.stderr)
    setup_variant(variant)
    import mitsuba as mi

    if not verbose:
        # Mitsuba logs warnings through its own logger; errors still arrive as exceptions.
        mi.set_log_level(mi.LogLevel.Error)
    t_load = time.perf_counter()
    scene = load_scene(scene_file, params, size=size, spp=spp, variant=variant, log=log)
    load_time = time.perf_counter() - t_load
    if not 0 <= sensor < len(scene.sensors()):
        raise UsageError(f"--sensor {sensor}: the scene has {len(scene.sensors())} sensor(s)")
    total_spp = int(spp) if spp is not None else int(scene.sensors()[sensor].sampler().sample_count())

    try:
        image, channels, passes, seconds = render_scene(
            scene, total_spp, seed=seed, sensor=sensor, max_pass_samples=max_pass_samples,
            progress=progress)
    except RenderError:
        raise
    except Exception as e:
        raise RenderFailure(f"rendering {scene_file} failed: {one_line(root_cause(e))}") from e

    attributes = output_attributes(scene_file, variant, total_spp, seconds, seed, passes, params)
    result = RenderResult(image=image, channels=channels, spp=total_spp, passes=passes,
                          render_time=seconds, load_time=load_time, attributes=attributes)
    try:
        result.exr_path = exr.write_exr(out, image, channels, attributes)
        result.png_path = exr.write_png(out.with_suffix(".png"), image, channels)
    except Exception as e:
        raise RenderFailure(f"writing {out} failed: {one_line(e)}") from e
    return result


def output_attributes(scene_file: str | os.PathLike, variant: str, spp: int, seconds: float,
                      seed: int, passes: int, params: Mapping[str, Any] | None) -> dict[str, Any]:
    """The EXR header attributes of a render (shared with ``thinfilm-render sweep``)."""
    import mitsuba as mi

    from thinfilm_mi.version import __version__

    return {
        "scene": str(Path(scene_file).resolve()),
        "variant": variant,
        "spp": int(spp),
        "renderTime": float(seconds),
        "seed": int(seed),
        "passes": int(passes),
        "parameters": " ".join(f"{k}={v}" for k, v in (params or {}).items()),
        "software": f"thinfilm-mi {__version__}, Mitsuba {mi.__version__}",
    }

