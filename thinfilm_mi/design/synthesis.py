"""Refinement and needle synthesis.

:func:`refine` moves every thickness (``>= 0``) and free index (within its
bounds) to a local minimum of the merit with scipy's bounded trust-region
least squares (``least_squares(method="trf")``, a Levenberg–Marquardt-like
method with bounds) on the exact Jacobian of :class:`~.merit.Merit`; films
that reach 0 (thinner than :data:`REMOVE_BELOW`) are then removed, their
neighbours merged when they are of one material, and the rest refined again.

:func:`synthesize` is needle optimisation (A. V. Tikhonravov, M. K. Trubetskov,
G. W. DeBell, "Application of the needle optimization technique to the design
of optical coatings", Appl. Opt. 35, 5493 (1996)): the needle function — the
derivative of the merit with respect to the thickness of a film of zero
thickness — is evaluated for every needle material at every depth of the
stack in one vectorised pass (:meth:`Merit.needle_function`); a needle goes
where it is most negative, its thickness is chosen by a short line search,
and the whole stack is refined. This repeats while a needle helps and the
stack has fewer than ``max_layers`` films.

:func:`run` is the whole design: from the problem's ``start``, or from several
seed stacks when there is none, keeping the best result.
"""
from __future__ import annotations

import math
import time
from typing import Callable

import numpy as np

from thinfilm_mi.design.merit import Design, Merit
from thinfilm_mi.design.targets import Problem

__all__ = ["refine", "clean", "insert_needle", "synthesize", "hop", "seed_designs", "run", "REMOVE_BELOW"]

#: Films thinner than this (nm) after a refinement count as having reached 0.
REMOVE_BELOW = 0.05

Progress = Callable[[float, str], None]


def _sum_sq(merit: Merit, design: Design) -> float:
    e, _ = merit.evaluate(design, jac=False)
    return float(e @ e)


def clean(design: Design) -> Design:
    """Remove films thinner than :data:`REMOVE_BELOW` and merge neighbours of one material."""
    films, d = [], []
    for m, t in zip(design.films, design.d):
        if t < REMOVE_BELOW:
            continue
        if films and films[-1] == m:
            d[-1] += t
        else:
            films.append(m)
            d.append(float(t))
    return Design(films, np.array(d, dtype=np.float64), np.array(design.n, dtype=np.float64))


