"""A design target (:class:`Target`) and what it asks for: the registries
:data:`TARGET_QUANTITIES` and :data:`COLOUR_SPACES`.

A target's ``quantity`` is one object holding everything that depends on it: the
keys a target of it may have, the parsing of its own keys, its description, its
residuals (:meth:`TargetQuantity.residuals`, the merit's branch for it) and what
the result's table, JSON and tolerance records show of it:

* ``R``, ``T``, ``A`` (:class:`Power`): a power at each wavelength and angle;
* ``Y`` (:class:`Luminous`): the luminous (CIE Y) reflectance or transmittance;
* ``colour`` (:class:`Colour`): its L*a*b* or chromaticity, in a colour space of
  :data:`COLOUR_SPACES` (``Lab``: residuals whose squares sum to ``(dE2000 /
  tolerance)^2``; ``xy``: the components of the distance in xy).

Colour targets of one space are evaluated together in one pass of
:meth:`ColourSpace.residuals` (the merit collects them with
:meth:`Colour.residuals`).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any

import numpy as np

from thinfilm_mi.colour.cie import delta_e2000
from thinfilm_mi.colour.report import integration_wavelengths, resolve_illuminant, resolve_observer
from thinfilm_mi.design.colourmath import Dual, colour_weights, delta_e2000_residuals, lab, xy_of
from thinfilm_mi.design.options import FRONT, KINDS, Kind, Side
from thinfilm_mi.design.parsing import fail, parse_choice, parse_grid, parse_number, per_point
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.polarization import UNPOLARIZED, Polarization

__all__ = ["Target", "TargetQuantity", "Power", "Absorptance", "Integrated", "Luminous", "Colour", "ColourSpace",
           "TARGET_QUANTITIES", "TARGET_QUANTITY_ALIASES", "POWERS", "COLOUR_SPACES", "stats", "json_list"]

_COMMON = ("quantity", "angles", "tolerance", "kind", "polarization", "side")


def json_list(a) -> Any:
    """An array as a JSON list (floats to 1e-10)."""
    return np.round(np.asarray(a, dtype=np.float64), 10).tolist()


def _bound_text(t: "Target") -> str:
    """``"<= 0.05"``: the kind and the wanted value(s) of a target with values."""
    v = t.value
    text = f"{v[0]:.4g}" if np.all(v == v[0]) else f"{v.min():.4g}..{v.max():.4g}"
    return f"{t.kind.name} {text}"


def stats(x: np.ndarray) -> dict:
    """Mean, standard deviation and worst (largest) of ``x``."""
    x = np.asarray(x, dtype=np.float64)
    return {"mean": float(x.mean()), "std": float(x.std()), "worst": float(x.max())}


class TargetQuantity(ABC):
    """What a target asks for. ``keys``: the keys its targets may have;
    ``required``: those they must have (besides ``quantity``)."""

    name: str
    keys: tuple[str, ...]
    required: tuple[str, ...] = ("tolerance", "value")
    #: whether its points are the colour integral's wavelengths (Y and colour)
    colour_integral: bool

    @abstractmethod
    def parse(self, t: "Target", entry: dict, where: str) -> np.ndarray:
        """Fill ``t`` from its own keys of ``entry``; return the wavelengths it needs."""

    @abstractmethod
    def describe(self, t: "Target") -> list[str]:
        """The first parts of the target's description."""

    @abstractmethod
    def spectral(self, t: "Target") -> "Power":
        """The power computed at each wavelength point (R, T or A)."""

    @abstractmethod
    def residuals(self, t: "Target", q: np.ndarray, dq, colour_step: int, pending: dict):
        """``(e, de, achieved, error)`` from the powers ``q`` (angles, n[, B]) and
        their derivatives ``dq`` (or ``None``): residuals (angles, m[, B]) and
        derivatives (angles, m[, B], K); or ``None`` after adding the target to
        ``pending`` (colour targets, evaluated together by their space)."""

    @abstractmethod
    def wanted(self, t: "Target") -> str:
        """What the table says is wanted."""

    @abstractmethod
    def record(self, t: "Target", achieved, error) -> dict:
        """The target's own entries of its JSON record."""

    @abstractmethod
    def achieved_text(self, t: "Target", achieved, error) -> tuple[str, np.ndarray]:
        """The table's text of one angle's achieved values, and the errors it shows."""

    def tolerance_bound(self, t: "Target"):
        """The tolerance broadcast against the errors (points, draws) of a tolerance analysis."""
        return t.tolerance[0]

    def tolerance_unit(self, t: "Target") -> str:
        """The unit the table appends to the tolerance."""
        return ""

    def spread(self, t: "Target", nominal, parts: list, error: np.ndarray, rec: dict) -> np.ndarray:
        """Add the target's own statistics over the draws of a tolerance analysis to
        ``rec``; return its achieved values over the draws (draw axis last)."""
        return np.concatenate([v.achieved for v in parts], axis=-1)


