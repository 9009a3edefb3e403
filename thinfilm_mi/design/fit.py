"""``fit``: from measured spectra to the stack as built, with uncertainties.

    >>> from thinfilm_mi.design import fit
    >>> result = fit("examples/fit/measurements.yml")        # doctest: +SKIP
    >>> result.layers, result.reduced_chi2                     # doctest: +SKIP

The measurements file is :mod:`.fitfile`'s, the model :mod:`.fitmodel`'s. The
fit is weighted least squares, ``χ² = Σ ((model - measured) / σ)²``, by scipy's
bounded trust-region method (``least_squares(method="trf")``, as
:func:`.synthesis.refine` uses) on the exact Jacobian, from several starts
(thickness fits are multimodal: a film a half wave thicker fits the fringes
almost as well). The first start is the nominal stack; the next are chosen by
the global stage (:data:`GLOBAL_STAGES`); the rest have every parameter off by
a uniform random ``±spread`` (relative, or of its bounds' width when both are
finite).

The global stage (``evolve``, :class:`Evolution`) is a population method, scipy's
``differential_evolution``, over the films' thicknesses within ±:data:`SEARCH_WIDTH`
of the nominal ones. A nominal stack 25 % off puts a thick film a fringe order
or more away, whose basin is narrow (a fraction of a fringe wide) in a landscape
of near-equal fits; the films are coupled, so a scan of one film at a time stops
in a wrong order. A population crosses the orders of all films together, and
its evaluations are cheap: the whole population at once
(:meth:`.FitModel.chi2`), on the data thinned to a few points per fringe.

At the best minimum the covariance of the parameters is ``(JᵀJ)⁻¹`` (the
linearised least-squares covariance; ``J`` the Jacobian of the weighted
residuals), multiplied by ``χ²/dof`` when the data carry no σ (their scatter is
then estimated from the residuals). Standard errors are its diagonal's square
roots; with σ given a χ² whose p-value is below :data:`CHI2_P_WARNING`,
correlations above :data:`CORRELATION_WARNING` in magnitude, a parameter at a
bound, and a distinct minimum whose χ² is within :data:`IDENTIFIABILITY_DELTA`
(in units of the scatter) of the best are warned about.
"""
from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import replace
from typing import Any, Callable

import numpy as np

from thinfilm_mi.design.fitfile import Measurement, load_measurements
from thinfilm_mi.design.fitmodel import FitModel
from thinfilm_mi.design.fitresult import CHI2_P_WARNING, CORRELATION_WARNING, IDENTIFIABILITY_DELTA, FitResult, Minimum
from thinfilm_mi.design.tolerance import ToleranceSpec, parse_tolerance
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.optics.choices import choose

__all__ = ["fit", "fit_model", "GlobalStage", "Evolution", "NoGlobalStage", "GLOBAL_STAGES", "as_global_stage",
           "search_box", "fringe_spacing", "thinned", "CHI2_P_WARNING", "CORRELATION_WARNING", "IDENTIFIABILITY_DELTA"]

#: Random starts screened (by χ², no Jacobian) per start that is descended from.
SCREEN_PER_START = 8
#: The size of the optimiser's first steps, relative to each parameter's start (see ``_solve``).
FIRST_STEP = 0.02
#: The global stage's box: each thickness parameter within this fraction of its start (unless bounded).
SEARCH_WIDTH = 0.4
#: The global stage's data: each spectrum thinned to this many points per period of its fastest fringe.
POINTS_PER_FRINGE = 4


class GlobalStage(ABC):
    """How the fit looks over the whole box of the films' thicknesses for the
    basin of the global minimum, before its local descents (:data:`GLOBAL_STAGES`)."""

    name: str

    @abstractmethod
    def search(self, model: FitModel, seed: int, count: int) -> list[np.ndarray]:
        """At most ``count`` starts (all parameters) for local descents; none when there is nothing to search."""


class NoGlobalStage(GlobalStage):
    """Only the local descents from the nominal start and the random starts around it."""

    name = "none"

    def search(self, model, seed, count):
        return []


