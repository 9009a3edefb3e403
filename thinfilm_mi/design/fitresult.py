"""The result of a fit: parameters with standard errors and correlations, χ², residuals, the fitted stack."""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from thinfilm_mi.design.fitfile import Measurement
from thinfilm_mi.design.fitmodel import FitModel
from thinfilm_mi.design.result import format_index
from thinfilm_mi.design.target_quantities import json_list, stats
from thinfilm_mi.design.tolerance import ToleranceSpec, draw_thicknesses, parse_tolerance
from thinfilm_mi.materials import save_material
from thinfilm_mi.materials.stack import format_layers

__all__ = ["FitResult", "Minimum", "CORRELATION_WARNING", "IDENTIFIABILITY_DELTA", "CHI2_P_WARNING"]

#: A correlation between two parameters above this (in magnitude) is warned about.
CORRELATION_WARNING = 0.95
#: A distinct minimum whose χ² exceeds the best's by less than this (times the
#: residuals' scale, 1 with σ, χ²/dof without) is warned about: the data hardly
#: prefer the best (Δχ² = 9 is a 3σ likelihood-ratio difference for one parameter).
IDENTIFIABILITY_DELTA = 9.0
#: With σ given, a χ² whose p-value (the chance that the right model with the
#: right σ gives a χ² at least as large) is below this is warned about.
CHI2_P_WARNING = 1e-3


@dataclass
class Minimum:
    """A start's local minimum: ``chi2``, the parameters ``x``, the start's number,
    its evaluations and where the start came from (``nominal``, ``random`` or the
    global stage's name)."""

    chi2: float
    x: np.ndarray
    start: int
    evaluations: int
    origin: str


def _file_name(prefix: str, name: str) -> str:
    return f"{prefix}_" + re.sub(r"[^A-Za-z0-9_.-]", "_", name) + ".csv"