class Power(TargetQuantity):
    """``R`` or ``T`` at each wavelength and angle: the mean over the polarisation's
    components. ``slot``: its place in ``(R, T)``."""

    keys = _COMMON + ("wavelengths", "value")
    colour_integral = False

    def __init__(self, name: str, slot: int):
        self.name, self.slot = name, slot

    def parse(self, t, entry, where):
        if "wavelengths" not in entry:
            fail(where, "missing 'wavelengths' (e.g. \"420:680:5\" or 550)")
        t.wavelengths = parse_grid(entry["wavelengths"], where, "wavelengths")
        count = t.wavelengths.size
        t.value = per_point(entry["value"], count, where, "value")
        t.tolerance = per_point(entry["tolerance"], count, where, "tolerance")
        return t.wavelengths

    def describe(self, t):
        w = t.wavelengths
        return [self.name, f"{w[0]:g} nm" if w.size == 1 else f"{w[0]:g}-{w[-1]:g} nm ({w.size})"]

    def spectral(self, t):
        return self

    def curve(self, R, T):
        """This power from the spectra ``R`` and ``T``."""
        return (R, T)[self.slot]

    def power(self, res: dict, components, idx: np.ndarray, jac: bool):
        """The power at ``idx`` of the responses ``res`` ({component: Response}),
        averaged over ``components``, and its derivatives (or ``None``)."""
        w = 1.0 / len(components)
        val = sum(getattr(res[p], self.name)[idx] for p in components) * w
        if not jac:
            return val, None
        return val, sum(getattr(res[p], "d" + self.name)[idx] for p in components) * w

    def residuals(self, t, q, dq, colour_step, pending):
        tol = t.tolerance.reshape((-1,) + (1,) * (q.ndim - 2))
        e, de = t.kind.residuals((q - t.value.reshape(tol.shape)) / tol,
                                 None if dq is None else dq / tol[..., None])
        return e, de, q, np.abs(e) * tol

    def wanted(self, t):
        return _bound_text(t)

    def record(self, t, achieved, error):
        return dict(wavelengths=json_list(t.wavelengths), wanted=json_list(t.value),
                    tolerance=json_list(t.tolerance), achieved=json_list(achieved))

    def achieved_text(self, t, achieved, error):
        if achieved.size == 1:
            return f"{achieved[0]:.5f} at {t.wavelengths[0]:g} nm", error
        worst = int(np.argmax(error / t.tolerance))
        return (f"{achieved.mean():.5f} mean, {achieved.min():.5f}..{achieved.max():.5f}; "
                f"worst {t.wavelengths[worst]:g} nm"), error[worst:worst + 1]

    def tolerance_bound(self, t):
        return t.tolerance.reshape((-1, 1))


class Absorptance(Power):
    """``A = 1 - R - T``, the power the stack absorbs."""

    def __init__(self):
        self.name = "A"

    def curve(self, R, T):
        return 1.0 - R - T

    def power(self, res, components, idx, jac):
        w = 1.0 / len(components)
        val = 1.0 - sum(res[p].R[idx] + res[p].T[idx] for p in components) * w
        if not jac:
            return val, None
        return val, -sum(res[p].dR[idx] + res[p].dT[idx] for p in components) * w


#: The powers a luminous or colour target may integrate (``of``).
POWERS: dict[str, Power] = {p.name: p for p in (Power("R", 0), Power("T", 1))}


class Integrated(TargetQuantity):
    """A quantity integrated over the spectrum ``of`` R or T under an illuminant."""

    colour_integral = True

    def parse(self, t, entry, where):
        try:
            t.illuminant = resolve_illuminant(entry.get("illuminant", "D65")).name
            t.observer = resolve_observer(entry.get("observer", 2))
        except ThinFilmError as e:
            fail(where, str(e))
        t.of = parse_choice(entry.get("of", "R"), POWERS, where, "of")
        t.tolerance = np.array([parse_number(entry["tolerance"], where, "tolerance")])
        self.parse_reference(t, entry, where)
        return integration_wavelengths(t.illuminant)

    @abstractmethod
    def parse_reference(self, t: "Target", entry: dict, where: str) -> None:
        """Fill what ``t`` wants from ``entry``."""

    def describe(self, t):
        return [f"{self.name} of {t.of.name}", f"{t.illuminant}, {t.observer}°"]

    def spectral(self, t):
        return t.of

    @staticmethod
    def xyz(t: "Target", q: np.ndarray, dq, colour_step: int):
        """``(XYZ, dXYZ, white)`` of the spectra ``q`` (angles, n[, B]): XYZ
        (angles[, B], 3), dXYZ (angles[, B], 3, K) or ``None``."""
        _, W, white = colour_weights(t.illuminant, t.observer, colour_step)
        XYZ = np.moveaxis(q, 1, -1) @ W
        dXYZ = None if dq is None else np.swapaxes(np.tensordot(dq, W, axes=([1], [0])), -1, -2)
        return XYZ, dXYZ, white

    def record(self, t, achieved, error):
        return dict(illuminant=t.illuminant, observer=t.observer, of=t.of.name, tolerance=float(t.tolerance[0]),
                    **self.reference_record(t, achieved, error))

    @abstractmethod
    def reference_record(self, t: "Target", achieved, error) -> dict:
        """The JSON entries of what is wanted and achieved."""


