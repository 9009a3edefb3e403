"""``design``, ``refine`` and ``evaluate``: a targets file in, a :class:`DesignResult` out."""
from __future__ import annotations

import dataclasses
import time
from typing import Any, Callable

import numpy as np

from thinfilm_mi.design.merit import Design, Merit
from thinfilm_mi.design.result import DesignResult
from thinfilm_mi.design.synthesis import refine as _refine
from thinfilm_mi.design.synthesis import run
from thinfilm_mi.design.targets import Problem, films_from_layers, load_problem
from thinfilm_mi.design.tolerance import ToleranceSpec, parse_tolerance, tolerance_analysis
from thinfilm_mi.errors import ThinFilmError

__all__ = ["design", "refine", "evaluate"]


def _problem(targets: Any, **overrides) -> Problem:
    problem = targets if isinstance(targets, Problem) else load_problem(targets)
    problem = dataclasses.replace(problem, materials=list(problem.materials))
    for key, least in (("max_layers", 1), ("seeds", 1), ("seed", 0)):
        value = overrides.get(key)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
            raise ThinFilmError(f"{key}: expected an integer >= {least}, got {value!r}")
        problem = dataclasses.replace(problem, **{key: int(value)})
    return problem


def _spec(tolerance: ToleranceSpec | str | None) -> ToleranceSpec | None:
    return parse_tolerance(tolerance) if isinstance(tolerance, str) else tolerance


def _design_of(problem: Problem, layers: Any, name: str) -> tuple[Merit, Design]:
    """The stack of a ``layers`` string (its materials matched to the problem's,
    or added) and the merit of the problem with those materials."""
    films, free = films_from_layers(problem.materials, layers, problem.base, name)
    merit = Merit(problem)
    return merit, Design([m for m, _ in films], np.array([d for _, d in films], dtype=np.float64),
                         merit.initial_n(free))


def _finish(problem: Problem, merit: Merit, design: Design, t0: float, history: list,
            tolerance: ToleranceSpec | str | None, tolerance_seed: int) -> DesignResult:
    """Round to what ``layers`` prints (0.1 pm, free indices to 1e-6) and report that."""
    rounded = Design(list(design.films), np.round(design.d, 4), np.round(design.n, 6))
    e, _, values = merit.evaluate(rounded, jac=False, report=True)
    value = float(np.sqrt(e @ e / merit.points))
    tol = None if tolerance is None else tolerance_analysis(merit, rounded, _spec(tolerance), seed=tolerance_seed)
    return DesignResult(problem, merit, rounded, value, time.perf_counter() - t0, values, history, tol)


def design(targets: Any, *, start: str | None = None, max_layers: int | None = None,
           seeds: int | None = None, seed: int | None = None, time_limit: float | None = None,
           tolerance: str | ToleranceSpec | None = None, tolerance_seed: int = 0,
           progress: Callable[[float, str], None] | None = None) -> DesignResult:
    """Design a stack for ``targets`` (a targets file path, YAML text, dict or
    :class:`~thinfilm_mi.design.targets.Problem`): needle synthesis from
    ``start`` (a ``layers`` string; default the file's ``start``) or from
    ``seeds`` seed stacks, refinement, and a half-wave hop search on the best.
    ``max_layers``, ``seeds``, ``seed`` override the file's. ``time_limit``
    (seconds): no new seed is started after it. ``tolerance`` (e.g. ``"1%:200"``)
    adds a Monte-Carlo tolerance analysis of the result. ``progress(fraction,
    message)`` is called after each seed."""
    t0 = time.perf_counter()
    tolerance = _spec(tolerance)             # a bad tolerance fails before the design, not after
    problem = _problem(targets, max_layers=max_layers, seeds=seeds, seed=seed)
    if time_limit is not None and not (isinstance(time_limit, (int, float)) and time_limit > 0):
        raise ThinFilmError(f"time_limit: expected a number of seconds > 0, got {time_limit!r}")
    first = None
    if start is not None:
        _, first = _design_of(problem, start, "start")
        if len(first.films) > problem.max_layers:
            raise ThinFilmError(f"start: {len(first.films)} films, more than max_layers = {problem.max_layers}")
    merit, best, history = run(problem, start=first, time_limit=time_limit, progress=progress)
    return _finish(problem, merit, best, t0, history, tolerance, tolerance_seed)


def refine(targets: Any, layers: str, *, tolerance: str | ToleranceSpec | None = None,
           tolerance_seed: int = 0) -> DesignResult:
    """Refine the thicknesses (and free indices) of ``layers`` for ``targets``,
    no films added; films that reach 0 are removed."""
    t0 = time.perf_counter()
    merit, given = _design_of(_problem(targets), layers, "layers")
    best = _refine(merit, given)
    return _finish(merit.problem, merit, best, t0, [], tolerance, tolerance_seed)


def evaluate(targets: Any, layers: str, *, tolerance: str | ToleranceSpec | None = None,
             tolerance_seed: int = 0) -> DesignResult:
    """What ``layers`` achieves for ``targets``, unchanged (a free index at the
    value its films have in ``layers``, see
    :func:`~thinfilm_mi.design.targets.films_from_layers`)."""
    t0 = time.perf_counter()
    merit, given = _design_of(_problem(targets), layers, "layers")
    return _finish(merit.problem, merit, given, t0, [], tolerance, tolerance_seed)