class Evolution(GlobalStage):
    """scipy's ``differential_evolution`` over the thickness parameters within
    :func:`search_box` (the other parameters held at their starts), on χ² of the
    data thinned to :data:`POINTS_PER_FRINGE` points per fringe, its population
    evaluated at once (:meth:`.FitModel.chi2`); the nominal start is one of its
    members. A low ``recombination`` (the chance that a trial takes each parameter
    from its mutant) moves a few films at a time, as the fringe orders of
    different films are nearly separable. Its ``polish`` best members (each at
    least ``distinct`` of the box apart from a better one in some parameter)
    start local descents on all the data."""

    name = "evolve"

    def __init__(self, popsize: int = 20, generations: int = 60, recombination: float = 0.3, tol: float = 0.01,
                 polish: int = 3, distinct: float = 0.02):
        self.popsize, self.generations, self.recombination, self.tol = popsize, generations, recombination, tol
        self.polish, self.distinct = polish, distinct

    def search(self, model, seed, count):
        from scipy.optimize import differential_evolution

        cols, lo, hi = search_box(model)
        if not cols or count < 1:
            return []
        x0 = model.x0
        coarse = FitModel(thinned(model.m, fringe_spacing(model, cols, hi)))
        d0, dd = model.thicknesses(x0)
        dd = dd[:, cols]

        def cost(X):            # X (thickness parameters, members)
            return coarse.chi2(x0, d0[:, None] + dd @ (X - x0[cols][:, None]))

        res = differential_evolution(cost, list(zip(lo, hi)), x0=np.clip(x0[cols], lo, hi), popsize=self.popsize,
                                     maxiter=self.generations, recombination=self.recombination, tol=self.tol,
                                     seed=seed, polish=False, vectorized=True, updating="deferred", init="sobol")
        chosen: list[np.ndarray] = []
        for member in res.population[np.argsort(res.population_energies)]:
            if all(np.any(np.abs(member - c) > self.distinct * (hi - lo)) for c in chosen):
                chosen.append(member)
            if len(chosen) == min(self.polish, count):
                break
        starts = np.repeat(x0[None, :], len(chosen), axis=0)
        starts[:, cols] = chosen
        return list(starts)


#: The global stages by name (the default first).
GLOBAL_STAGES: dict[str, GlobalStage] = {s.name: s for s in (Evolution(), NoGlobalStage())}


def as_global_stage(value: Any) -> GlobalStage:
    """The :class:`GlobalStage` that ``value`` names (an object passes through)."""
    return value if isinstance(value, GlobalStage) else choose(GLOBAL_STAGES, value, "global stage")


def search_box(model: FitModel) -> tuple[list[int], np.ndarray, np.ndarray]:
    """``(columns, lo, hi)`` of the thickness parameters searched: their bounds
    where both are finite, else their start ± :data:`SEARCH_WIDTH` of it within
    their bounds (a parameter whose box is empty, a film of 0 nm, is not searched)."""
    params = [model.m.parameters[c] for c in model.thick_cols]
    x0 = model.x0[model.thick_cols]
    lower = np.array([p.lower for p in params])
    upper = np.array([p.upper for p in params])
    bounded = np.isfinite(lower) & np.isfinite(upper)
    lo = np.where(bounded, lower, np.maximum(lower, x0 * (1 - SEARCH_WIDTH)))
    hi = np.where(bounded, upper, np.minimum(upper, x0 * (1 + SEARCH_WIDTH)))
    keep = hi > lo
    return [c for c, k in zip(model.thick_cols, keep) if k], lo[keep], hi[keep]


def fringe_spacing(model: FitModel, cols: list[int], hi: np.ndarray) -> float:
    """The wavelength step (nm) of :data:`POINTS_PER_FRINGE` points per period of
    the fastest fringe of stacks within the box (``hi``: the upper ends of the
    parameters ``cols``): ``λ² / (2 Σ n_j d_j)`` at the shortest wavelength,
    ``n_j`` each film's largest index."""
    x = model.x0.copy()
    x[cols] = hi
    path = float(model.peak_indices(model.x0) @ model.thicknesses(x)[0])
    wl = min(float(d.wavelengths.min()) for d in model.m.datasets)
    return wl * wl / (2.0 * max(path, 1e-9) * POINTS_PER_FRINGE)