class Luminous(Integrated):
    """``Y``: the luminous (CIE Y) reflectance or transmittance."""

    name = "Y"
    keys = _COMMON + ("value", "illuminant", "observer", "of")

    def parse_reference(self, t, entry, where):
        t.value = np.array([parse_number(entry["value"], where, "value")])

    def residuals(self, t, q, dq, colour_step, pending):
        XYZ, dXYZ, _ = self.xyz(t, q, dq, colour_step)
        tol = t.tolerance[0]
        e, de = t.kind.residuals((XYZ[..., 1] - t.value[0]) / tol, None if dXYZ is None else dXYZ[..., 1, :] / tol)
        # one residual per angle: (angles, 1[, B]) like the others' (angles, m[, B])
        return e[:, None], None if de is None else de[:, None], XYZ[..., 1], np.abs(e) * tol

    def wanted(self, t):
        return _bound_text(t)

    def reference_record(self, t, achieved, error):
        return dict(wanted=float(t.value[0]), achieved=json_list(achieved))

    def achieved_text(self, t, achieved, error):
        return f"{float(achieved):.5f}", error


class ColourSpace(ABC):
    """Where a colour target's reference lives: ``size`` numbers, the residuals and
    what the tables call the error."""

    name: str
    size: int
    unit: str            # appended to the tolerance in the table
    error_key: str       # the JSON key of the per-angle error

    @abstractmethod
    def check(self, reference: np.ndarray, where: str) -> None:
        """:func:`~thinfilm_mi.design.parsing.fail` unless ``reference`` is a colour of this space."""

    @abstractmethod
    def residuals(self, XYZ: np.ndarray, white: np.ndarray, reference: np.ndarray) -> tuple[Dual, Dual]:
        """``(c, r)``: the colours of ``XYZ`` (..., 3) in this space and the residuals
        to ``reference``, both with derivatives with respect to XYZ."""

    @abstractmethod
    def to_xy(self, values: np.ndarray, white: np.ndarray) -> np.ndarray:
        """Colours of this space as chromaticities xy (for the plot)."""

    def nominal_spread(self, nominal, achieved) -> dict:
        """Extra statistics of a tolerance analysis: ``{key: (angles, draws)}`` of
        the draws' distance to the nominal design's colour."""
        return {}


class _Lab(ColourSpace):
    name, size, unit, error_key = "Lab", 3, " ΔE2000", "delta_e2000"

    def check(self, reference, where):
        if not 0 <= reference[0] <= 100:
            fail(where, f"Lab: L* must be in [0, 100], got {reference[0]:g}")

    def residuals(self, XYZ, white, reference):
        c = lab(Dual.variables(XYZ), white)
        return c, delta_e2000_residuals(c, reference)

    def to_xy(self, values, white):
        import colour

        return colour.XYZ_to_xy(colour.Lab_to_XYZ(values, colour.XYZ_to_xy(white)))

    def nominal_spread(self, nominal, achieved):
        return {"delta_e2000_nominal": delta_e2000(nominal[:, None, :], achieved)}


class _Xy(ColourSpace):
    name, size, unit, error_key = "xy", 2, " in xy", "distance"

    def check(self, reference, where):
        if not (0 < reference[0] < 1 and 0 < reference[1] < 1):
            fail(where, f"xy: x and y must be in (0, 1), got {list(reference)}")

    def residuals(self, XYZ, white, reference):
        c = xy_of(Dual.variables(XYZ))
        return c, Dual(c.val - reference, c.der)

    def to_xy(self, values, white):
        return values


#: The colour spaces by name, as a colour target's key names them.
COLOUR_SPACES: dict[str, ColourSpace] = {s.name: s for s in (_Lab(), _Xy())}


