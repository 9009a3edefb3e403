"""Reading the plugins' properties: the films (``layers`` or the one-film shorthand),
the thickness texture, ``tabulate`` and the table settings, ``ext_ior``, a conductor's
substrate (``material`` or ``eta`` + ``k``), and the check that no property was misspelt
(:func:`check_unqueried`). Every bad value raises :class:`~thinfilm_mi.errors.ThinFilmError`
naming the property and the value.
"""
from __future__ import annotations

import math

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import MAX_INDEX, MIN_INDEX
from thinfilm_mi.materials.stack import check_thickness, parse_layers
from thinfilm_mi.render.kernel import (
    DEFAULT_COHERENCE_THICKNESS,
    DEFAULT_SPECTRAL_RESOLUTION,
    DEFAULT_TABLE_ERROR,
    KernelStack,
)
from thinfilm_mi.render.media import DEFAULT_EXT_IOR, SpectralIndex, real_index
from thinfilm_mi.render.tabulation import TABULATE_OPTIONS
from thinfilm_mi.render.textures import check_texture_range, checked_texture, uniform

__all__ = ["MAX_SPECTRAL_RESOLUTION", "optional_texture", "films_from_props", "thickness_texture_from_props",
           "tabulate_from_props", "stack_from_props", "stack_options_from_props", "ext_ior_from_props",
           "substrate_from_props", "check_unqueried"]


def optional_texture(props, name: str, plugin: str):
    """The factor texture ``name`` of a plugin's properties (``specular_reflectance``,
    ``specular_transmittance``), or ``None`` if it was not given. Its values must be
    finite and >= 0 (a negative or infinite factor renders black or NaN)."""
    if name not in props:
        return None
    return checked_texture(props, name, plugin, "a number, a spectrum or a texture",
                           f"{plugin}: '{name}'", 0.0)


def films_from_props(props, plugin: str) -> list[tuple[SpectralIndex, float]]:
    """The film list of a plugin: ``layers`` or ``thin_film_ior`` + ``thin_film_thickness``."""
    has_layers = ("layers" in props)
    has_ior = ("thin_film_ior" in props)
    has_thk = ("thin_film_thickness" in props)
    if has_layers and (has_ior or has_thk):
        raise ThinFilmError(f"{plugin}: give either 'layers' or 'thin_film_ior' + "
                            "'thin_film_thickness', not both")
    if has_ior != has_thk:
        missing = "thin_film_thickness" if has_ior else "thin_film_ior"
        raise ThinFilmError(f"{plugin}: '{missing}' is missing (the single-film shorthand needs "
                            "both 'thin_film_ior' and 'thin_film_thickness')")
    if has_ior:
        spec = props.get("thin_film_ior")
        thk = check_thickness(props.get("thin_film_thickness"), "thin_film_thickness")
        return [(SpectralIndex.from_material(spec, "thin_film_ior"), thk)]
    text = props.get("layers", "")
    try:
        parsed = parse_layers(text)
    except ThinFilmError as e:
        raise ThinFilmError(f"{plugin}: {e}") from None
    return [(SpectralIndex.from_material(m, f"layers[{i}] material"), d)
            for i, (m, d) in enumerate(parsed)]


def thickness_texture_from_props(props, plugin: str):
    """The optional ``thickness`` scale texture (any Mitsuba texture, or a number)."""
    if "thickness" not in props:
        return None
    value = props.get("thickness")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if not math.isfinite(value) or value < 0:
            raise ThinFilmError(f"{plugin}: 'thickness' (a scale on every film's thickness) "
                                f"must be a finite number >= 0 or a texture, got {value!r}")
    return checked_texture(props, "thickness", plugin, "a number or a texture",
                           f"{plugin}: 'thickness' (a scale on every film's thickness)", 0.0,
                           mono=True)


def tabulate_from_props(props, plugin: str) -> bool | str:
    """``tabulate``: ``"auto"`` (default), ``true`` or ``false`` (bool or string)."""
    value = props.get("tabulate", "auto")
    name = value.strip().lower() if isinstance(value, str) else value
    for key, option in TABULATE_OPTIONS.items():   # a bool, or an option's name
        if name is key or (isinstance(name, str) and name == option.name):
            return key
    raise ThinFilmError(f"{plugin}: 'tabulate' must be \"auto\", true or false, got {value!r}")


def _positive_float(props, name: str, default: float, plugin: str, upper: float = math.inf) -> float:
    value = props.get(name, default)
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or not math.isfinite(value) or not 0 < value <= upper):
        bound = f" and <= {upper:g}" if math.isfinite(upper) else ""
        raise ThinFilmError(f"{plugin}: '{name}' must be a number > 0{bound}, got {value!r}")
    return float(value)


#: Largest ``spectral_resolution`` (nm) accepted: a Gaussian wider than this
#: would wash out the colours of single films.
MAX_SPECTRAL_RESOLUTION = 20.0


