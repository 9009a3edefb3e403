"""Monte-Carlo tolerances of a design: random thickness errors, many draws.

``"1%:200"`` draws 200 stacks whose every thickness is off by a normal error of
standard deviation 1 % of it; ``"2nm:500"`` by 2 nm; ``"1%:200:uniform"``
uniformly within ±1 % (the number is then the half-width). Errors are
independent between films; thicknesses are clipped at 0; free indices keep
their designed values. The draws are evaluated all at once
(:meth:`~thinfilm_mi.design.merit.Merit.evaluate` on a batch), and the report
gives, for the merit and for each target's own merit (the RMS of its
residuals), the mean, standard deviation and worst case (largest), the fraction
of draws in which every point of the target stays within tolerance, and for
colour targets the CIEDE2000 (or xy distance) to the target and to the
nominal design's colour, per angle.
"""
from __future__ import annotations

import re
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from thinfilm_mi.design.merit import Design, Merit
from thinfilm_mi.design.target_quantities import stats
from thinfilm_mi.errors import ThinFilmError

__all__ = ["ToleranceSpec", "parse_tolerance", "ToleranceResult", "tolerance_analysis", "draw_thicknesses",
           "Distribution", "DISTRIBUTIONS"]


class Distribution(ABC):
    """The distribution of the thickness errors: its draws in units of ``sigma``."""

    name: str
    what: str          # what ``sigma`` is, as the table says it

    @abstractmethod
    def draw(self, rng: np.random.Generator, shape: tuple) -> np.ndarray:
        """Errors of unit size (``sigma`` 1), of ``shape``."""


class _Normal(Distribution):
    name, what = "normal", "standard deviation"

    def draw(self, rng, shape):
        return rng.standard_normal(shape)


class _Uniform(Distribution):
    name, what = "uniform", "half-width (uniform)"

    def draw(self, rng, shape):
        return rng.uniform(-1.0, 1.0, shape)


#: The error distributions by name (the default first).
DISTRIBUTIONS: dict[str, Distribution] = {d.name: d for d in (_Normal(), _Uniform())}

_SPEC = re.compile(r"^\s*(?P<sigma>[0-9.eE+\-]+)\s*(?P<unit>%|nm)\s*(?::\s*(?P<n>\d+))?"
                   rf"\s*(?::\s*(?P<dist>{'|'.join(DISTRIBUTIONS)}))?\s*$", re.IGNORECASE)


#: Most draws one analysis may ask for.
MAX_DRAWS = 100_000


@dataclass(frozen=True)
class ToleranceSpec:
    """Thickness errors: ``sigma`` (a fraction when ``relative``, else nm), the
    ``distribution`` (``normal``: standard deviation; ``uniform``: half-width)
    and the number of ``draws``."""

    sigma: float
    relative: bool
    draws: int = 200
    distribution: Distribution = DISTRIBUTIONS["normal"]
    text: str = ""


def parse_tolerance(text: str) -> ToleranceSpec:
    """``"SIGMA%|SIGMAnm[:DRAWS][:normal|uniform]"`` -> :class:`ToleranceSpec`
    (200 normal draws by default); anything else raises :class:`ThinFilmError`
    naming ``--tolerance``."""
    m = _SPEC.match(str(text))
    example = "e.g. 1%:200, 2nm:500 or 1%:200:uniform"
    if m is None:
        raise ThinFilmError(f"--tolerance {text!r}: expected SIGMA% or SIGMAnm, then :DRAWS and "
                            f":normal|uniform ({example})")
    try:
        sigma = float(m.group("sigma"))
    except ValueError:
        raise ThinFilmError(f"--tolerance {text!r}: {m.group('sigma')!r} is not a number ({example})") from None
    relative = m.group("unit") == "%"
    draws = int(m.group("n") or 200)
    if not (np.isfinite(sigma) and sigma >= 0) or (relative and sigma >= 100):
        raise ThinFilmError(f"--tolerance {text!r}: the error must be >= 0 (and below 100 %), got {sigma:g}")
    if not 1 <= draws <= MAX_DRAWS:
        raise ThinFilmError(f"--tolerance {text!r}: draws must be in [1, {MAX_DRAWS}], got {draws}")
    return ToleranceSpec(sigma / 100.0 if relative else sigma, relative, draws,
                         DISTRIBUTIONS[(m.group("dist") or "normal").lower()], str(text).strip())