def thinned(m: Measurement, spacing: float) -> Measurement:
    """``m`` with each data set's points at each angle thinned to one per ``spacing`` nm of wavelength."""
    datasets = []
    for ds in m.datasets:
        keep = np.zeros(ds.value.size, dtype=bool)
        for a in np.unique(ds.angles):
            idx = np.flatnonzero(ds.angles == a)
            _, first = np.unique(np.floor((ds.wavelengths[idx] - ds.wavelengths[idx].min()) / spacing),
                                 return_index=True)
            keep[idx[first]] = True
        datasets.append(replace(ds, wavelengths=ds.wavelengths[keep], angles=ds.angles[keep],
                                value=ds.value[keep], sigma=None if ds.sigma is None else ds.sigma[keep]))
    return replace(m, datasets=datasets)


def _random_starts(model: FitModel, count: int, spread: float, seed: int) -> list[np.ndarray]:
    """The ``count`` best by χ² of :data:`SCREEN_PER_START` times as many random
    starts (each parameter off by a uniform ``±spread`` from the nominal one)."""
    params = model.m.parameters
    x0 = model.x0
    if count < 1:
        return []
    lo = np.array([p.lower for p in params])
    hi = np.array([p.upper for p in params])
    rng = np.random.default_rng(seed)
    width = np.where([p.relative for p in params], np.abs(x0), hi - lo)
    trials = np.clip(x0 + spread * width * rng.uniform(-1.0, 1.0, (SCREEN_PER_START * count, x0.size)), lo, hi)
    cost = [float(e @ e) for e in (model.residuals(x, jac=False)[0] for x in trials)]
    return [trials[i] for i in np.argsort(cost)[:count]]


def _solve(model: FitModel, x0: np.ndarray, max_nfev: int) -> tuple[np.ndarray, float, int]:
    """A local minimum from ``x0``. The optimiser works on the offsets from
    ``x0`` in units of :data:`FIRST_STEP` of each parameter, so that its first trust
    region (of radius 1 at a zero start) is a few per cent of the start: with the
    default radius (the start's own size) a first step may leap over the
    fringes into another minimum."""
    from scipy.optimize import least_squares

    params = model.m.parameters
    lo = np.array([p.lower for p in params])
    hi = np.array([p.upper for p in params])
    x0 = np.clip(x0, lo, hi)
    unit = FIRST_STEP * np.maximum(np.abs(x0), np.where(np.isfinite(hi - lo), hi - lo, 0.0) / 10 + 1e-6)
    cache: dict = {}

    def at(y):
        key = y.tobytes()
        if key not in cache:
            cache.clear()
            e, J = model.residuals(x0 + unit * y)
            cache[key] = (e, J * unit)
        return cache[key]

    res = least_squares(lambda y: at(y)[0], np.zeros_like(x0), jac=lambda y: at(y)[1],
                        bounds=((lo - x0) / unit, (hi - x0) / unit), method="trf",
                        ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=max_nfev)
    x = np.clip(x0 + unit * res.x, lo, hi)
    e, _ = model.residuals(x, jac=False)
    return x, float(e @ e), int(res.nfev)


def _covariance(J: np.ndarray) -> np.ndarray:
    """``(JᵀJ)⁻¹`` by the SVD of ``J``; a direction the data do not determine
    (singular value below 1e-12 of the largest) gets an infinite variance."""
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    inv = np.where(s > 1e-12 * s.max(), 1.0 / np.maximum(s, 1e-300) ** 2, np.inf) if s.size else s
    with np.errstate(invalid="ignore"):
        cov = (Vt.T * inv) @ Vt
    undetermined = ~np.isfinite(inv)
    if np.any(undetermined):
        bad = np.any(np.abs(Vt[undetermined]) > 1e-6, axis=0)
        cov[bad, :] = np.nan
        cov[:, bad] = np.nan
        cov[bad, bad] = np.inf
    return cov


def _check_parameters_seen(model: FitModel, J: np.ndarray):
    for k, p in enumerate(model.m.parameters):
        if not np.any(J[:, k]):
            raise ThinFilmError(f"{model.m.source}: {p.name}: appears in no data (the modelled spectra do not "
                                f"depend on it at all)")


