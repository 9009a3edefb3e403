"""What a design run returns: the stack as a ``layers`` string, the merit, and
what each target achieves (a table, a dict for JSON)."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from thinfilm_mi.design.merit import Design, Merit, TargetValues
from thinfilm_mi.design.options import Side
from thinfilm_mi.design.target_quantities import json_list
from thinfilm_mi.design.targets import Problem, Target
from thinfilm_mi.materials.stack import format_layers
from thinfilm_mi.optics.polarization import Polarization

__all__ = ["DesignResult", "design_layers", "film_specs", "format_index"]


def format_index(z: complex) -> str:
    """A constant index as a ``layers`` string writes it (n to 1e-6, then ``+kj``)."""
    text = f"{z.real:.6f}".rstrip("0").rstrip(".")
    return text + (f"+{z.imag:.6g}j" if z.imag else "")


def film_specs(problem: Problem, design: Design) -> list[str]:
    """The material of each film as a ``layers`` string writes it (a free index as its value)."""
    out = []
    free = [i for i, m in enumerate(problem.materials) if m.free]
    for m in design.films:
        dm = problem.materials[m]
        out.append(format_index(complex(design.n[free.index(m)], dm.n0.imag)) if dm.free else dm.spec)
    return out


def design_layers(problem: Problem, design: Design) -> str:
    """``"MATERIAL NM; ..."`` (thicknesses to 0.1 pm): what every plugin's ``layers`` accepts."""
    return format_layers(zip(film_specs(problem, design), design.d))


@dataclass
class DesignResult:
    """A designed (or evaluated) stack and what it achieves.

    ``layers``: the stack as a ``layers`` string; ``merit``: ``sqrt(sum(e^2) /
    points)`` (1: every point at its tolerance); ``seconds``: wall time of the
    run; ``values``: one :class:`~thinfilm_mi.design.merit.TargetValues` per
    target; ``history``: one record per start; ``tolerance``: the
    :class:`~thinfilm_mi.design.tolerance.ToleranceResult` when asked for.
    """

    problem: Problem
    merit_function: Merit
    design: Design
    merit: float
    seconds: float
    values: list[TargetValues]
    history: list[dict] = field(default_factory=list)
    tolerance: Any = None

    @property
    def layers(self) -> str:
        return design_layers(self.problem, self.design)

    @property
    def films(self) -> list[tuple[str, float]]:
        """``[(material, nm), ...]`` from the ambient side."""
        return list(zip(film_specs(self.problem, self.design), (float(d) for d in self.design.d)))

    def stack(self):
        """The design as a :class:`thinfilm_mi.Stack` (for ``rt``, ``colour_report``)."""
        from thinfilm_mi.materials.stack import Stack

        return Stack(self.layers, substrate=self.problem.substrate_spec, ambient=self.problem.ambient_spec)

    def spectrum(self, wavelengths, angle: float = 0.0, side: Side | str = "front",
                 polarization: Polarization | str = "unpolarized") -> tuple[np.ndarray, np.ndarray]:
        """``(R, T)`` of the design at ``wavelengths`` (nm) and ``angle`` (degrees),
        lit from ``side`` in ``polarization`` (objects or their names)."""
        return self.merit_function.spectrum(self.design, wavelengths, angle, side, polarization)

    # -- reports -------------------------------------------------------------
    def target_records(self) -> list[dict]:
        """Per target: what was wanted and what is achieved, point by point."""
        out = []
        for v in self.values:
            t = v.target
            rec: dict[str, Any] = {"target": t.index, "quantity": t.quantity.name, "kind": t.kind.name,
                                   "polarization": t.polarization.name, "side": t.side.name,
                                   "angles": json_list(t.angles)}
            rec.update(t.quantity.record(t, v.achieved, v.error))
            within = v.within
            rec.update(error=json_list(v.error), within=bool(np.all(within)),
                       points_within=int(np.sum(within)), points=int(within.size),
                       residual_sq=float(v.residual_sq))
            out.append(rec)
        return out

    def to_dict(self) -> dict:
        """``layers``, ``merit``, ``seconds``, ``targets`` (and ``tolerance`` when computed)."""
        out = {"layers": self.layers, "merit": float(self.merit), "seconds": float(self.seconds),
               "films": len(self.design.films), "targets": self.target_records()}
        if self.tolerance is not None:
            out["tolerance"] = self.tolerance.to_dict()
        return out

    def to_json(self, **kwargs) -> str:
        return json.dumps(self.to_dict(), **kwargs)

    def table(self) -> str:
        """A text table per target: wanted, achieved, within tolerance."""
        lines = [f"design: {len(self.design.films)} films, merit {self.merit:.4g} "
                 f"(RMS of (achieved - wanted) / tolerance), {self.seconds:.1f} s",
                 f"layers: {self.layers or '(none)'}"]
        for v in self.values:
            t = v.target
            lines.append("")
            lines.append(f"{t.name}: {t.describe()}; wanted {t.quantity.wanted(t)}, tolerance "
                         f"{_tol_text(t)}")
            lines.append(f"  {'angle':>6} {'achieved':>44} {'error':>10} {'within':>8}")
            for a, angle in enumerate(t.angles):
                ach, err, ok = v.achieved[a], np.atleast_1d(v.error[a]), np.atleast_1d(v.within[a])
                text, err = t.quantity.achieved_text(t, ach, err)
                within = f"{int(ok.sum())}/{ok.size}" if ok.size > 1 else ("yes" if ok[0] else "NO")
                lines.append(f"  {angle:>6g} {text:>44} {float(err.max()):>10.4g} {within:>8}")
        if self.tolerance is not None:
            lines.append("")
            lines.append(self.tolerance.table())
        return "\n".join(lines)

    def figure(self):
        """Spectra against the targets, colour against angle on the chromaticity
        diagram, and the tolerance spread (a matplotlib figure)."""
        from thinfilm_mi.design.plot import design_figure

        return design_figure(self)


def _tol_text(t: Target) -> str:
    tol = t.tolerance
    unit = t.quantity.tolerance_unit(t)
    return (f"{tol[0]:.4g}" if np.all(tol == tol[0]) else f"{tol.min():.4g}..{tol.max():.4g}") + unit