def _least_squares(merit: Merit, design: Design, max_nfev: int) -> Design:
    from scipy.optimize import least_squares

    L, F = len(design.films), len(merit.free)
    if L + F == 0:
        return design.copy()
    bounds_n = merit.bounds_n()
    lb = np.r_[np.zeros(L), [b[0] for b in bounds_n]]
    ub = np.r_[np.full(L, np.inf), [b[1] for b in bounds_n]]
    x0 = np.clip(np.r_[design.d, design.n], lb, ub)
    cache: dict = {}

    def at(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = merit.evaluate(Design(design.films, x[:L], x[L:]))
        return cache[key]

    res = least_squares(lambda x: at(x)[0], x0, jac=lambda x: at(x)[1], bounds=(lb, ub), method="trf",
                        x_scale="jac", ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=max_nfev)
    x = np.clip(res.x, lb, ub)
    return Design(list(design.films), x[:L], x[L:])


def refine(merit: Merit, design: Design, max_nfev: int = 200) -> Design:
    """A local minimum of the merit from ``design``, thin films removed."""
    current = _least_squares(merit, design, max_nfev)
    for _ in range(len(design.films) + 1):
        cleaned = clean(current)
        if len(cleaned.films) == len(current.films):
            return cleaned
        current = _least_squares(merit, cleaned, max_nfev)
    return clean(current)


def _insert(design: Design, j: int, z: float, m: int, t: float) -> Design:
    """``design`` with a film of material ``m`` and thickness ``t`` at depth ``z`` of film ``j``."""
    films, d = list(design.films), list(design.d)
    if not films:
        return Design([m], np.array([t]), design.n.copy())
    top, bottom = z, d[j] - z
    new_f = films[:j] + [films[j], m, films[j]] + films[j + 1:]
    new_d = d[:j] + [top, t, bottom] + d[j + 1:]
    keep = [i for i in range(len(new_f)) if i == j + 1 or new_d[i] > 0]
    return Design([new_f[i] for i in keep], np.array([new_d[i] for i in keep]), design.n.copy())


def _line_search(merit: Merit, design: Design, j: int, z: float, m: int, base: float):
    """The best of needle thicknesses 1/8 to 64 times :attr:`Merit.needle_step`: ``(t, sum e^2)``."""
    best_t, best = None, base
    for t in merit.needle_step * 2.0 ** np.arange(-3, 7):
        trial = _sum_sq(merit, _insert(design, j, z, m, float(t)))
        if trial < best:
            best_t, best = float(t), trial
    return best_t, best


def insert_needle(merit: Merit, design: Design, max_layers: int) -> Design | None:
    """``design`` with the best needle inserted (its thickness by a line search),
    or ``None`` if no needle lowers the merit within ``max_layers`` films.

    A stack with no films has a needle function of 0 when the media do not absorb
    (a thin film changes only the phase of ``r`` to first order), so there the
    first film is the best of a line search for every needle material."""
    needle_mats = [i for i, dm in enumerate(merit.problem.materials) if dm.needle]
    base = _sum_sq(merit, design)
    if not design.films:
        tries = [(*_line_search(merit, design, 0, 0.0, m, base), m) for m in needle_mats]
        t, value, m = min(tries, key=lambda r: r[1])
        return None if t is None else _insert(design, 0, 0.0, m, t)
    depths, P = merit.needle_function(design)
    L = len(design.films)
    where = [(j, k) for j in range(L) for k in range(len(depths[j]))]
    order = np.argsort(P, axis=None)
    for flat in order[:64]:
        row, col = divmod(int(flat), P.shape[1])
        if P[row, col] >= -1e-12 * max(base, 1e-30):
            return None
        j, k = where[row]
        m = needle_mats[col]
        z = float(depths[j][k])
        host = design.films[j]
        inside = 0.0 < z < design.d[j]
        if m == host or (z == 0.0 and j > 0 and design.films[j - 1] == m) or \
                (z == design.d[j] and j < L - 1 and design.films[j + 1] == m):
            continue
        if L + (2 if inside else 1) > max_layers:
            continue
        best_t, _ = _line_search(merit, design, j, z, m, base)
        if best_t is not None:
            return _insert(design, j, z, m, best_t)
    return None


def synthesize(merit: Merit, design: Design, max_layers: int, deadline: float = math.inf) -> Design:
    """Needle optimisation from ``design`` (refined first) up to ``max_layers`` films."""
    current = refine(merit, design)
    value = merit.merit(current)
    while time.perf_counter() < deadline:
        trial = insert_needle(merit, current, max_layers)
        if trial is None:
            break
        trial = refine(merit, trial)
        trial_value = merit.merit(trial)
        if not trial_value < value * (1 - 1e-6):
            break
        current, value = trial, trial_value
    return current


def refine_batch(merit: Merit, films: list[int], D: np.ndarray, n: np.ndarray, iterations: int = 12
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg–Marquardt steps on B stacks of the same ``films`` at once
    (thicknesses ``D`` (L, B), kept >= 0; free indices fixed at ``n``): each step
    solves ``(J^T J + lambda diag(J^T J)) delta = -J^T e`` for every stack, keeps
    it where it lowers that stack's ``sum(e^2)`` (then lambda / 3, else x 4).
    Returns ``(D, sum(e^2))``: a cheap first descent for many starts."""
    L = len(films)
    D = np.array(D, dtype=np.float64)
    e, J = merit.evaluate(Design(list(films), D, n))
    J = J[..., :L]
    cost = np.sum(e * e, axis=0)
    lam = np.full(D.shape[1], 1e-3)
    eye = np.eye(L)
    for _ in range(iterations):
        JtJ = np.einsum("nbk,nbl->bkl", J, J)
        g = np.einsum("nbk,nb->bk", J, e)
        diag = np.einsum("bkk->bk", JtJ) + 1e-12
        A = JtJ + lam[:, None, None] * diag[:, :, None] * eye
        step = np.linalg.solve(A, -g[..., None])[..., 0]                     # (B, L)
        trial = np.maximum(D + step.T, 0.0)
        e2, J2 = merit.evaluate(Design(list(films), trial, n))
        cost2 = np.sum(e2 * e2, axis=0)
        ok = cost2 < cost
        D[:, ok], e[:, ok], J[:, ok], cost[ok] = trial[:, ok], e2[:, ok], J2[:, ok, :L], cost2[ok]
        lam = np.where(ok, lam / 3.0, lam * 4.0)
    return D, cost


def hop(merit: Merit, design: Design, deadline: float = math.inf, rounds: int = 10) -> Design:
    """Try every film a half wave thicker and thinner (at the targets' centre
    wavelength): all these stacks descend together (:func:`refine_batch`), the
    best is refined and kept if it lowers the merit; repeat (at most ``rounds``
    times) until none does. Interference repeats every half wave, so this leaps
    between the local minima that a film's thickness alone separates."""
    lam = _centre_wavelength(merit.problem)
    current, value = design, merit.merit(design)
    for _ in range(rounds):
        if not current.films or time.perf_counter() > deadline:
            break
        shifted = []
        for j, m in enumerate(current.films):
            dm = merit.problem.materials[m]
            n = dm.n0.real if dm.material.constant is not None else \
                float(dm.material.index(np.array([lam]))[0].real)
            for sign in (1.0, -1.0):
                d = current.d.copy()
                d[j] += sign * lam / (2.0 * n)
                if d[j] >= 0:
                    shifted.append(d)
        D, cost = refine_batch(merit, current.films, np.array(shifted).T, current.n)
        b = int(np.argmin(cost))
        if not cost[b] < value ** 2 * merit.points * (1 - 1e-6):
            break
        trial = refine(merit, Design(list(current.films), D[:, b], current.n.copy()))
        trial_value = merit.merit(trial)
        if not trial_value < value * (1 - 1e-6):
            break
        current, value = trial, trial_value
    return current


def _centre_wavelength(problem: Problem) -> float:
    spectral = [t.wavelengths for t in problem.targets if t.wavelengths is not None]
    return float(np.mean(np.concatenate(spectral))) if spectral else 550.0


#: Wavelength step (nm) of the colour integrals while synthesising; the final
#: refinement uses the 1 nm integrals of :mod:`thinfilm_mi.colour.report`. Spectra of
#: stacks up to several microns of optical thickness vary over tens of nm, which
#: linear interpolation between 5 nm samples follows closely.
SYNTHESIS_COLOUR_STEP = 5

#: Random stacks screened per screened seed (:func:`seed_designs`).
SCREEN_PER_SEED = 1024
#: Screened stacks per seed that take a few batched Levenberg–Marquardt steps.
DESCENT_PER_SEED = 32
#: Screened seeds of the same materials differ by more than this (nm) in some film.
SEED_DISTANCE = 20.0


def seed_designs(merit: Merit, count: int, seed: int) -> list[Design]:
    """``count`` starting stacks, for a problem that gives none.

    Half of them (rounded up) are single films of each needle material in turn,
    a quarter wave, a half wave, three quarters ... thick at the centre
    wavelength of the targets: synthesis grows them with needles, and adds films
    at either end. The others come from :data:`SCREEN_PER_SEED` random stacks
    per seed (1 to ``max_layers`` films alternating the needle materials from a
    random first one, each 10-300 nm; ``numpy.random.default_rng(seed)``),
    ranked by ``merit`` (all of them at once, :meth:`Merit.merits`; :func:`run`
    passes the merit with colour integrals on a 5 nm grid): the best
    :data:`DESCENT_PER_SEED` per seed take a few Levenberg–Marquardt steps
    together (:func:`refine_batch`), and the best of those that differ by more
    than :data:`SEED_DISTANCE` are the seeds.
    """
    problem = merit.problem
    mats = [i for i, dm in enumerate(problem.materials) if dm.needle]
    lam = _centre_wavelength(problem)
    n = merit.initial_n()

    def real_index(m):
        dm = problem.materials[m]
        return dm.n0.real if dm.material.constant is not None else float(dm.material.index(np.array([lam]))[0].real)

    n_single = (count + 1) // 2
    out = [Design([mats[i % len(mats)]],
                  np.array([(i // len(mats) + 1) * lam / (4.0 * real_index(mats[i % len(mats)]))]),
                  n.copy()) for i in range(n_single)]
    n_screen = count - n_single
    if n_screen <= 0:
        return out
    rng = np.random.default_rng(seed)
    by_films: dict[tuple, list[np.ndarray]] = {}
    for _ in range(SCREEN_PER_SEED * n_screen):
        size = int(rng.integers(1, problem.max_layers + 1))
        first = int(rng.integers(len(mats)))
        films = tuple(mats[(first + k) % len(mats)] for k in range(size))
        by_films.setdefault(films, []).append(rng.uniform(10.0, 300.0, size))
    ranked = []
    for films, ds in by_films.items():
        D = np.array(ds).T                                   # (L, B)
        for lo in range(0, D.shape[1], 256):
            chunk = D[:, lo:lo + 256]
            ranked += [(v, films, chunk[:, b]) for b, v in enumerate(merit.merits(list(films), chunk, n))]
    ranked.sort(key=lambda r: r[0])
    # the best DESCENT_PER_SEED per seed descend together, then the best distinct ones are seeds
    descended = []
    pool = ranked[:DESCENT_PER_SEED * n_screen]
    for films in {r[1] for r in pool}:
        D = np.array([r[2] for r in pool if r[1] == films]).T
        D, cost = refine_batch(merit, list(films), D, n)
        descended += [(cost[b], films, D[:, b]) for b in range(D.shape[1])]
    descended.sort(key=lambda r: r[0])
    chosen: list[tuple] = []
    for _, films, d in descended:
        if len(chosen) == n_screen:
            break
        if all(f != films or np.max(np.abs(c - d)) > SEED_DISTANCE for f, c in chosen):
            chosen.append((films, d))
    return out + [Design(list(f), d.copy(), n.copy()) for f, d in chosen]


def run(problem: Problem, *, start: Design | None = None, time_limit: float | None = None,
        progress: Progress | None = None) -> tuple[Merit, Design, list[dict]]:
    """The best design found: from ``start`` (or the problem's), else from
    :func:`seed_designs`, then :func:`hop`; with colour or Y targets all of this on
    colour integrals at :data:`SYNTHESIS_COLOUR_STEP`, and a last :func:`refine`
    on the exact ones. Returns ``(merit, design, history)``; ``history`` holds
    one record per start (``films``, ``merit``, ``seconds``). ``time_limit``
    (seconds): no new start begins after it (the one running finishes its
    current refinement)."""
    merit = Merit(problem)
    colour = any(t.quantity.colour_integral for t in problem.targets)
    fast = Merit(problem, colour_step=SYNTHESIS_COLOUR_STEP) if colour else merit
    t0 = time.perf_counter()
    deadline = t0 + time_limit if time_limit is not None else math.inf
    if start is None and problem.start is not None:
        start = Design([m for m, _ in problem.start], np.array([d for _, d in problem.start]),
                       merit.initial_n(problem.start_n))
    starts = [start] if start is not None else seed_designs(fast, problem.seeds, problem.seed)
    best, best_value, history = None, math.inf, []
    for i, s in enumerate(starts):
        if best is not None and time.perf_counter() > deadline:
            break
        t1 = time.perf_counter()
        result = synthesize(fast, s, problem.max_layers, deadline)
        value = fast.merit(result)
        history.append({"start": i, "films": len(result.films), "merit": value,
                        "seconds": time.perf_counter() - t1})
        if value < best_value:
            best, best_value = result, value
        if progress:
            progress((i + 1) / (len(starts) + 1), f"start {i + 1}/{len(starts)}: {len(result.films)} films, "
                                                 f"merit {value:.4g} (best {best_value:.4g})")
    best = hop(fast, best, deadline)
    if fast is not merit:
        best = refine(merit, best)
    if progress:
        progress(1.0, f"half-wave hops: {len(best.films)} films, merit {merit.merit(best):.4g}")
    return merit, best, history