def fit_model(model: FitModel, *, starts: int, spread: float, seed: int, max_nfev: int = 200,
              global_stage: GlobalStage | str = "evolve",
              progress: Callable[[float, str], None] | None = None) -> tuple[list[Minimum], np.ndarray]:
    """Every start's minimum (best first) and the Jacobian at the best. Of the
    ``starts`` local descents the first is from the nominal stack, the next from
    the global stage's starts, the rest from :func:`_random_starts`."""
    stage = as_global_stage(global_stage)
    _, J0 = model.residuals(model.x0)
    _check_parameters_seen(model, J0)
    found = []
    chosen = stage.search(model, seed, starts - 1)
    random = _random_starts(model, starts - 1 - len(chosen), spread, seed)
    xs = [model.x0] + chosen + random
    origins = ["nominal"] + [stage.name] * len(chosen) + ["random"] * len(random)
    for i, (x0, origin) in enumerate(zip(xs, origins)):
        x, chi2, nfev = _solve(model, x0, max_nfev)
        found.append(Minimum(chi2, x, i, nfev, origin))
        if progress is not None:
            progress((i + 1) / len(xs), f"start {i + 1}/{len(xs)}: χ² {chi2:.4g}")
    found.sort(key=lambda r: r.chi2)
    _, J = model.residuals(found[0].x)
    return found, J


def _distinct(found: list[Minimum], se: np.ndarray) -> list[Minimum]:
    """The minima that differ from every better one by more than a standard
    error (or 1e-6 relative, where errors vanish) in some parameter."""
    kept: list[Minimum] = []
    for r in found:
        if all(np.any(np.abs(r.x - k.x) > np.maximum(np.nan_to_num(se, nan=0.0, posinf=0.0),
                                                        1e-6 * (np.abs(k.x) + 1e-3))) for k in kept):
            kept.append(r)
    return kept


def fit(measurements: Any, *, starts: int | None = None, seed: int | None = None, spread: float | None = None,
        global_stage: GlobalStage | str = "evolve", tolerance: str | ToleranceSpec | None = None,
        tolerance_seed: int = 0, progress: Callable[[float, str], None] | None = None) -> FitResult:
    """Fit the free parameters of ``measurements`` (a measurements file path,
    YAML text, dict or :class:`~.fitfile.Measurement`; see :mod:`.fitfile`) to
    its data. ``starts``, ``seed``, ``spread`` override the file's.
    ``tolerance`` (e.g. ``"1%:200"``) adds a Monte-Carlo analysis of thickness
    errors on the fitted stack. ``progress(fraction, message)`` is called after
    each start."""
    t0 = time.perf_counter()
    spec = parse_tolerance(tolerance) if isinstance(tolerance, str) else tolerance
    m = measurements if isinstance(measurements, Measurement) else load_measurements(measurements)
    for key, value, low in (("starts", starts, 1), ("seed", seed, 0)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                                  or value < low):
            raise ThinFilmError(f"{key}: expected an integer >= {low}, got {value!r}")
    if spread is not None and not (isinstance(spread, (int, float)) and 0 <= spread < 1):
        raise ThinFilmError(f"spread: expected a fraction in [0, 1), got {spread!r}")
    stage = as_global_stage(global_stage)
    model = FitModel(m)
    found, J = fit_model(model, starts=starts or m.starts, spread=m.spread if spread is None else spread,
                         seed=m.seed if seed is None else seed, global_stage=stage, progress=progress)
    best = found[0]
    dof = model.points - best.x.size
    if dof <= 0:
        raise ThinFilmError(f"{m.source}: {model.points} data points for {best.x.size} free parameters; "
                            "a fit needs more points than parameters")
    reduced = best.chi2 / dof
    cov = _covariance(J) * (1.0 if m.sigma_given else reduced)
    se = np.sqrt(np.diag(cov))
    minima = _distinct(found, se)
    result = FitResult(m, model, best.x, se, cov, best.chi2, dof, minima, found, time.perf_counter() - t0)
    if spec is not None:
        result.tolerance_analysis(spec, tolerance_seed)
    return result