class Colour(Integrated):
    """``colour``: L*a*b* (residual CIEDE2000) or chromaticity xy (residual the distance)."""

    name = "colour"
    keys = _COMMON + tuple(COLOUR_SPACES) + ("illuminant", "observer", "of")
    required = ("tolerance",)

    def parse_reference(self, t, entry, where):
        given = [k for k in COLOUR_SPACES if k in entry]
        if len(given) != 1:
            fail(where, "give exactly one of Lab: [L, a, b] or xy: [x, y]")
        t.space = COLOUR_SPACES[given[0]]
        ref = entry[t.space.name]
        size = t.space.size
        if not isinstance(ref, (list, tuple)) or len(ref) != size:
            fail(where, f"{t.space.name}: expected {size} numbers, got {ref!r}")
        t.reference = np.array([parse_number(v, where, t.space.name) for v in ref])
        t.space.check(t.reference, where)
        if t.kind is not KINDS["="]:
            fail(where, f"kind: colour targets are '=' only (a colour difference), got {t.kind.name!r}")

    def residuals(self, t, q, dq, colour_step, pending):
        pending.setdefault(t.space, []).append((t, *self.xyz(t, q, dq, colour_step)))
        return None

    @staticmethod
    def evaluate(space: ColourSpace, items: list) -> list:
        """The parts ``(e, de, achieved, error)`` of the colour targets ``items``
        (``(t, XYZ, dXYZ, white)`` each) of one ``space``, in one pass."""
        shaped = lambda a, like: np.broadcast_to(a, like.shape[:-1] + a.shape[-1:])
        XYZ = np.concatenate([it[1] for it in items])
        ref = np.concatenate([shaped(it[0].reference, it[1]) for it in items])
        white = np.concatenate([shaped(it[3], it[1]) for it in items])
        c, r = space.residuals(XYZ, white, ref)
        out, start = [], 0
        for t, xyz, dXYZ, _ in items:
            sl = slice(start, start + xyz.shape[0])
            start = sl.stop
            tol = t.tolerance[0]
            e = np.moveaxis(r.val[sl], -1, 1) / tol                          # (angles, 3|2[, B])
            de = None if dXYZ is None else np.moveaxis(r.der[sl] @ dXYZ, -2, 1) / tol
            out.append((e, de, c.val[sl], np.sqrt(np.sum(r.val[sl] ** 2, axis=-1))))
        return out

    def wanted(self, t):
        return f"{t.space.name} {', '.join(f'{v:g}' for v in t.reference)}"

    def reference_record(self, t, achieved, error):
        return {"space": t.space.name, "wanted": json_list(t.reference), "achieved": json_list(achieved),
                t.space.error_key: json_list(error)}

    def achieved_text(self, t, achieved, error):
        return ", ".join(f"{x:.4g}" for x in np.atleast_1d(achieved)), error

    def tolerance_unit(self, t):
        return t.space.unit

    def spread(self, t, nominal, parts, error, rec):
        ach = np.concatenate([v.achieved for v in parts], axis=1)          # (angles, draws, 3|2)
        rec["angles"] = t.angles.tolist()
        rec[t.space.error_key] = [stats(error[a]) for a in range(t.angles.size)]
        for key, shift in t.space.nominal_spread(nominal.achieved, ach).items():
            rec[key] = [stats(shift[a]) for a in range(t.angles.size)]
        return ach


#: The target quantities by name, in the order errors list them.
TARGET_QUANTITIES: dict[str, TargetQuantity] = {q.name: q for q in (POWERS["R"], POWERS["T"], Absorptance(),
                                                                Luminous(), Colour())}
#: Other spellings users write.
TARGET_QUANTITY_ALIASES = {"color": "colour"}


@dataclass
class Target:
    """One parsed target. ``value``/``tolerance`` hold one number per
    wavelength for R/T/A and one number otherwise; ``reference`` is the Lab or xy
    of a colour target. ``quantity``, ``kind``, ``polarization``, ``side``,
    ``of`` and ``space`` are the objects of their registries (each has a ``name``)."""

    index: int
    quantity: TargetQuantity
    angles: np.ndarray
    tolerance: np.ndarray
    kind: Kind = KINDS["="]
    polarization: Polarization = UNPOLARIZED
    side: Side = FRONT
    wavelengths: np.ndarray | None = None
    value: np.ndarray | None = None
    illuminant: str = "D65"
    observer: int = 2
    of: Power | None = None           # R or T: what Y and colour targets integrate
    space: ColourSpace | None = None  # Lab or xy for colour targets
    reference: np.ndarray | None = None

    @property
    def name(self) -> str:
        """``targets[i] (quantity)``, as errors and tables name it."""
        return f"targets[{self.index}] ({self.quantity.name})"

    def describe(self) -> str:
        """A short human description (the table's heading)."""
        bits = self.quantity.describe(self) + [self.polarization.describe(), self.side.describe()]
        return ", ".join(b for b in bits if b)