@dataclass
class ToleranceResult:
    """The merit and per-target statistics over the draws (see the module docstring)."""

    spec: ToleranceSpec
    seed: int
    nominal_merit: float
    merits: np.ndarray                 # (draws,)
    targets: list[dict] = field(default_factory=list)
    thicknesses: np.ndarray | None = None    # (films, draws)
    achieved: list = field(default_factory=list)   # per target: achieved values, draw axis last

    def to_dict(self) -> dict:
        s = self.spec
        return {"spec": s.text, "sigma": s.sigma, "relative": s.relative, "unit": "fraction" if s.relative else "nm",
                "distribution": s.distribution.name, "draws": s.draws, "seed": self.seed,
                "merit": {"nominal": self.nominal_merit, **stats(self.merits)}, "targets": self.targets}

    def table(self) -> str:
        s = self.spec
        size = f"{100 * s.sigma:g} %" if s.relative else f"{s.sigma:g} nm"
        what = s.distribution.what
        m = stats(self.merits)
        lines = [f"tolerance: {s.draws} draws, thickness errors of {size} ({what}), seed {self.seed}",
                 f"  merit: nominal {self.nominal_merit:.4g}, mean {m['mean']:.4g}, std {m['std']:.4g}, "
                 f"worst {m['worst']:.4g}"]
        for rec in self.targets:
            tm = rec["merit"]
            line = (f"  targets[{rec['target']}] ({rec['quantity']}): merit mean {tm['mean']:.4g}, "
                    f"std {tm['std']:.4g}, worst {tm['worst']:.4g}; all points within tolerance in "
                    f"{100 * rec['yield']:.1f} % of draws")
            lines.append(line)
            for key, label in (("delta_e2000", "ΔE2000 to target"), ("delta_e2000_nominal", "ΔE2000 to nominal"),
                               ("distance", "xy distance to target")):
                for a, st in zip(rec.get("angles", []), rec.get(key, [])):
                    lines.append(f"      {a:g}°: {label} mean {st['mean']:.3g}, std {st['std']:.3g}, "
                                 f"worst {st['worst']:.3g}")
        return "\n".join(lines)


def draw_thicknesses(d, spec: ToleranceSpec, seed: int = 0) -> np.ndarray:
    """``spec.draws`` perturbed copies of the thicknesses ``d`` (nm), (films, draws),
    clipped at 0 (``numpy.random.default_rng(seed)``)."""
    rng = np.random.default_rng(seed)
    d = np.asarray(d, dtype=np.float64)
    shape = (d.size, spec.draws)
    eps = spec.distribution.draw(rng, shape)
    return np.maximum(d[:, None] * (1.0 + spec.sigma * eps) if spec.relative else d[:, None] + spec.sigma * eps,
                      0.0)


def tolerance_analysis(merit: Merit, design: Design, spec: ToleranceSpec | str, seed: int = 0,
                       chunk: int = 100) -> ToleranceResult:
    """Evaluate ``spec.draws`` perturbed copies of ``design`` (see the module docstring)."""
    if not isinstance(spec, ToleranceSpec):
        spec = parse_tolerance(spec)
    D = draw_thicknesses(design.d, spec, seed)
    nominal_e, _, nominal = merit.evaluate(design, jac=False, report=True)
    nominal_merit = float(np.sqrt(nominal_e @ nominal_e / merit.points))
    sums = np.zeros(spec.draws)
    per_target = [[] for _ in merit.problem.targets]
    for lo in range(0, spec.draws, chunk):
        batch = Design(design.films, D[:, lo:lo + chunk], design.n)
        e, _, values = merit.evaluate(batch, jac=False, report=True)
        sums[lo:lo + chunk] = np.sum(e * e, axis=0)
        for i, v in enumerate(values):
            per_target[i].append(v)
    records, achieved = [], []
    for i, (t, nom) in enumerate(zip(merit.problem.targets, nominal)):
        parts = per_target[i]
        res_sq = np.concatenate([np.atleast_1d(v.residual_sq) for v in parts])
        points = t.angles.size * (t.wavelengths.size if t.wavelengths is not None else 1)
        error = np.concatenate([v.error for v in parts], axis=-1)              # (..., draws)
        tol = t.quantity.tolerance_bound(t)
        within = np.all((error <= tol * (1 + 1e-9)).reshape(-1, spec.draws), axis=0)
        rec = {"target": t.index, "quantity": t.quantity.name, "merit": stats(np.sqrt(res_sq / points)),
               "yield": float(within.mean())}
        achieved.append(t.quantity.spread(t, nom, parts, error, rec))
        records.append(rec)
    return ToleranceResult(spec, seed, nominal_merit, np.sqrt(sums / merit.points), records, D, achieved)