def _nonnegative_float(props, name: str, default: float, plugin: str, upper: float) -> float:
    value = props.get(name, default)
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or not math.isfinite(value) or not 0 <= value <= upper):
        raise ThinFilmError(f"{plugin}: '{name}' must be a number >= 0 and <= {upper:g}, "
                            f"got {value!r}")
    return float(value)


def stack_from_props(props, plugin: str, substrate: SpectralIndex,
                     ambient: SpectralIndex | None = None, *,
                     sides: dict | None = None) -> KernelStack:
    """The :class:`KernelStack` of a thin-film BSDF from its properties.

    Reads ``layers`` (or ``thin_film_ior`` + ``thin_film_thickness``),
    ``ext_ior`` (unless ``ambient`` is given), the optional ``thickness``
    texture, ``tabulate``, ``table_error`` and ``coherence_thickness``.
    ``sides`` (``{inside: needs_T}``) says what the BSDF evaluates, hence what
    is tabulated (default: reflectance from the ambient side only). Every
    thin-film BSDF builds its stack here, so the stack options are the same for
    all of them.
    """
    films = films_from_props(props, plugin)
    if ambient is None:
        ambient = ext_ior_from_props(props)
    return KernelStack(films, ambient, substrate, sides=sides,
                       **stack_options_from_props(props, plugin))


def stack_options_from_props(props, plugin: str, thickness_texture: bool = True) -> dict:
    """The :class:`KernelStack` keyword options every thin-film BSDF accepts."""
    options = dict(
        tabulate=tabulate_from_props(props, plugin),
        table_error=_positive_float(props, "table_error", DEFAULT_TABLE_ERROR, plugin, 0.5),
        spectral_resolution=_nonnegative_float(props, "spectral_resolution",
                                               DEFAULT_SPECTRAL_RESOLUTION, plugin,
                                               MAX_SPECTRAL_RESOLUTION),
        coherence_thickness=_positive_float(props, "coherence_thickness",
                                            DEFAULT_COHERENCE_THICKNESS, plugin),
        plugin=plugin)
    if thickness_texture:
        options["thickness_texture"] = thickness_texture_from_props(props, plugin)
    return options


def ext_ior_from_props(props) -> SpectralIndex:
    return real_index(props.get("ext_ior", DEFAULT_EXT_IOR), "ext_ior")


def substrate_from_props(props, plugin: str) -> SpectralIndex:
    """The conductor substrate: ``material`` or ``eta`` + ``k`` (as Mitsuba's conductor)."""
    has_eta, has_k = ("eta" in props), ("k" in props)
    if ("material" in props) and (has_eta or has_k):
        raise ThinFilmError(f"{plugin}: give either 'material' "
                            f"({props.get('material')!r}) or 'eta' + 'k', not both")
    if has_eta or has_k:
        if not (has_eta and has_k):
            raise ThinFilmError(f"{plugin}: 'eta' and 'k' must be given together "
                                f"(only '{'eta' if has_eta else 'k'}' was given)")
        values = {}
        for name in ("eta", "k"):
            v = props.get(name)
            if isinstance(v, bool) or isinstance(v, str):
                raise ThinFilmError(f"{plugin}: '{name}' must be a number or a "
                                    f"spectrum/texture, got {v!r}")
            if isinstance(v, (int, float)):
                v = uniform(v)
            else:
                try:
                    v = props.get_unbounded_texture(name)
                except Exception as e:
                    raise ThinFilmError(f"{plugin}: '{name}' must be a number or a "
                                        f"spectrum/texture, got {v!r} ({e})") from None
            # the range of every index (thinfilm_mi.materials.catalog.MIN_INDEX/MAX_INDEX),
            # over all of Mitsuba's wavelengths
            check_texture_range(v, f"{plugin}: '{name}'", MIN_INDEX if name == "eta" else 0.0,
                                MAX_INDEX, cover=True)
            values[name] = v
        return SpectralIndex.from_textures(values["eta"], values["k"], "eta/k")
    return SpectralIndex.from_material(props.get("material", "Au"), "material")


def check_unqueried(props, plugin: str) -> None:
    """Report parameters the plugin did not read, as Mitsuba does for its own plugins."""
    left = [k for k in props.unqueried()]
    if left:
        def shown(k):
            try:
                v = props.get(k)
            except Exception:  # noqa: BLE001 - e.g. nested objects Python cannot read
                return repr(k)
            text = repr(v) if isinstance(v, (str, int, float, bool)) else type(v).__name__
            return f"{k!r} = {text}"
        raise ThinFilmError(
            f"{plugin}: unreferenced propert{'y' if len(left) == 1 else 'ies'} "
            + ", ".join(shown(k) for k in left)
            + " (misspelled? see the plugin's parameter table)"
        )
