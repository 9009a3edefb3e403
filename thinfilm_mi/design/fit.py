"""``fit``: from measured spectra to the stack as built, with uncertainties.

    >>> from thinfilm_mi.design import fit
    >>> result = fit("examples/fit/measurements.yml")        # doctest: +SKIP
    >>> result.layers, result.reduced_chi2                     # doctest: +SKIP

The measurements file is :mod:`.fitfile`'s, the model :mod:`.fitmodel`'s. The
fit is weighted least squares, ``χ² = Σ ((model - measured) / σ)²``, by scipy's
bounded trust-region method (``least_squares(method="trf")``, as
:func:`.synthesis.refine` uses) on the exact Jacobian, from several starts
(thickness fits are multimodal: a film a half wave thicker fits the fringes
almost as well). The first start is the nominal stack, the others every
parameter off by a uniform random ``±spread`` (relative, or of its bounds'
width when both are finite).

At the best minimum the covariance of the parameters is ``(JᵀJ)⁻¹`` (the
linearised least-squares covariance; ``J`` the Jacobian of the weighted
residuals), multiplied by ``χ²/dof`` when the data carry no σ (their scatter is
then estimated from the residuals). Standard errors are its diagonal's square
roots; correlations above :data:`CORRELATION_WARNING` in magnitude, a
parameter at a bound, and a distinct minimum whose χ² is within
:data:`IDENTIFIABILITY_DELTA` (in units of the scatter) of the best are warned about.
"""
from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from thinfilm_mi.design.fitfile import Measurement, load_measurements
from thinfilm_mi.design.fitmodel import FitModel
from thinfilm_mi.design.fitresult import CORRELATION_WARNING, IDENTIFIABILITY_DELTA, FitResult, Minimum
from thinfilm_mi.design.tolerance import ToleranceSpec, parse_tolerance
from thinfilm_mi.errors import ThinFilmError

__all__ = ["fit", "fit_model", "CORRELATION_WARNING", "IDENTIFIABILITY_DELTA"]

#: Random starts screened (by χ², no Jacobian) per start that is descended from.
SCREEN_PER_START = 8
#: The size of the optimiser's first steps, relative to each parameter's start (see ``_solve``).
FIRST_STEP = 0.02


def _starts(model: FitModel, count: int, spread: float, seed: int) -> list[np.ndarray]:
    """The nominal start, and the ``count - 1`` best by χ² of :data:`SCREEN_PER_START`
    times as many random ones (each parameter off by a uniform ``±spread``)."""
    params = model.m.parameters
    x0 = model.x0
    if count == 1:
        return [x0]
    lo = np.array([p.lower for p in params])
    hi = np.array([p.upper for p in params])
    rng = np.random.default_rng(seed)
    width = np.where([p.relative for p in params], np.abs(x0), hi - lo)
    trials = np.clip(x0 + spread * width * rng.uniform(-1.0, 1.0, (SCREEN_PER_START * (count - 1), x0.size)),
                     lo, hi)
    cost = [float(e @ e) for e in (model.residuals(x, jac=False)[0] for x in trials)]
    return [x0] + [trials[i] for i in np.argsort(cost)[:count - 1]]


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
              progress: Callable[[float, str], None] | None = None) -> tuple[list[Minimum], np.ndarray]:
    """Every start's minimum (best first) and the Jacobian at the best."""
    _, J0 = model.residuals(model.x0)
    _check_parameters_seen(model, J0)
    found = []
    xs = _starts(model, starts, spread, seed)
    for i, x0 in enumerate(xs):
        x, chi2, nfev = _solve(model, x0, max_nfev)
        found.append(Minimum(chi2, x, i, nfev))
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
        tolerance: str | ToleranceSpec | None = None, tolerance_seed: int = 0,
        progress: Callable[[float, str], None] | None = None) -> FitResult:
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
    model = FitModel(m)
    found, J = fit_model(model, starts=starts or m.starts, spread=m.spread if spread is None else spread,
                         seed=m.seed if seed is None else seed, progress=progress)
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