@dataclass
class FitResult:
    """A fitted measurement (see :func:`thinfilm_mi.design.fit`).

    ``x``: the fitted parameters (in the order of ``names``); ``se``: their
    standard errors; ``covariance``; ``chi2`` and ``dof`` (points - parameters);
    ``minima``: the distinct minima, best first (the next-best's χ² is the
    identifiability check); ``found``: every start's minimum; ``seconds``: wall
    time; ``tolerance``: the thickness-error analysis when asked for.
    """

    measurement: Measurement
    model: FitModel
    x: np.ndarray
    se: np.ndarray
    covariance: np.ndarray
    chi2: float
    dof: int
    minima: list[Minimum]
    found: list[Minimum]
    seconds: float
    tolerance: dict | None = None
    _values: Any = field(default=None, repr=False)

    # -- the parameters ------------------------------------------------------
    @property
    def problem(self) -> Measurement:
        """The measurement (its ``substrate``, ``substrate_spec`` and ``ambient_spec``, as a design's problem)."""
        return self.measurement

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.measurement.parameters]

    @property
    def values(self) -> dict[str, float]:
        return dict(zip(self.names, map(float, self.x)))

    @property
    def errors(self) -> dict[str, float]:
        return dict(zip(self.names, map(float, self.se)))

    @property
    def correlation(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.covariance / np.outer(self.se, self.se)

    @property
    def reduced_chi2(self) -> float:
        return self.chi2 / self.dof

    @property
    def p_value(self) -> float | None:
        """With σ given, the chance that the right model with the right σ gives a
        χ² at least this large (χ² distribution of ``dof`` degrees); else ``None``."""
        if not self.measurement.sigma_given:
            return None
        from scipy.stats import chi2

        return float(chi2.sf(self.chi2, self.dof))

    @property
    def next_best(self) -> Minimum | None:
        return self.minima[1] if len(self.minima) > 1 else None

    def warnings(self) -> list[str]:
        """What a reader of the fit should know: an implausible χ² (σ given), strong
        correlations, undetermined parameters, parameters at a bound, a near minimum."""
        out = []
        pv = self.p_value
        if pv is not None and pv < CHI2_P_WARNING:
            chance = f"{pv:.2g}" if pv > 0 else "below 1e-300"
            out.append(f"χ²/dof {self.reduced_chi2:.4g} is implausible for the σ given (p-value {chance} for "
                       f"{self.dof} degrees of freedom): the fit may have ended in a local minimum (start "
                       "nearer the truth, or bound the thicknesses: the global stage searches within the bounds), "
                       "the model may be wrong (a missing film, a dispersion not modelled, the substrate's back "
                       "side), or σ may be too small")
        rho = self.correlation
        names = self.names
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                if abs(rho[i, j]) > CORRELATION_WARNING:
                    out.append(f"{names[i]} and {names[j]} are correlated (ρ = {rho[i, j]:+.3f}): the data "
                               "determine a combination of them better than either")
        for name, se in zip(names, self.se):
            if not np.isfinite(se):
                out.append(f"{name} is not determined by the data (its standard error is infinite)")
        for p, v in zip(self.measurement.parameters, self.x):
            if v <= p.lower or v >= p.upper:
                out.append(f"{p.name} = {v:.6g} is at its bound [{p.lower:g}, {p.upper:g}]; its standard "
                           "error ignores the bound")
        nb = self.next_best
        scale = 1.0 if self.measurement.sigma_given else self.reduced_chi2
        if nb is not None and (nb.chi2 - self.chi2) / max(scale, 1e-300) < IDENTIFIABILITY_DELTA:
            out.append(f"a distinct minimum (start {nb.start}) fits almost as well: χ² {nb.chi2:.6g} against "
                       f"{self.chi2:.6g}; the fit may not be unique")
        return out

    # -- the spectra -----------------------------------------------------------
    def fitted(self) -> list[np.ndarray]:
        """The modelled value of every data set's points at the fit."""
        if self._values is None:
            self._values = self.model.predict(self.x, jac=False)[0]
        return self._values

    def residuals(self) -> list[np.ndarray]:
        """Per data set ``(model - measured) / sigma`` (sigma 1 when the data carry none)."""
        return [(v - d.value) / s for v, d, s in zip(self.fitted(), self.measurement.datasets, self.model.sigma)]

    # -- the stack -------------------------------------------------------------
    def thicknesses(self) -> np.ndarray:
        return self.model.thicknesses(self.x)[0]

    def _material_specs(self, folder: Path | None, x: np.ndarray, prefix: str) -> list[str]:
        params = self.model.disp_cols
        out = []
        for key, _ in self.measurement.films:
            f = self.measurement.materials[key]
            if f.model is None:
                out.append(f.name)
                continue
            values = dict(f.model.values)
            values.update({p: float(x[c]) for (k, p), c in params.items() if k == key})
            c = f.model.constant(values)
            if c is not None:
                out.append(format_index(c))
                continue
            path = Path(_file_name(prefix, key)) if folder is None else Path(folder) / _file_name(prefix, key)
            if folder is not None:
                path.parent.mkdir(parents=True, exist_ok=True)
                mat = f.model.material(values, f"{prefix} {key}")
                save_material(mat, path, mat.knots())
            out.append(str(path.resolve() if folder is not None else path))
        return out

    def layers_in(self, folder: str | Path | None = None) -> str:
        """The fitted stack as a ``layers`` string; a fitted dispersive material is
        a table ``fit_NAME.csv`` written into ``folder`` (and named by its path),
        or only named when ``folder`` is ``None``."""
        specs = self._material_specs(None if folder is None else Path(folder), self.x, "fit")
        return format_layers(zip(specs, self.thicknesses()))

    def nominal_layers_in(self, folder: str | Path | None = None) -> str:
        """The nominal stack (the file's start values) as :meth:`layers_in` writes
        the fitted one (its tables ``nominal_NAME.csv``)."""
        x0 = self.model.x0
        specs = self._material_specs(None if folder is None else Path(folder), x0, "nominal")
        return format_layers(zip(specs, self.model.thicknesses(x0)[0]))

    @property
    def layers(self) -> str:
        """The fitted stack as a ``layers`` string (see :meth:`layers_in` for fitted dispersive materials)."""
        return self.layers_in(None)

    # -- tolerance -------------------------------------------------------------
    def tolerance_analysis(self, spec: ToleranceSpec | str, seed: int = 0) -> dict:
        """Thickness errors on the fitted stack (``"1%:200"``, as ``design --tolerance``):
        χ²/dof of each draw against the data, and each data set's RMS change from the fit."""
        spec = parse_tolerance(spec) if isinstance(spec, str) else spec
        D = draw_thicknesses(self.thicknesses(), spec, seed)
        fitted = self.fitted()
        chi, change = [], []
        for k in range(spec.draws):
            values, _ = self.model.predict(self.x, jac=False, d=D[:, k])
            e = np.concatenate([(v - ds.value) / s for v, ds, s in
                                zip(values, self.measurement.datasets, self.model.sigma)])
            chi.append(float(e @ e) / self.dof)
            change.append([float(np.sqrt(np.mean((v - f) ** 2))) for v, f in zip(values, fitted)])
        change = np.array(change)
        self.tolerance = {"spec": spec.text, "sigma": spec.sigma, "relative": spec.relative, "draws": spec.draws,
                          "distribution": spec.distribution.name, "seed": seed,
                          "reduced_chi2": {"fitted": self.reduced_chi2, **stats(chi)},
                          "datasets": [{"data": d.index, "rms_change": stats(change[:, i])}
                                       for i, d in enumerate(self.measurement.datasets)]}
        return self.tolerance

    # -- reports ---------------------------------------------------------------
    def parameter_records(self) -> list[dict]:
        rho = self.correlation
        return [{"name": p.name, "value": float(v), "se": float(s), "start": float(p.value),
                 "bounds": [float(p.lower), float(p.upper)],
                 "correlation": json_list(np.nan_to_num(rho[i], nan=0.0))}
                for i, (p, v, s) in enumerate(zip(self.measurement.parameters, self.x, self.se))]

    def to_dict(self) -> dict:
        nb = self.next_best
        out = {"layers": self.layers, "chi2": float(self.chi2), "dof": int(self.dof),
               "reduced_chi2": float(self.reduced_chi2), "p_value": self.p_value,
               "sigma_given": self.measurement.sigma_given,
               "seconds": float(self.seconds), "parameters": self.parameter_records(),
               "next_best_chi2": None if nb is None else float(nb.chi2),
               "starts": [{"start": r.start, "origin": r.origin, "chi2": float(r.chi2),
                           "evaluations": r.evaluations} for r in self.found],
               "warnings": self.warnings(),
               "datasets": [{"data": d.index, "file": d.file, "quantity": d.quantity,
                             "polarization": d.polarization.name, "wavelengths": json_list(d.wavelengths),
                             "angles": json_list(d.angles), "measured": json_list(d.value),
                             "fitted": json_list(v), "residuals": json_list(r)}
                            for d, v, r in zip(self.measurement.datasets, self.fitted(), self.residuals())]}
        if self.tolerance is not None:
            out["tolerance"] = self.tolerance
        return out

    def to_json(self, **kwargs) -> str:
        return json.dumps(self.to_dict(), **kwargs)

    def table(self) -> str:
        m = self.measurement
        nb = self.next_best
        pv = self.p_value
        unit = f", p-value {pv:.3g}" if pv is not None else " (no σ given: errors scaled by χ²/dof)"
        origins = [r.origin for r in sorted(self.found, key=lambda r: r.start)]
        kinds = ", ".join(f"{origins.count(o)} {o}" for o in dict.fromkeys(origins))
        lines = [f"fit: {len(self.x)} parameters, {self.model.points} points, {len(self.found)} starts ({kinds}), "
                 f"{self.seconds:.1f} s",
                 f"χ² {self.chi2:.6g}, dof {self.dof}, χ²/dof {self.reduced_chi2:.4g}{unit}",
                 "next-best distinct minimum: " + ("none found" if nb is None else
                                                    f"χ² {nb.chi2:.6g} (start {nb.start})"),
                 f"layers: {self.layers or '(none)'}", "",
                 f"  {'parameter':<20} {'value':>14} {'std error':>12} {'start':>12}"]
        for p, v, s in zip(m.parameters, self.x, self.se):
            lines.append(f"  {p.name:<20} {v:>14.6g} {s:>12.3g} {p.value:>12.6g}")
        lines += ["", f"  {'data':<24} {'what':<44} {'RMS resid':>10}"]
        for d, r in zip(m.datasets, self.residuals()):
            lines.append(f"  {d.name:<24} {d.describe():<44} {float(np.sqrt(np.mean(r ** 2))):>10.4g}")
        if len(self.x) > 1:
            rho = np.nan_to_num(self.correlation, nan=0.0)
            lines += ["", "correlation:"] + [f"  {n:<20} " + " ".join(f"{c:+.2f}" for c in row)
                                              for n, row in zip(self.names, rho)]
        for w in self.warnings():
            lines.append(f"warning: {w}")
        if self.tolerance is not None:
            t = self.tolerance
            c = t["reduced_chi2"]
            lines += ["", f"tolerance: {t['draws']} draws of {t['spec']} thickness errors, seed {t['seed']}",
                      f"  χ²/dof: fitted {c['fitted']:.4g}, mean {c['mean']:.4g}, std {c['std']:.4g}, "
                      f"worst {c['worst']:.4g}"]
            for rec, d in zip(t["datasets"], m.datasets):
                s = rec["rms_change"]
                lines.append(f"  {d.name}: RMS change from the fit mean {s['mean']:.3g}, worst {s['worst']:.3g}")
        return "\n".join(lines)

    def figure(self):
        """Measured against fitted spectra, and the residuals (a matplotlib figure)."""
        from matplotlib.figure import Figure

        fig = Figure(figsize=(7.5, 6.0), dpi=110)
        top, bottom = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
        for d, v, r in zip(self.measurement.datasets, self.fitted(), self.residuals()):
            order = np.lexsort((d.wavelengths, d.angles))
            line, = top.plot(d.wavelengths[order], v[order], lw=1.1, label=f"{d.name}: {d.describe()}"[:70])
            top.plot(d.wavelengths, d.value, ls="none", marker=".", ms=2.5, color=line.get_color())
            bottom.plot(d.wavelengths[order], r[order], lw=0.8, color=line.get_color())
        top.set_ylabel("fraction of incident power")
        top.set_title(f"measured (dots) and fitted (lines); χ²/dof {self.reduced_chi2:.3g}", fontsize=8)
        top.legend(fontsize=6)
        bottom.axhline(0.0, color="k", lw=0.6)
        bottom.set_ylabel("(fitted - measured) / σ" if self.measurement.sigma_given else "fitted - measured")
        bottom.set_xlabel("wavelength (nm)")
        for ax in (top, bottom):
            ax.grid(alpha=0.3)
        fig.suptitle(f"fitted: {self.layers}"[:150], fontsize=8)
        fig.tight_layout()
        return fig
