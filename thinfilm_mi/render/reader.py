"""One reader of a plugin's properties (no plugin classes here).

:class:`PluginProperties` wraps the ``mi.Properties`` a plugin constructor receives and
answers typed, checked values by name, as ``Properties::get<T>`` and a plugin's parse step
do for Mitsuba's C++ plugins: numbers in a range (:meth:`~PluginProperties.number`),
integers, booleans, a choice from a registry, textures whose values are checked at load,
real indices and materials, the parts of a film stack (:meth:`~PluginProperties.films`,
:meth:`~PluginProperties.stack_options`, or the stack's whole spec,
:meth:`~PluginProperties.stack_spec`), a conductor's substrate and a nested BSDF.
:meth:`~PluginProperties.check_unqueried` then refuses what no one read (a misspelt name),
as Mitsuba does for its own plugins. It parses and checks; it builds nothing: a plugin
builds its stack from the spec after the check.

A bad value raises :class:`~thinfilm_mi.errors.ThinFilmError` naming the property and the
value. Nothing here knows the plugin: its name is put in front of the message once, at the
plugin boundary (:func:`thinfilm_mi.errors.plugin_boundary`), which every plugin
constructor runs in.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import MAX_INDEX, MIN_INDEX
from thinfilm_mi.materials.stack import check_thickness, parse_layers
from thinfilm_mi.optics.choices import choose
from thinfilm_mi.render.kernel import StackSpec
from thinfilm_mi.render.media import DEFAULT_EXT_IOR, SpectralIndex, real_index
from thinfilm_mi.render.stack_plan import (
    DEFAULT_COHERENCE_THICKNESS,
    DEFAULT_SPECTRAL_RESOLUTION,
    DEFAULT_TABLE_ERROR,
)
from thinfilm_mi.render.tabulation import TABULATE_OPTIONS
from thinfilm_mi.render.textures import bounds, check_texture_range, mitsuba_module, property_texture, uniform

__all__ = ["MAX_SPECTRAL_RESOLUTION", "PluginProperties", "finite_number"]

#: Largest ``spectral_resolution`` (nm) accepted: a Gaussian wider than this
#: would wash out the colours of single films.
MAX_SPECTRAL_RESOLUTION = 20.0


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def finite_number(what: str, value, lo: float = -math.inf, hi: float = math.inf, *,
                  strict: bool = False, unit: str = "", also: str = "", hint: str = "") -> float:
    """``value`` as a float if it is a finite number within ``[lo, hi]`` (``lo`` excluded
    with ``strict``), else :class:`ThinFilmError` ``"{what} must be a finite number > lo
    and <= hi{unit}{also}, got {value!r}{hint}"`` (``what``: the property, quoted; the
    same check at load and at an edit)."""
    if not (_is_number(value) and math.isfinite(value) and lo <= value <= hi
            and not (strict and value == lo)):
        want = bounds(lo, hi, strict)
        raise ThinFilmError(f"{what} must be a finite number{' ' + want if want else ''}{unit}{also}, "
                            f"got {value!r}{hint}")
    return float(value)


class PluginProperties:
    """A plugin's ``mi.Properties`` (:attr:`props`), read as typed, checked values.

    Each getter marks what it reads as queried (Mitsuba counts a ``get``), so that
    :meth:`check_unqueried`, called once everything is read, finds exactly the names no
    getter asked for."""

    def __init__(self, props):
        #: the ``mi.Properties`` read
        self.props = props

    def __contains__(self, name: str) -> bool:
        return name in self.props

    def value(self, name: str, default=None):
        """The raw value of ``name`` (``default`` if absent), unchecked."""
        return self.props.get(name, default)

    # -- plain values ---------------------------------------------------------------

    def number(self, name: str, default: float | None = None, lo: float = -math.inf,
               hi: float = math.inf, *, strict: bool = False, unit: str = "",
               required: str = "") -> float:
        """``name`` as a finite float in ``[lo, hi]`` (:func:`finite_number`);
        ``default`` if absent, or, with no default, an error saying it is ``required``."""
        if name not in self.props:
            if default is None:
                raise ThinFilmError(f"'{name}' is required ({required})")
            return float(default)
        return finite_number(f"'{name}'", self.props.get(name), lo, hi, strict=strict, unit=unit)

    def integer(self, name: str, default: int, lo: int) -> int:
        """``name`` as an integer >= ``lo``."""
        value = self.props.get(name, default)
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= lo):
            raise ThinFilmError(f"'{name}' must be an integer >= {lo}, got {value!r}")
        return value

    def boolean(self, name: str, default: bool) -> bool:
        value = self.props.get(name, default)
        if not isinstance(value, bool):
            raise ThinFilmError(f"'{name}' must be a boolean, got {value!r}")
        return value

    def choice(self, name: str, registry: Mapping, default: str | None = None):
        """The entry of ``registry`` that ``name`` names (its first entry by default;
        :func:`~thinfilm_mi.optics.choices.choose`: case-insensitive)."""
        value = self.props.get(name, next(iter(registry)) if default is None else default)
        return choose(registry, value, f"'{name}'")

    # -- textures -------------------------------------------------------------------

    def texture(self, name: str, want: str, what: str = "", lo: float = -math.inf,
                hi: float = math.inf, *, mono: bool = False, strict: bool = False,
                cover: bool = False, unbounded: bool = False, uniform_number: bool = False,
                hint: str = ""):
        """``name`` as a Mitsuba texture (``want`` says what it may be), its values
        checked at load to be finite and in ``[lo, hi]``
        (:func:`~thinfilm_mi.render.textures.check_texture_range`: ``mono`` reads one
        channel, ``strict`` excludes ``lo``, ``cover`` wants a spectrum over all of
        Mitsuba's range). A plain number is checked first (its error says ``hint``)
        and, with ``uniform_number``, made a ``uniform`` spectrum. ``what`` names it in
        errors (default: ``'name'``)."""
        what = what or f"'{name}'"
        value = self.props.get(name)
        if isinstance(value, (bool, str)):
            raise ThinFilmError(f"'{name}' must be {want}, got {value!r}")
        if _is_number(value):
            finite_number(what, value, lo, hi, strict=strict, also=" or a texture", hint=hint)
            if uniform_number:
                return uniform(value)
        tex = property_texture(self.props, name, want, unbounded=unbounded)
        check_texture_range(tex, what, lo, hi, mono=mono, strict=strict, cover=cover)
        return tex

    def factor(self, name: str):
        """An optional factor texture (``specular_reflectance``, ``specular_transmittance``,
        an absorption coefficient), or ``None`` if it was not given. Its values must be
        finite and >= 0 (a negative or infinite factor renders black or NaN)."""
        if name not in self.props:
            return None
        return self.texture(name, "a number, a spectrum or a texture", lo=0.0)

    def nested_bsdf(self):
        """The one nested BSDF: named ``bsdf``, or the one nested BSDF of another name
        (XML's unnamed child). Refused where there is none or more than one."""
        mi = mitsuba_module()
        if "bsdf" in self.props:
            base = self.props.get("bsdf")
            if not isinstance(base, mi.BSDF):
                raise ThinFilmError(f"'bsdf' must be a nested BSDF, got {base!r}")
            return base
        found = [obj for _, obj in self.props.objects() if isinstance(obj, mi.BSDF)]
        if len(found) != 1:
            raise ThinFilmError(f"needs exactly one nested BSDF (the base under the coat), "
                                f"got {len(found)}")
        return found[0]

    # -- indices and the film stack -------------------------------------------------

    def index(self, name: str, default) -> SpectralIndex:
        """A non-absorbing medium (``ext_ior``, ``int_ior``, ``base_ior``): a number or
        a material name (:func:`~thinfilm_mi.render.media.real_index`)."""
        return real_index(self.props.get(name, default), name)

    def indices(self, *named: tuple[str, Any]) -> list[SpectralIndex]:
        """The non-absorbing media of an interface, read together and in order: one
        :meth:`index` per ``(name, default)`` (e.g. ``int_ior`` and ``ext_ior``)."""
        return [self.index(name, default) for name, default in named]

    def substrate(self, default: str = "Au") -> SpectralIndex:
        """A conductor's substrate: ``material`` or ``eta`` + ``k`` (textures checked over
        all of Mitsuba's wavelengths, as Mitsuba's ``conductor`` takes them)."""
        has_eta, has_k = ("eta" in self.props), ("k" in self.props)
        if ("material" in self.props) and (has_eta or has_k):
            raise ThinFilmError(f"give either 'material' ({self.props.get('material')!r}) "
                                "or 'eta' + 'k', not both")
        if has_eta or has_k:
            if not (has_eta and has_k):
                raise ThinFilmError(f"'eta' and 'k' must be given together "
                                    f"(only '{'eta' if has_eta else 'k'}' was given)")
            # the range of every index (thinfilm_mi.materials.model.MIN_INDEX/MAX_INDEX)
            eta, k = (self.texture(name, "a number or a spectrum/texture", "", low, MAX_INDEX,
                                   cover=True, unbounded=True, uniform_number=True)
                      for name, low in (("eta", MIN_INDEX), ("k", 0.0)))
            return SpectralIndex.from_textures(eta, k, "eta/k")
        return SpectralIndex.from_material(self.props.get("material", default), "material")

    def films(self) -> list[tuple[SpectralIndex, float]]:
        """The films from the outside in: ``layers``, or the one-film shorthand
        ``thin_film_ior`` + ``thin_film_thickness``."""
        has_layers = ("layers" in self.props)
        has_ior = ("thin_film_ior" in self.props)
        has_thk = ("thin_film_thickness" in self.props)
        if has_layers and (has_ior or has_thk):
            raise ThinFilmError("give either 'layers' or 'thin_film_ior' + "
                                "'thin_film_thickness', not both")
        if has_ior != has_thk:
            missing = "thin_film_thickness" if has_ior else "thin_film_ior"
            raise ThinFilmError(f"'{missing}' is missing (the single-film shorthand needs "
                                "both 'thin_film_ior' and 'thin_film_thickness')")
        if has_ior:
            parsed = [(self.props.get("thin_film_ior"),
                       check_thickness(self.props.get("thin_film_thickness"), "thin_film_thickness"))]
            names = ["thin_film_ior"]
        else:
            parsed = parse_layers(self.props.get("layers", ""))
            names = [f"layers[{i}] material" for i in range(len(parsed))]
        return [(SpectralIndex.from_material(m, label), d) for label, (m, d) in zip(names, parsed)]

    def tabulate(self) -> bool | str:
        """``tabulate``: ``"auto"`` (default), ``true`` or ``false`` (bool or string)."""
        value = self.props.get("tabulate", "auto")
        name = value.strip().lower() if isinstance(value, str) else value
        for key, option in TABULATE_OPTIONS.items():   # a bool, or an option's name
            if name is key or (isinstance(name, str) and name == option.name):
                return key
        raise ThinFilmError(f"'tabulate' must be \"auto\", true or false, got {value!r}")

    def stack_options(self, thickness_texture: bool = True) -> dict:
        """The :class:`~thinfilm_mi.render.kernel.KernelStack` keyword options every
        thin-film BSDF accepts: ``tabulate``, ``table_error``, ``spectral_resolution``,
        ``coherence_thickness`` and the optional ``thickness`` scale texture."""
        options = dict(
            tabulate=self.tabulate(),
            table_error=self.number("table_error", DEFAULT_TABLE_ERROR, 0.0, 0.5, strict=True),
            spectral_resolution=self.number("spectral_resolution", DEFAULT_SPECTRAL_RESOLUTION,
                                            0.0, MAX_SPECTRAL_RESOLUTION),
            coherence_thickness=self.number("coherence_thickness", DEFAULT_COHERENCE_THICKNESS,
                                            0.0, strict=True))
        if thickness_texture:
            options["thickness_texture"] = (
                self.texture("thickness", "a number or a texture",
                             "'thickness' (a scale on every film's thickness)", 0.0, mono=True)
                if "thickness" in self.props else None)
        return options

    def stack_spec(self, substrate: SpectralIndex, ambient: SpectralIndex | None = None) -> StackSpec:
        """The :class:`~thinfilm_mi.render.kernel.StackSpec` of a thin-film BSDF, parsed,
        not built: its :meth:`films` over ``substrate``, under ``ambient`` (default:
        ``ext_ior``), with the :meth:`stack_options`. Every thin-film BSDF reads its stack
        here, so the stack options are the same for all of them; it builds the stack
        (:func:`~thinfilm_mi.render.kernel.build_stack`) once
        :meth:`check_unqueried` has passed, so a misspelt name is refused before the
        tables are built."""
        options = self.stack_options()
        films = self.films()
        if ambient is None:
            ambient = self.index("ext_ior", DEFAULT_EXT_IOR)
        return StackSpec(films, ambient, substrate, options)

    def check_unqueried(self) -> None:
        """Refuse the properties no getter read, named with their values, as Mitsuba
        does for its own plugins."""
        left = list(self.props.unqueried())
        if not left:
            return

        def shown(k):
            try:
                v = self.props.get(k)
            except Exception:  # noqa: BLE001 - e.g. nested objects Python cannot read
                return repr(k)
            text = repr(v) if isinstance(v, (str, int, float, bool)) else type(v).__name__
            return f"{k!r} = {text}"
        raise ThinFilmError(f"unreferenced propert{'y' if len(left) == 1 else 'ies'} "
                            + ", ".join(shown(k) for k in left)
                            + " (misspelled? see the plugin's parameter table)")
