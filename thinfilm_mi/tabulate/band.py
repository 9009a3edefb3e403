"""Band-limited tables: a stack's ``R`` and ``T`` convolved along the spectrum, for
stacks whose exact values no table resolves (no plugin classes here).

Ten or more films on a metal form cavities with resonances ~0.1 nm wide and
narrower: a cubic table of the exact ``R`` would need millions of texels. But a
spectral render integrates ``R(λ)`` against smooth emitter x colour-matching
curves, and no real light is monochromatic, so a resonance narrower than the
light's bandwidth changes an image only by its area. A band-limited table holds

    R_σ(ν) = ∫ R(ν') G_σ(ν - ν') dν'        (and T_σ likewise)

with ``ν = 1/λ`` the wavenumber and ``G_σ`` a Gaussian of standard deviation
``σ_ν = spectral_resolution / 560²`` (nm⁻¹): ``spectral_resolution`` nm at
560 nm, 0.41x that at 360 nm and 2.2x at 830 nm. A Gaussian in wavenumber is
light of finite coherence: it multiplies every interference term of optical
path difference ``p`` by ``exp(-2 π² σ_ν² p²)``, so paths longer than the
coherence length ``1 / (2 π σ_ν)`` (~50 µm at the default 1 nm) stop
interfering, shorter ones are untouched. It is also uniform on the tables'
wavelength axis (uniform in ``ν``): ``R_σ`` needs the same node spacing
everywhere, half the nodes a Gaussian of constant width in λ would need.

**How ``R_σ`` is computed.** Per angle row (a node coordinate of the table's
angle axis), the exact ``R`` (float64) is integrated by adaptive Simpson along
``ν`` into bins of width ``w`` (:data:`KNOT_SHARE` σ_ν) with cubic B-spline
weights, ``I_b = ∫ R(ν) B((ν - ν_b) / w) dν``:

* the first level samples the amplitudes ``N``, ``D`` of the recursion
  (``R = |N|²/|D|²``, :func:`amplitudes`) 32 times per interference fringe
  of the whole stack (:func:`first_bin_step`); ``N`` and ``D`` are smooth where
  ``R`` has resonances, so every resonance shows as a zero of ``D`` near the
  real axis, found on the cubic through four samples (:func:`near_zeros`),
  however narrow it is;
* a panel is halved (two new exact values) until Simpson's error estimate is
  within :data:`TOLERANCE` times its width *and* it is no wider than
  :data:`GRADING` times its distance to the nearest zero of ``D``, down to
  :data:`MIN_PANEL` (~1e-4 nm);
* each accepted panel stands for the quadratic through its three values,
  integrated exactly against the B-splines (3-point Gauss-Legendre on each bin
  interval it covers);

then ``R_σ = Σ_b G_σ'(ν - ν_b) I_b`` with ``σ'² = σ_ν² - w²/3`` (the
B-spline's variance; the Gaussian of ``σ'`` times the B-spline is the Gaussian
of ``σ_ν`` to its fourth cumulant), one FFT per row.
``tests/tabulate/test_band.py`` checks ``R_σ`` against a brute-force convolution
of exact values on a 0.0005 nm grid (measured within 1e-5).

**The table** is the cubic B-spline of :mod:`thinfilm_mi.tabulate.exact` (same lookup;
the angle axis warped to put more nodes at mid angles,
:data:`~thinfilm_mi.tabulate.axes.BAND`, where ``R_σ``'s features move fastest with the angle),
its error ``table_error`` still the interpolation error, now against ``R_σ``,
verified outside the same grazing sliver; the angle rows are refined until the
spline through them predicts the midpoint rows within the target. Lit from the
ambient, its v axis is sheared (:class:`Shear`): ``ν' = ν
P(sin²θ)`` follows the films' fringes as the angle grows, so 65 rows do where the
plain axis needed 385 (the 30-film benchmark stack: one round, 0.3-0.4 s instead
of 0.8-1.4 s, a 4x smaller table); its nodes' values are the Gaussian summed over the
bins at ``ν'_t / P`` (:meth:`Rows.sample`), the bins spanning every
wavenumber a row's nodes reach. Lit from inside a denser medium (a split axis) the
v nodes sit on every other bin (their midpoints on the others), so a row gives
the whole spectrum. The build also checks the colour: the colour of ``R_σ`` against
that of ``R`` under D65, illuminant A and the line spectrum F11, per row and
channel, must be within :data:`COLOUR_TOLERANCE` (CIEDE2000); otherwise no
table is built (``tabulate="auto"`` then evaluates exactly).

The module is one algorithm (``ALGORITHMS`` in ``tests/cross/test_architecture.py`` lists it),
in four parts, each built on the ones before it: the sheared wavenumber axis
(:class:`Shear`), the smooth amplitudes of the rows' first level (:func:`amplitudes`,
:class:`Amplitudes`), the rows (:class:`Rows`) and the build (:func:`build_table`,
:func:`build_band_table`).

**The rows** (:class:`Rows`): per angle, the exact ``R`` (and ``T``) integrated by
adaptive Simpson along the wavenumber into B-spline bins of a fraction of the Gaussian's
width (:func:`sigma_nu`), with the resonances of the stack found as zeros of its smooth
denominator ``D`` and the panels graded around them.

**The amplitudes** of a row's first level: their evaluation in float64
(:func:`amplitudes`, ``R = |N|²/|D|²``), the channels from them (:func:`powers_of`; a
quantity's ``values``), the resonances they reveal as zeros of ``D`` near the real axis
(:func:`near_zeros`), and their interpolation between the samples (:class:`Amplitudes`),
which the adaptive panels read instead of the films.

**The sheared axis** (:class:`Shear`): ``ν' = ν P(sin²θ)``.

A stack's interference orders sit where ``ν Σ_j d_j q_j(θ)`` takes fixed values,
``q_j = Re sqrt(n_j² - n_0² sin²θ)`` (the films' normal wave numbers over ``ν``): as
the angle grows they move to larger ``ν`` together, by up to ~20 % at grazing
incidence for the benchmark stacks. On the plain (angle, wavenumber) grid every
fringe and resonance of ``R_σ`` therefore runs diagonally, and a cubic along the
angle needs hundreds of rows to follow it (385 for the 30-film benchmark stack at
1e-3). In the coordinate

    ν' = ν P(s),   s = sin²θ,   P(s) ≈ Σ_j d_j q_j(θ) / Σ_j d_j Re n_j

they run along the angle axis instead: measured on the benchmark stacks, a cubic
through 65 rows errs by 5e-4 (30 films; 0.28 unsheared) and 129 rows by 1.3e-4
(10 films; 9e-3 unsheared).

``P`` is a cubic in ``s`` fitted to that ratio at 550 nm (:meth:`Shear.of`). It is a
choice of coordinates, not an approximation: the build evaluates ``R_σ`` at the
wavenumbers ``ν'_t / P(s)`` of its nodes and the lookup computes the same ``ν'``
from the same coefficients, so how well ``P`` follows the films only decides how
many rows the table needs. The axis covers ``ν'`` from ``low = σ_min P_min`` to
``σ_max`` (360 nm at ``s = 0``), with ``P_min`` the least ``P`` on ``[0, 1]``.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from thinfilm_mi.colour import cie
from thinfilm_mi.optics.core import COMPONENTS, Cx
from thinfilm_mi.tabulate import exact
from thinfilm_mi.tabulate.axes import GHOST, AngleAxis, axis_for, band_cos
from thinfilm_mi.tabulate.base import (
    GRAZING_COS,
    MAX_U,
    MAX_V,
    SIGMA_MAX,
    SIGMA_MIN,
    BuildReport,
    SideData,
    Table,
    bspline_coefficients,
    bspline_midpoints,
    bspline_weights,
    evaluate_side,
    film_gather,
    opaque_float,
    side_indices,
    unique_wavelengths,
    with_ghosts,
)
from thinfilm_mi.tabulate.bilinear import SPLINE_SHARE, resample
from thinfilm_mi.tabulate.policy import MAX_TEXELS
from thinfilm_mi.tabulate.refine import (
    Budget,
    build_work,
    convergence_factor,
    optical_thickness,
    power_of_two_step,
)

__all__ = ["COLOUR_TOLERANCE", "EXPECTED_TOTAL", "FIRST_NU", "FIRST_ORDER", "GRADING",
           "ILLUMINANTS", "INTERPOLATION_NODES", "KNOT_SHARE", "MAX_ROUNDS", "MAX_STEP",
           "MIN_FACTOR", "MIN_PANEL", "MIN_PANEL_GRAZING", "REFERENCE_WAVELENGTH",
           "RESOLVE_DISTANCE", "SAMPLE_ROWS", "SHEAR_WAVELENGTH", "TAIL", "TOLERANCE", "V_SPACING",
           "Amplitudes", "Rows", "Shear", "amplitudes", "build_band_table", "build_table",
           "first_bin_step", "near_zeros", "powers_of", "samples_amplitudes",
           "sigma_nu"]


# -- the sheared wavenumber axis ---------------------------------------------------------
#: The wavelength (nm) of the indices ``P`` is fitted at.
SHEAR_WAVELENGTH = 550.0
#: Stacks whose ``P`` would fall below this on ``[0, 1]`` (films of index near or
#: below the ambient's, where ``q_j`` vanishes) keep the plain axis.
MIN_FACTOR = 0.5


def _range(coeffs) -> tuple[float, float]:
    """The least and the largest ``P`` on ``[0, 1]`` (on 257 points; between them a
    lookup falls within the table's ghost nodes)."""
    p = np.polynomial.polynomial.polyval(np.linspace(0.0, 1.0, 257), coeffs)
    return (float(p.min()), float(p.max())) if np.all(np.isfinite(p)) else (math.nan, math.nan)


class Shear:
    """``ν' = ν P(s)`` with ``P(s) = c0 + c1 s + c2 s² + c3 s³`` (``coeffs``) and the
    table's v axis from ``σ_max`` down to ``low`` (its node ``nv - 1``)."""

    def __init__(self, coeffs, low: float):
        self.coeffs = tuple(float(c) for c in coeffs)
        self.low = float(low)
        self._opaque = None

    @classmethod
    def of(cls, films, n0: complex) -> "Shear | None":
        """The shear of ``films`` (pairs ``(index function of λ, thickness)``, the
        coherent films) under an ambient of index ``n0``, or ``None`` where none helps
        (no films, or ``P`` below :data:`MIN_FACTOR`)."""
        if not films:
            return None
        wl = np.array([SHEAR_WAVELENGTH])
        n = np.array([complex(np.asarray(f(wl))[0]) for f, _ in films])
        d = np.array([float(t) for _, t in films])
        n0r = float(np.real(n0))
        total = float(np.sum(d * n.real))
        if total <= 0:
            return None
        s = 0.5 - 0.5 * np.cos(np.pi * (np.arange(33) + 0.5) / 33)     # Chebyshev points on [0, 1]
        q = np.sqrt((n[None, :] ** 2 - (n0r * n0r) * s[:, None]).astype(np.complex128)).real
        ratio = (q * d[None, :]).sum(axis=1) / total
        coeffs = np.polynomial.polynomial.polyfit(s, ratio, 3)
        low, _ = _range(coeffs)
        if not np.isfinite(low) or low < MIN_FACTOR:
            return None
        return cls(coeffs, SIGMA_MIN * low)

    @property
    def min_factor(self) -> float:
        """``P_min``: the least ``P`` on ``[0, 1]`` (``low / σ_min``)."""
        return self.low / SIGMA_MIN

    @property
    def max_factor(self) -> float:
        """The largest ``P`` on ``[0, 1]`` (1 at normal incidence, to the fit)."""
        return _range(self.coeffs)[1]

    def factor_np(self, s: np.ndarray) -> np.ndarray:
        """``P(s)`` (float64 numpy)."""
        return np.polynomial.polynomial.polyval(np.asarray(s, np.float64), self.coeffs)

    def factor(self, sin_i):
        """``P(sin_i²)`` in a render kernel (opaque coefficients: another stack's shear
        reuses the kernel)."""
        if self._opaque is None:
            self._opaque = [opaque_float(c) for c in self.coeffs]
        c0, c1, c2, c3 = self._opaque
        s = sin_i * sin_i
        return c0 + s * (c1 + s * (c2 + s * c3))

    def node_wavenumbers(self, t: np.ndarray, nv: int) -> np.ndarray:
        """``ν'`` of the v node coordinates ``t`` of an axis of ``nv`` nodes."""
        return SIGMA_MAX - np.asarray(t, np.float64) * ((SIGMA_MAX - self.low) / (nv - 1))

    def to_plain(self) -> dict:
        return {"coeffs": list(self.coeffs), "low": self.low}

    @classmethod
    def from_plain(cls, data: dict) -> "Shear":
        coeffs, low = data["coeffs"], data["low"]
        if len(coeffs) != 4 or not all(np.isfinite(coeffs)) or not 0 < low < SIGMA_MAX:
            raise ValueError(f"not a shear: {data!r}")
        return cls(coeffs, low)

# -- the smooth amplitudes of the first level --------------------------------------------
#: Panels near a zero ``z_p`` of the resonant denominator ``D`` are at most this
#: times their distance to it (:class:`_Resonances`): Simpson's error estimate
#: alone misses or mis-measures resonances a few samples wide (measured on the
#: 10-film stack: with 1, panels of 16 bins on the flank of a resonance 30 bins
#: wide erred by 1e-2 in area, R_σ by 1e-3).
GRADING = 0.5
#: Zeros farther from the axis than this many first-level samples ask nothing
#: of the first panels (two samples wide).
RESOLVE_DISTANCE = 2.0 / GRADING

#: Nodes of the interpolation of the first level's amplitudes (:class:`Amplitudes`):
#: a quintic through 6 samples 32 or more per fringe errs by ~1e-7 of the
#: amplitudes' scale (the cubic's ~2e-5 would move narrow resonances' areas).
INTERPOLATION_NODES = 6


class Amplitudes:
    """The first level's smooth amplitudes (:func:`amplitudes`, or a quantity's
    ``smooth_terms``) of a set of rows, interpolated along the wavenumber: the
    values (``R`` [, ``T``] or the quantity's channels) at any point between
    the samples, at the cost of a polynomial instead of the films' loop.

    ``N`` and ``D`` are smooth where ``R`` has resonances, made of the
    interference terms of the stack's optical paths; sampled 32 or more times per
    fringe of the longest (:func:`first_bin_step`), the quintic through the six samples
    around a point (Lagrange, :data:`INTERPOLATION_NODES`) gives them within ~1e-7
    of their scale. A resonance is a zero of ``D`` near the axis: an error ``ε`` of
    ``D`` moves it by ``ε / |D'|``, which changes the area of a resonance of half
    width ``d`` by a fraction ``~ε |D| / (|D'| d)`` (~1e-3 at the narrowest,
    :data:`MIN_PANEL`). The samples' power-of-two rescaling (``exponents``) is undone
    in units of their row's largest exponent, exactly (rows whose exponents spread
    over more than :data:`MAX_RANGE` are refined with the films instead)."""

    def __init__(self, terms: np.ndarray, exps: np.ndarray, cos: np.ndarray, quantity,
                 transmission: bool):
        R, P, K = terms.shape
        self.P, self.K, self.cos = P, K, cos
        self.quantity, self.transmission = quantity, transmission
        # the samples in units of 2^(their row's largest exponent), exact powers
        # of two: the amplitudes of s (channels 0-3) and p (4-7) once, the powers'
        # |T|^2 f (8, 9) twice (a quantity's exponents are 0); a row's range of
        # exponents is checked by :meth:`usable`
        shift = exps - exps.max(axis=1, keepdims=True)
        self.range = float(-shift.min()) if shift.size else 0.0
        flat = np.ascontiguousarray(terms, np.float64).reshape(R * P, K)   # the caller's, in place
        if self.range:
            scale = np.exp2(shift.reshape(R * P, 2))
            flat[:, 0:4] *= scale[:, 0:1]
            flat[:, 4:8] *= scale[:, 1:2]
            if quantity.squared_terms and K > 8:
                flat[:, 8:10] *= scale * scale
        self.flat = flat
        self._buffer = None

    #: Largest spread of a row's exponents (powers of two) the common unit
    #: may absorb: their squares stay far above float64's smallest normal.
    MAX_RANGE = 400.0

    def usable(self) -> bool:
        """Whether the samples' exponents are within :data:`MAX_RANGE` along every row."""
        return self.range <= self.MAX_RANGE

    def values(self, r: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The values (shape ``(points, C)``) at rows ``r`` and sample coordinates
        ``s`` (fractional indices of the first level's samples)."""
        from drjit.llvm import Float64, UInt32

        from thinfilm_mi.optics.backend import aligned_array, float64_array

        n, P, K = INTERPOLATION_NODES, self.P, self.K
        i0 = np.clip(np.floor(s).astype(np.int64) - (n // 2 - 1), 0, P - n)
        if self._buffer is None:      # one kernel for every stack of K channels
            self._buffer = float64_array(self.flat.ravel())
        x = float64_array(s - i0)
        at = aligned_array((r * P + i0) * K, np.uint32, UInt32)
        out = [Float64(0.0)] * K
        for k in range(n):
            w = Float64(1.0)
            for m in range(n):
                if m != k:
                    w = w * ((x - m) * (1.0 / (k - m)))
            for c in range(K):
                out[c] = dr.fma(w, dr.gather(Float64, self._buffer, at + (k * K + c)), out[c])
        dr.eval(*out)
        out = np.stack([np.array(v, dtype=np.float64) for v in out], axis=-1)
        q, tr = self.quantity, self.transmission
        f = q.values(out, tr)
        grazing = q.grazing(tr)
        near = np.clip(np.rint(s).astype(np.int64), 0, P - 1)
        return np.where((self.cos.reshape(-1)[r * P + near] <= 0.0)[:, None], grazing, f)


def samples_amplitudes(side: SideData) -> bool:
    """Whether the first level samples the amplitudes (:func:`amplitudes`): every
    coherent side with films (sides with incoherent films, whose evaluator has no
    such amplitudes, are sampled without the resonance search)."""
    return 0 < len(side.films) == len(side.fringe_films)


def amplitudes(side: SideData, cos0: np.ndarray, rows: np.ndarray, wl: np.ndarray,
               indices) -> tuple[np.ndarray, np.ndarray]:
    """The stack's projective amplitudes at points ``(cos0[i], wl[rows[i]])``:
    ``(terms, exponents)``, ``terms`` of shape ``(points, C)`` with channels
    ``Re, Im`` of ``N_s, D_s, N_p, D_p`` and, with transmission, ``|T_s|^2 f_s,
    |T_p|^2 f_p`` (``R = |N|^2 / |D|^2``, ``T = |T|^2 f / |D|^2``), and
    ``exponents`` of shape ``(points, 2)`` (s, p): ``N 2^E``, ``D 2^E`` are smooth
    functions of λ without the resonant denominator ``1 / D``, so a few nodes per
    fringe interpolate them where ``R`` itself would need hundreds.

    The films' loop of the render kernels in float64
    (:func:`thinfilm_mi.optics.core.stack_loop_terms` with ``smooth``: its
    power-of-two rescaling keeps every depth within range, and the exponents it
    sums undo it), the films gathered per point's row."""
    from drjit.llvm import Float64, UInt32

    from thinfilm_mi.optics import core as op
    from thinfilm_mi.optics.backend import aligned_array, float64_array

    n0, film_n, n_exit = indices
    film_n = [np.asarray(n, np.complex128) for n in film_n]
    n_exit = np.asarray(n_exit, np.complex128)
    at = aligned_array(rows, np.uint32, UInt32)

    def per_row(values):
        return dr.gather(Float64, float64_array(values), at)

    real = not any(np.any(n.imag) for n in film_n)
    re = np.concatenate([n.real for n in film_n])
    film = film_gather(film_n, [d for _, d in side.films], at, len(wl), real)
    exit_cx = Cx(per_row(n_exit.real), per_row(n_exit.imag) if np.any(n_exit.imag) else 0.0)
    terms, fac, grazing = op.stack_loop_terms(
        per_row(n0), float64_array(cos0), dr.opaque(UInt32, len(film_n), len(rows)), film,
        exit_cx, per_row(wl), transmission=side.transmission, n0_max=float(np.max(n0)),
        film_n_min=float(re.min()) if real else None, label="thinfilm_band", exponents=True,
        smooth=True)
    out = []
    for pol in COMPONENTS:
        N, D, _, _ = terms[pol]
        out += [N.re, N.im, D.re, D.im]
    if side.transmission:
        out += [dr.select(grazing, 0.0, terms[pol][2] * fac[pol]) for pol in COMPONENTS]
    exps = [terms[pol][3] for pol in COMPONENTS]
    dr.eval(*out, *exps)
    return (np.stack([np.array(v, dtype=np.float64) for v in out], axis=-1),
            np.stack([np.array(v, dtype=np.float64) for v in exps], axis=-1))


def powers_of(terms: np.ndarray, transmission: bool) -> np.ndarray:
    """``R`` [, ``T``] (last axis) from :func:`amplitudes` channels (any leading shape)."""
    Ns = terms[..., 0] ** 2 + terms[..., 1] ** 2
    Ds = terms[..., 2] ** 2 + terms[..., 3] ** 2
    Np = terms[..., 4] ** 2 + terms[..., 5] ** 2
    Dp = terms[..., 6] ** 2 + terms[..., 7] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        R = np.minimum(0.5 * (Ns / Ds + Np / Dp), 1.0)
        if not transmission:
            return R[..., None]
        T = 0.5 * (terms[..., 8] / Ds + terms[..., 9] / Dp)
    R = np.where(np.isfinite(R), R, 1.0)
    T = np.clip(np.where(np.isfinite(T), T, 0.0), 0.0, 1.0 - R)
    return np.stack([R, T], axis=-1)


def near_zeros(samples: np.ndarray, channel: int, exponents: np.ndarray | None = None) -> tuple:
    """Zeros of the complex function ``samples[..., channel] + i samples[...,
    channel + 1]`` (shape ``(rows, n, K)``, smooth on the samples' scale) near the
    real axis: ``(row, position, distance)`` arrays, position a sample
    coordinate, distance from the axis in sample steps, for the zeros within
    :data:`RESOLVE_DISTANCE` steps.

    A zero at ``x_p + i d`` makes ``|f|²`` a bowl ``∝ (x - x_p)² + d²`` along the
    axis, so only the samples where ``|f|²`` has a local minimum are examined:
    the cubic through the four samples around it is solved by Newton's method
    (8 steps from the minimum). With ``exponents`` (shape ``(rows, n)``) the
    function is ``f 2^exponents`` (:func:`amplitudes`): neighbours are compared,
    and the cubic fitted, in units of ``2^`` the middle sample's exponent (exact
    powers of two, so the result does not depend on the exponents' split)."""
    f = samples[..., channel] + 1j * samples[..., channel + 1]
    a2 = f.real * f.real + f.imag * f.imag
    n = a2.shape[1]
    before, here, after = a2[:, 0:n - 3], a2[:, 1:n - 2], a2[:, 2:n - 1]
    if exponents is not None:     # neighbours in units of 2^(the sample's exponent): exact
        e = exponents[:, 1:n - 2]
        before = before * np.exp2(2.0 * (exponents[:, 0:n - 3] - e))
        after = after * np.exp2(2.0 * (exponents[:, 2:n - 1] - e))
    low = (here <= before) & (here < after)
    r, i = np.nonzero(low)
    i = i + 1                                   # the minimum's sample, 1 .. n - 3
    f0, f1, f2, f3 = f[r, i - 1], f[r, i], f[r, i + 1], f[r, i + 2]
    if exponents is not None:     # the window in units of 2^(its minimum's exponent)
        e = exponents[r, i]
        f0, f2, f3 = (fk * np.exp2(exponents[r, i + k] - e) for fk, k in ((f0, -1), (f2, 1), (f3, 2)))
    # the cubic through (-1.5, f0), (-0.5, f1), (0.5, f2), (1.5, f3)
    b0 = (-f0 + 9.0 * (f1 + f2) - f3) / 16.0
    b1 = (f0 - 27.0 * f1 + 27.0 * f2 - f3) / 24.0
    b2 = (f0 - f1 - f2 + f3) / 4.0
    b3 = (-f0 + 3.0 * f1 - 3.0 * f2 + f3) / 6.0
    z = np.full(b0.shape, -0.5, np.complex128)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(8):
            z = z - (((b3 * z + b2) * z + b1) * z + b0) / ((3.0 * b3 * z + 2.0 * b2) * z + b1)
        scale = np.abs(b0) + np.abs(b1) + np.abs(b2) + np.abs(b3)
        ok = (np.isfinite(z) & (np.abs(((b3 * z + b2) * z + b1) * z + b0) <= 1e-6 * scale)
              & (np.abs(z.real + 0.5) <= 2.0) & (np.abs(z.imag) < RESOLVE_DISTANCE))
    return r[ok], (i + 0.5 + z.real)[ok], np.abs(z.imag)[ok]

# -- the rows ----------------------------------------------------------------------------
#: The wavelength (nm) at which ``spectral_resolution`` is the Gaussian's
#: standard deviation in nm (it scales as λ² elsewhere).
REFERENCE_WAVELENGTH = 560.0
#: Spacing of the table's v nodes in units of σ_ν: the cubic spline of ``R_σ``
#: along v is then within ~3e-4 (measured: 1.6e-4 for the 10-film and 3.2e-4
#: for the 30-film benchmark stack; at 0.8, 6.7e-4 and 1.3e-3); where that is not
#: enough the build makes it finer (and computes every row again).
V_SPACING = 0.6
#: A panel is accepted when its Simpson error estimate is within this times its
#: width in bins (``R_σ`` then errs by ~2x this: the Gaussian's peak is 0.4 / σ
#: and ~5 σ of panels weigh in). 5e-5 left single rows of the 30-film stack 9e-4
#: off where the estimate was still far from its asymptotic regime.
TOLERANCE = 5e-6
#: Largest first-level sample step (bins).
MAX_STEP = 8.0
#: Finest panel (bins: ~1e-4 nm at 560 nm and the default σ), below the
#: narrowest cavity resonances outside the grazing sliver.
MIN_PANEL = 2.0 ** -10
#: The finest panel where ``cos θ < GRAZING_COS / 2``: deep in the grazing
#: sliver, which builds do not verify (the rows just inside it are as exact as
#: the others: the spline at a verified midpoint reaches two nodes on either side).
MIN_PANEL_GRAZING = 2.0 ** -2
#: The Gaussian is cut at this many standard deviations.
TAIL = 6.0


def sigma_nu(resolution: float) -> float:
    """The Gaussian's standard deviation in wavenumber (nm⁻¹) for a
    ``spectral_resolution`` of ``resolution`` nm at :data:`REFERENCE_WAVELENGTH`."""
    return resolution / REFERENCE_WAVELENGTH ** 2



_GL3_X = (-0.5 * math.sqrt(0.6), 0.0, 0.5 * math.sqrt(0.6))
_GL3_W = (5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0)


def first_bin_step(side: SideData, w: float) -> tuple[float, float]:
    """``(step, fringe)``: the first level's sample step and a 32nd of an interference
    fringe of the stack's whole optical thickness (period ``1 / (2 Σ n_j d_j)`` in
    wavenumber), both in bins of width ``w`` (nm⁻¹); the step is the fringe's 32nd as a
    power of two from 1/2 to :data:`MAX_STEP`. (Accepted panels stand for their
    quadratics, so the step bounds ``R_σ``'s error where no resonance refines it:
    measured on the 10-film stack against a brute-force convolution, 5e-5 at 16
    samples per fringe, 4e-6 at 32.)"""
    ot = optical_thickness(side.films, np.linspace(360.0, 830.0, 48))
    fringe = 1.0 / max(2.0 * ot, 1e-9) / w / 32.0
    return power_of_two_step(fringe, 0.5, MAX_STEP), fringe


class _Resonances:
    """The resonances the first level found (zeros ``x_p + i d`` of ``D`` near the
    axis; per row, positions and distances in bins), and the graded panels they
    ask for: a panel must be no wider than :data:`GRADING` times its distance to
    the nearest zero, ``|x - (x_p + i d)|`` at its point nearest ``x_p`` (the
    scale on which the resonance's Lorentzian varies there). Simpson's error
    estimate alone can vanish by accident on a panel beside a resonance
    (measured: a panel of 16 bins on the flank of a dip of depth 0.4 left R_σ
    0.017 off)."""

    #: The zeros checked per panel: the last one before it and the first ones
    #: from its start (two polarizations, a few per panel at most).
    PER_PANEL = 4

    def __init__(self, rows: np.ndarray, pos: np.ndarray, dist: np.ndarray, nb: int):
        self.span = 4.0 * nb + 64.0
        keys = rows * self.span + np.clip(pos, -nb, 2.0 * nb)
        order = np.argsort(keys)
        self.keys, self.dist = keys[order], dist[order]

    @classmethod
    def none(cls):
        return cls(np.empty(0), np.empty(0), np.empty(0), 0)

    def forced(self, r: np.ndarray, a: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Per panel ``[a, a + h]`` of row ``r``: whether a zero near it asks for a
        narrower panel."""
        out = np.zeros(r.shape, bool)
        n = self.keys.size
        if n == 0:
            return out
        start = r * self.span + a
        first = np.searchsorted(self.keys, start)
        for k in range(-1, self.PER_PANEL):
            j = first + k
            valid = (j >= 0) & (j < n)
            j = np.clip(j, 0, n - 1)
            gap = np.maximum(np.maximum(start - self.keys[j], self.keys[j] - (start + h)), 0.0)
            out |= valid & (h * h > GRADING ** 2 * (gap * gap + self.dist[j] * self.dist[j]))
        return out


ILLUMINANTS = ("D65", "A", "F11")


class Rows:
    """Band-limited angle rows of one side: ``R_σ`` [, ``T_σ``] on a grid of bins
    uniform in ``ν`` whose every other bin is a v node of a table of ``nv`` nodes.

    ``rows.values(xs)`` gives, per row coordinate (the angle axis's ``row_cos``), ``R_σ`` at
    the bins (shape ``(len xs, nb, C)``), computing the rows it has not seen.
    Bin ``b`` sits at ``ν = SIGMA_MAX - (b - b0) w``, so v node ``t`` (of a table
    of ``nv`` nodes) is bin ``b0 + 2 t``.
    """

    def __init__(self, side: SideData, axis: AngleAxis, resolution: float,
                 spacing: float = V_SPACING, extent: tuple | None = None):
        self.side, self.axis, self.resolution, self.spacing = side, axis, resolution, spacing
        self.sigma = sigma_nu(resolution)
        #: what is tabulated: the side's quantity (the powers, or the Mueller
        #: components, :data:`~thinfilm_mi.tabulate.quantities.QUANTITIES`)
        self.quantity = q = side.quantity
        self.channels = q.channels(side.transmission)
        sampled = samples_amplitudes(side)
        # the wavenumbers the bins cover (a sheared table's rows reach beyond
        # 360-830 nm, :meth:`sample`), SIGMA_MIN .. SIGMA_MAX by default
        low, self.top = extent if extent is not None else (SIGMA_MIN, SIGMA_MAX)
        span = self.top - low
        self.nv = max(int(math.ceil(span / (spacing * self.sigma))) + 1, 16)
        self.w = w = span / (2.0 * (self.nv - 1))
        self.sig = math.sqrt(self.sigma ** 2 - w * w / 3.0)
        self.reach = int(math.ceil(TAIL * self.sig / w))
        self.step, fringe = first_bin_step(side, w)
        #: whether the adaptive panels take their values from the first level's
        #: amplitudes (:class:`Amplitudes`) instead of the films: where the first
        #: level samples them, at least 32 times per fringe
        self.interpolate = sampled and self.step <= fringe
        # margins: ghosts, the Gaussian's reach, and whole pairs of first panels
        # (nb - 1 a multiple of 4 steps; it is even, and so is every quantum)
        quantum = int(round(4 * self.step))
        b0 = 2 * GHOST + self.reach + 2
        b0 += (-(2 * (self.nv - 1) + 2 * b0)) % quantum // 2
        self.b0 = b0
        self.nb = nb = 2 * (self.nv - 1) + 2 * b0 + 1
        self.wavenumbers = self.top - (np.arange(nb) - b0) * w          # decreasing ν
        #: the first level's wavenumbers (every row is sampled there, every
        #: :attr:`step` bins)
        self.first_nu = self.wavenumbers[0] - w * (self.step * np.arange(int(round((nb - 1) / self.step)) + 1))
        # the side's indices where every row is evaluated: at the first level's
        # wavenumbers and at the bins (the colour check, the nodes' angles)
        self._first_indices = side_indices(side, 1.0 / self.first_nu)
        self._bin_indices = side_indices(side, 1.0 / self.wavenumbers)
        self.points = 0
        self._bins_of: dict = {}     # the rows computed: their bins I_b
        self._smooth: dict = {}      # R_σ at the bins of the rows values() was asked for
        self._row_cos: dict = {}
        #: the largest colour difference of the rows so far under D65, A, F11
        self.colour_errors = np.zeros(3)

    @property
    def colour_error(self) -> float:
        return float(self.colour_errors.max())

    # -- exact values ----------------------------------------------------------
    def _exact(self, xs: np.ndarray, r: np.ndarray, nu: np.ndarray):
        """Exact ``R`` [, ``T``] at rows ``xs[r[i]]`` and wavenumbers ``nu[i]``, and
        the per-point ``cos``."""
        wl, inv = unique_wavelengths(1.0 / nu)
        if wl.size == 1:     # a 1-element buffer would trace as a scalar: another kernel
            wl = np.repeat(wl, 2)
        idx = side_indices(self.side, wl)
        cos = self._cos(xs, r, idx, inv)
        self.points += cos.size
        return evaluate_side(self.side, cos, inv, wl, idx), cos

    def _cos(self, xs, r, idx, inv):
        """cos θ_i at the points of rows ``xs[r]`` at the wavelengths ``inv`` of the
        indices ``idx`` (per row on an axis that does not depend on the indices)."""
        if not self.axis.needs_n_exit:
            key = xs.tobytes()
            if key not in self._row_cos:
                self._row_cos = {key: self.axis.row_cos(xs, None, None)}
            return self._row_cos[key][r]
        return self.axis.row_cos(xs[r], np.asarray(idx[0], np.float64)[inv],
                                 np.asarray(idx[2]).real[inv])

    def _first(self, xs: np.ndarray):
        """The first level: exact ``R`` [, ``T``] of every row at :attr:`first_nu` (shape
        ``(rows, P, C)``), ``cos`` there, the resonances panels must resolve
        (:class:`_Resonances`), and the amplitudes' interpolation the panels read
        (an ``Amplitudes``, or ``None``: the panels evaluate the films).

        The amplitudes ``N``, ``D`` of :func:`amplitudes` (``R = |N|²/|D|²``)
        are smooth where ``R`` has resonances: a resonance is a zero of ``D_s``
        or ``D_p`` just off the real axis, found on the cubic through the
        samples (:func:`near_zeros`) even where it is far narrower than the
        samples' step; the panels around it are graded by their distance to the
        zero (:class:`_Resonances`: at the zero itself, its distance from the
        axis, the resonance's half width), and the adaptive rule then resolves
        its shape."""
        nu_pts = self.first_nu
        R, P, C = xs.size, nu_pts.size, self.channels
        rows_of = np.repeat(np.arange(R), P)
        if not samples_amplitudes(self.side):
            f, cos = self._exact(xs, rows_of, np.tile(nu_pts, R))
            return f.reshape(R, P, C), cos.reshape(R, P), _Resonances.none(), None
        wl, idx = 1.0 / nu_pts, self._first_indices
        cos = self._cos(xs, rows_of, idx, np.tile(np.arange(P), R)).reshape(R, P)
        q, tr = self.quantity, self.side.transmission
        terms, exps = q.smooth_terms(
            self.side, np.ascontiguousarray(cos).ravel(), np.tile(np.arange(P), R), wl, idx)
        self.points += cos.size
        terms, exps = terms.reshape(R, P, -1), exps.reshape(R, P, 2)
        f = q.values(terms, tr)
        f = np.where((cos <= 0.0)[..., None], q.grazing(tr), f)
        # zeros of D_s and D_p within RESOLVE_DISTANCE sample steps of the axis
        # (positions and distances in bins)
        r, pos, d = (np.concatenate(v) for v in zip(*(near_zeros(terms, k, exps[..., e])
                                                      for k, e in ((2, 0), (6, 1)))))
        smooth = None
        if self.interpolate:
            smooth = Amplitudes(terms, exps, cos, q, tr)
            smooth = smooth if smooth.usable() else None
        return f, cos, _Resonances(r, self.step * pos,
                                   np.maximum(self.step * d, MIN_PANEL), self.nb), smooth

    def bin_cos(self, xs: np.ndarray, bins: np.ndarray) -> np.ndarray:
        """cos θ_i of rows ``xs`` at the bins ``bins``: shape ``(len bins, len xs)``."""
        cos = self._cos(xs, np.tile(np.arange(xs.size), len(bins)), self._bin_indices,
                        np.repeat(bins, xs.size))
        return cos.reshape(len(bins), xs.size)

    # -- adaptive Simpson into bins ---------------------------------------------
    def _bins(self, xs: np.ndarray) -> np.ndarray:
        """``I_b`` of the rows ``xs``: shape ``(rows, nb, C)``.

        First level: samples every :attr:`step` bins, panels two steps wide whose
        error is estimated in pairs (5 samples); a panel that fails, or is wider
        than the resonances near it allow (:class:`_Resonances`), is halved (2
        new samples) until it passes or reaches :data:`MIN_PANEL`. Each accepted panel stands for
        the quadratic through its three
        samples, integrated exactly against the bins' B-splines (3-point
        Gauss-Legendre on each bin interval it covers: degree 2 + 3)."""
        R, w, S = xs.size, self.w, self.step
        P = self.first_nu.size
        f, cos, res, smooth = self._first(xs)
        f0, f1, f2, f3, f4 = (f[:, k:P - 4 + k:4] if k < 4 else f[:, 4::4] for k in range(5))
        H = 2.0 * S
        coarse = (2 * H / 6) * (f0 + 4 * f2 + f4)
        fine = (H / 6) * (f0 + 4 * f1 + 2 * f2 + 4 * f3 + f4)
        ok = np.abs(fine - coarse).max(axis=-1) / 15.0 <= TOLERANCE * 2 * H
        pr, pk = np.nonzero(ok)
        full = np.full(pr.size, H)
        ok[pr, pk] = ~(res.forced(pr, 2 * H * pk, full) | res.forced(pr, 2 * H * pk + H, full))
        out = self._first_panels(f, ok)
        # the others: (row, start and width in bins, R at start, middle, end, cos)
        panels, pending = [], []
        r, k = np.nonzero(~ok)
        for half in (0, 1):
            j = 4 * k + 2 * half
            pending.append((r, H * (2 * k + half), np.full(r.size, H),
                            f[r, j], f[r, j + 1], f[r, j + 2], cos[r, j]))
        pending = [np.concatenate(a) for a in zip(*pending)]
        while pending[0].size:
            r, a, h, fa, fm, fb, c = pending
            q = np.concatenate([a + 0.25 * h, a + 0.75 * h])
            if smooth is not None:       # from the first level's amplitudes
                fq = smooth.values(np.concatenate([r, r]), q / S)
            else:
                fq, _ = self._exact(xs, np.concatenate([r, r]), self.wavenumbers[0] - w * q)
            fq1, fq3 = fq[:r.size], fq[r.size:]
            coarse = (h / 6)[:, None] * (fa + 4 * fm + fb)
            fine = (h / 12)[:, None] * (fa + 4 * fq1 + 2 * fm + 4 * fq3 + fb)
            finest = np.where(c < 0.5 * GRAZING_COS, MIN_PANEL_GRAZING, MIN_PANEL)
            done = (((np.abs(fine - coarse).max(axis=-1) / 15.0 <= TOLERANCE * h)
                     & ~res.forced(r, a, h)) | (h <= 2.0 * finest))
            h2 = 0.5 * h
            halves = ((r, a, h2, fa, fq1, fm, c), (r, a + h2, h2, fm, fq3, fb, c))
            for hv in halves:
                panels.append(tuple(v[done] for v in hv))
            pending = [np.concatenate([hv[i][~done] for hv in halves]) for i in range(7)]
        if panels:
            r, a, h, fa, fm, fb = (np.concatenate(v) for v in list(zip(*panels))[:6])
            out += self._gather(r, a, h, fa, fm, fb, R)
        return w * out

    def _first_panels(self, f: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """The bins (shape ``(rows, nb, C)``, in bins) of the first-level panels
        of the pairs ``ok`` accepts, all at once: every panel is ``2 step`` bins on
        the same grid, so its quadratic's values at the Gauss points of the bin
        intervals it covers are one fixed (3 samples -> intervals x 3 points) map."""
        R, P, C = f.shape
        H = int(round(2 * self.step))
        npan = (P - 1) // 2
        s = (np.arange(H)[:, None] + 0.5 + np.array(_GL3_X)[None, :]) / H      # (H, 3)
        lagrange = np.stack([2 * (s - 0.5) * (s - 1), -4 * s * (s - 1), 2 * s * (s - 0.5)])
        trip = np.stack([f[:, 0:P - 2:2], f[:, 1:P - 1:2], f[:, 2::2]], axis=2)  # (R, npan, 3, C)
        keep = np.repeat(ok, 2, axis=1)[:, :npan, None, None]
        V = np.einsum("rpjc,jhg->rphgc", np.where(keep, trip, 0.0), lagrange)
        return self._bin_intervals(V.reshape(R, npan * H, 3, C))

    def _bin_intervals(self, V: np.ndarray) -> np.ndarray:
        """Bins from values at the 3 Gauss points of every bin interval (shape
        ``(rows, nb - 1, 3, C)``): the B-spline weights at those points are the
        same for every interval."""
        R, n, _, C = V.shape
        out = np.zeros((R, n + 1, C))
        for g, (x, wg) in enumerate(zip(_GL3_X, _GL3_W)):
            for j, bw in enumerate(bspline_weights(0.5 + x)):
                # interval k feeds bin k - 1 + j
                lo, hi = max(0, 1 - j), min(n, n + 1 - j + 1)
                out[:, lo - 1 + j:hi - 1 + j] += (wg * bw) * V[:, lo:hi, g]
        return out

    def _gather(self, r, a, h, fa, fm, fb, R):
        """``Σ_panels ∫ q(t) B(t - b) dt`` (in bins) for the quadratics ``q`` of the
        panels ``[a, a + h]`` through ``fa``, ``fm``, ``fb``."""
        nb, C = self.nb, self.channels
        out = np.zeros((R, nb, C))
        # the quadratic in the panel's coordinate s in [0, 1]
        c1 = (-3 * fa + 4 * fm - fb)
        c2 = 2 * (fa - 2 * fm + fb)
        big = h >= 1.0
        if big.any():
            # each bin interval a big panel covers: its values at the 3 Gauss points
            n = np.round(h[big]).astype(np.int64)
            pid = np.repeat(np.arange(n.size), n)
            k = np.round(np.repeat(a[big], n)).astype(np.int64) + (
                np.arange(pid.size) - np.repeat(np.cumsum(n) - n, n))
            V = np.zeros((R, nb - 1, 3, C))
            for g, x in enumerate(_GL3_X):
                sfrac = ((k + 0.5 + x - a[big][pid]) / h[big][pid])[:, None]
                V[r[big][pid], k, g] = fa[big][pid] + sfrac * (c1[big][pid] + sfrac * c2[big][pid])
            out += self._bin_intervals(V)
        small = ~big
        if small.any():
            rs, as_, hs = r[small], a[small], h[small]
            k = np.floor(as_ + 1e-9).astype(np.int64)      # the bin interval holding it
            for x, wg in zip(_GL3_X, _GL3_W):
                sfrac = 0.5 + x
                val = fa[small] + sfrac * (c1[small] + sfrac * c2[small])
                t = as_ + sfrac * hs - k
                for j, bw in enumerate(bspline_weights(t)):
                    node = np.clip(k + j - 1, 0, nb - 1) + rs * nb
                    for ch in range(C):
                        out.reshape(R * nb, C)[:, ch] += np.bincount(
                            node, wg * hs * bw * val[:, ch], minlength=R * nb)
        return out

    def _convolve(self, bins: np.ndarray) -> np.ndarray:
        """``R_σ`` at the bins: ``Σ_j G_σ'(j w) I_{b-j}`` (FFT along the bins)."""
        nb, J = self.nb, self.reach
        n = 1 << int(math.ceil(math.log2(nb + 2 * J + 1)))
        j = np.arange(-J, J + 1)
        g = np.exp(-0.5 * (j * self.w / self.sig) ** 2) / (self.sig * math.sqrt(2 * math.pi))
        kern = np.zeros(n)
        kern[j % n] = g
        spec = np.fft.rfft(bins, n=n, axis=1) * np.fft.rfft(kern)[None, :, None]
        return np.fft.irfft(spec, n=n, axis=1)[:, :nb]

    @staticmethod
    def _keys(xs) -> np.ndarray:
        return np.round(np.asarray(xs, np.float64), 12)

    @property
    def computed(self) -> int:
        """How many rows have been computed."""
        return len(self._bins_of)

    def missing(self, xs) -> int:
        """How many of the rows ``xs`` are not computed yet."""
        return len({k for k in self._keys(xs) if k not in self._bins_of})

    def compute(self, xs) -> None:
        """Compute the bins (and the colour check) of the rows ``xs`` not seen yet."""
        keys = self._keys(xs)
        fresh = np.unique([k for k in keys if k not in self._bins_of])
        if fresh.size:
            bins = self._bins(fresh)
            self.colour_errors = np.maximum(self.colour_errors, self._colour_check(fresh, bins))
            for k, b in zip(fresh, bins):
                self._bins_of[k] = b

    def values(self, xs: np.ndarray) -> np.ndarray:
        """``R_σ`` [, ``T_σ``] at the bins of the rows ``xs``: ``(len xs, nb, C)``."""
        keys = self._keys(xs)
        self.compute(keys)
        todo = [k for k in np.unique(keys) if k not in self._smooth]
        if todo:
            for k, v in zip(todo, self._convolve(np.stack([self._bins_of[k] for k in todo]))):
                self._smooth[k] = v
        return np.stack([self._smooth[k] for k in keys])

    def sample(self, xs: np.ndarray, nus: np.ndarray) -> np.ndarray:
        """``R_σ`` [, ``T_σ``] of the rows ``xs`` at any wavenumbers ``nus`` (shape
        ``(len xs, K)``, within the bins' extent): ``(len xs, K, C)``, the Gaussian
        of :meth:`_convolve` summed over the bins directly (the same values at the
        bins, to rounding)."""
        keys = self._keys(xs)
        self.compute(keys)
        J, nb = self.reach, self.nb
        # each row's bins between 2J + 2 zeros at either end, as wide as the bins a point
        # reaches: a point's bins all lie in its row, a point beyond them reads zeros
        raw = np.stack([self._bins_of[k] for k in keys])                 # (R, nb, C)
        R, C, pad = raw.shape[0], raw.shape[2], 2 * J + 2
        flat = np.pad(raw, ((0, 0), (pad, pad), (0, 0))).reshape(-1, C)
        p = (self.top - np.asarray(nus, np.float64)) / self.w + self.b0  # bin coordinates
        k0 = np.floor(p)
        f = p - k0                                                       # in [0, 1)
        # bin k0 - J, padded
        first = np.clip(k0 + (pad - J), 0, nb + pad).astype(np.int64)
        first += (np.arange(R) * (nb + 2 * pad))[:, None]
        # the Gaussian at bins k0 + j, j = -J .. J + 1, by a recurrence in j (two
        # products a bin instead of an exponential): g_{j+1} = g_j r_j, r_{j+1} = r_j e^{-s²}
        s2 = (self.w / self.sig) ** 2
        g = np.exp(-0.5 * s2 * (f + J) ** 2) / (self.sig * math.sqrt(2.0 * math.pi))
        r = np.exp(s2 * (f + J) - 0.5 * s2)
        decay = math.exp(-s2)
        out = np.zeros((R, p.shape[1], C))
        for j in range(2 * J + 2):
            out += g[..., None] * flat.take(first + j, axis=0)
            g *= r
            r *= decay
        return out

    # -- colour check -------------------------------------------------------------
    def _colour_check(self, xs: np.ndarray, bins: np.ndarray) -> np.ndarray:
        """The largest CIEDE2000 between the colours of the exact and the
        band-limited values of the rows (each channel) outside the grazing sliver,
        under D65, A and F11 (an array of 3; ``∫ R W dλ = ∫ R W(1/ν) dν / ν²``;
        ``R_σ``'s colour weights the bins by the Gaussian-smoothed weights)."""
        wl_b = 1.0 / self.wavenumbers
        nb = wl_b.size
        cos = self.bin_cos(xs, np.arange(nb)).T
        keep = cos.min(axis=1) >= GRAZING_COS
        if not keep.any():
            return np.zeros(3)
        bins = bins[keep]
        bins = self.quantity.colour_terms(bins, self.side.transmission)   # its powers
        cw = cie.colour_weights()
        grid = cw[:, 0]
        inside = (wl_b >= grid[0]) & (wl_b <= grid[-1])
        jac = wl_b ** 2 * inside                              # dλ = dν / ν²
        cmf = np.stack([np.interp(wl_b, grid, cw[:, c]) for c in (1, 2, 3)], axis=-1)
        J = self.reach
        j = np.arange(-J, J + 1)
        g = np.exp(-0.5 * (j * self.w / self.sig) ** 2) * (self.w / (self.sig * math.sqrt(2 * math.pi)))
        worst = np.zeros(3)
        for i, col in enumerate((4, 5, 6)):
            wgt = cmf * (np.interp(wl_b, grid, cw[:, col]) * jac)[:, None]   # (nb, 3)
            wgt_s = np.stack([np.convolve(wgt[:, c], g, mode="same") for c in range(3)], axis=-1)
            white = wgt.sum(axis=0) * self.w
            xyz = np.einsum("rbc,bk->rck", bins, wgt)
            xyz_s = np.einsum("rbc,bk->rck", bins, wgt_s)
            ref = 100.0 * white / white[1]
            de = cie.delta_e2000(cie.lab(100.0 * xyz / white[1], ref), cie.lab(100.0 * xyz_s / white[1], ref))
            worst[i] = float(np.max(de))
        return worst

# -- the build ---------------------------------------------------------------------------
#: Bins are half a v-node spacing wide, 0.3 σ_ν: the bins' B-spline departs
#: from a Gaussian by its fourth cumulant, ~1e-6 of ``R_σ``.
KNOT_SHARE = 0.5 * V_SPACING
#: Largest CIEDE2000 between the colours of ``R`` and ``R_σ`` (and ``T``,
#: ``T_σ``) over the angle rows under D65, A and F11 a table may show. F11's
#: lines (as tabulated by the CIE, every 5 nm) are what a band-limited table
#: shifts most: 0.27 for the 30-film benchmark stack at 1 nm, D65 0.009.
COLOUR_TOLERANCE = 0.5
#: Angle nodes of the first round (a plain axis; a split one: per segment, half).
FIRST_NU = 65
#: Convergence order assumed for the first refinement of the angle axis (then
#: the order observed between rounds): ``R_σ``'s resonances are still sharp at
#: the first round's spacing, so the cubic's h^4 is not reached yet.
FIRST_ORDER = 3.5
#: Rounds after the first (each sized from the last's error).
MAX_ROUNDS = 4
#: A build's expected exact evaluations over a lower bound of its first round's
#: (its rows' first-level samples): the adaptive panels and the later rounds, a bound
#: for the benchmark stacks up to 60 films. A build whose expected total exceeds
#: :data:`~thinfilm_mi.tabulate.policy.MAX_BUILD_WORK` is not started (milliseconds
#: instead of seconds); one that passes is checked again on
#: :data:`SAMPLE_ROWS` rows before the rest of its first round.
EXPECTED_TOTAL = 4.0
#: Rows of the first round computed first, to measure the cost per row.
SAMPLE_ROWS = 8


def build_table(side: SideData, error: float, wavelengths: np.ndarray,
                max_texels: int = MAX_TEXELS, resolution: float = 0.0,
                report: BuildReport | None = None, budget_scale: float = 1.0,
                linear_floats: int = 0) -> Table | None:
    """The table of one side: of the exact values
    (:func:`~thinfilm_mi.tabulate.exact.build_exact_table`) if one resolves them within
    ``error`` (1-3 films: unchanged by band-limiting),
    else, if ``resolution`` > 0, of ``R_σ`` (:func:`build_band_table`); ``None``
    if neither can be built. What the build did is written into ``report`` (a
    :class:`~thinfilm_mi.tabulate.base.BuildReport`; the exact attempt's report
    under ``"exact_attempt"`` when a band-limited table was tried after it).
    ``budget_scale`` multiplies the evaluations and work both builds may spend
    (:meth:`~thinfilm_mi.tabulate.refine.Budget.scaled`).

    With ``linear_floats`` > 0 the spline is built within
    :data:`~thinfilm_mi.tabulate.bilinear.SPLINE_SHARE` of ``error`` and resampled for
    bilinear lookups within the rest (:func:`~thinfilm_mi.tabulate.bilinear.resample`)
    where that takes at most ``linear_floats`` floats; ``report["interpolation"]`` says
    which the table is."""
    report = report if report is not None else BuildReport()
    target = error * SPLINE_SHARE if linear_floats > 0 else error
    attempt = BuildReport()
    table = exact.build_exact_table(side, target, wavelengths, max_texels, report=attempt,
                                    budget_scale=budget_scale)
    if table is not None or resolution <= 0:
        report.update(attempt)
    else:
        table = build_band_table(side, target, wavelengths, max_texels, resolution,
                                 report=report, budget_scale=budget_scale)
        report["exact_attempt"] = attempt
    if table is not None and linear_floats > 0:
        fine = resample(table, side, error, linear_floats)
        if fine is not None:
            report.update(factors=list(fine.factors), spline_error=table.error)
            table = fine
    if table is not None:
        report["interpolation"] = table.interpolation.name
    return table


def build_band_table(side: SideData, error: float, wavelengths: np.ndarray,
                     max_texels: int, resolution: float, report: BuildReport | None = None,
                     budget_scale: float = 1.0) -> Table | None:
    """A verified table of ``R_σ`` (see the module), or ``None`` if the colour
    check fails or the target needs more than ``max_texels`` texels,
    :data:`~thinfilm_mi.tabulate.policy.MAX_BUILD_POINTS` exact evaluations or
    :data:`~thinfilm_mi.tabulate.policy.MAX_BUILD_WORK` (the
    expected total, :data:`EXPECTED_TOTAL`, checked before any evaluation; then
    each round's before it runs), both times ``budget_scale``. Writes its account
    into ``report``.

    Rounds: the rows of the angle nodes (a plain axis's ghosts included) and of
    their midpoints are computed (each row: every bin, so the v nodes and their
    midpoints come with it); the spline through the node rows is compared with
    the midpoint rows (``err_u``) and, along v, with the bins between the nodes
    (``err_v``), outside the grazing sliver. If ``err_u + err_v`` exceeds
    ``error``, the angle nodes are multiplied by the factor the error's
    convergence order predicts (the v spacing is reduced instead, all rows
    computed again, where ``err_v`` alone exceeds half the target)."""
    axis = axis_for(side.n0(wavelengths), side.n_exit(wavelengths))
    stats = report if report is not None else BuildReport()
    stats.update({"kind": axis.name if axis is not None else None, "rounds": 0, "points": 0,
                  "result": "critical angle varies", "resolution": resolution,
                  "colour_error": None, "errors": []})
    if axis is None:
        return None
    axis = axis.band_limited     # a plain axis: more nodes at mid angles
    # a quantity whose channels vary faster along v (tabulate.mueller) starts finer
    spacing = side.quantity.v_spacing
    shear = _fringe_shear(side, axis)
    rows = _rows(side, axis, resolution, spacing, shear)
    nu = 2 * FIRST_NU if axis.split else FIRST_NU
    side.set_absorbing(wavelengths)     # every evaluation of the build traces one kernel
    budget = Budget.scaled(budget_scale, texels=max_texels, point_work=build_work(side, 1))
    first = EXPECTED_TOTAL * sum(len(x) for x in axis.rows(nu)) * ((rows.nb - 1) / rows.step + 1)
    stats["expected_work"] = build_work(side, first)
    if not budget.allows(first):
        stats["result"] = "over budget (expected)"
        return None
    return _rounds(rows, shear, spacing, nu, budget, error, stats)


def _rounds(rows: Rows, shear: Shear | None, spacing: float, nu: int, budget: Budget,
            error: float, stats: BuildReport) -> Table | None:
    """The rounds of :func:`build_band_table` from ``nu`` angle nodes: each samples the
    rows (:func:`_samples`, :func:`_sheared_samples`), fits the spline through them and
    measures its errors (:func:`_fit`), and refines the axes until the target
    ``error`` is met, the colour check fails or the budget is spent."""
    axis, last, per_row = rows.axis, None, 0.0
    for _ in range(MAX_ROUNDS + 1):
        if shear is None and spacing != rows.spacing:    # a finer v axis: every row again
            rows = Rows(rows.side, axis, rows.resolution, spacing)
        nv = rows.nv if shear is None else _sheared_nv(shear, rows.sigma, spacing)
        xn, xm = axis.rows(nu)
        coords = np.concatenate((xn, xm))
        if not per_row:
            # the cost per row measured on SAMPLE_ROWS of the first round's rows (then
            # part of it) before the rest is spent: the expectation is a bound from the
            # first level alone, and the adaptive panels grow with the resonances
            rows.compute(coords[np.linspace(0, coords.size - 1, SAMPLE_ROWS).round().astype(int)])
            per_row = rows.points / rows.computed
        # the round's new rows at the cost per row so far
        todo = rows.missing(coords)
        if nu > MAX_U or nv > MAX_V or not budget.allows(rows.points + todo * per_row, nu * nv):
            stats.update(result="over budget", points=budget.spent + rows.points)
            return None
        samples = (_samples(rows, xn, xm) if shear is None
                   else _sheared_samples(rows, shear, xn, xm, nv))
        coeffs, err_u, err_v = _fit(*samples)
        per_row = max(per_row, rows.points / rows.computed)
        stats.update(rounds=stats["rounds"] + 1, points=budget.spent + rows.points,
                     colour_error=rows.colour_error,
                     colour_errors=dict(zip(ILLUMINANTS, rows.colour_errors.tolist())))
        stats["errors"].append((nu, nv, err_u, err_v))
        if rows.colour_error > COLOUR_TOLERANCE:
            stats["result"] = "colour check failed"
            return None
        if err_u + err_v <= error:
            stats["result"] = "table"
            return Table(coeffs, axis, err_u + err_v, coeffs.shape[-1], rows.resolution, shear=shear)
        if not budget.allows(rows.points):
            break
        if err_u > 0.5 * error or err_u + min(err_v, 0.5 * error) > error:
            # more angle nodes, by the factor the error's convergence order predicts
            # (``last``: the previous round's ``(nu, err_u)``), so that ``err_u``
            # reaches what ``err_v`` leaves of the target
            factor = convergence_factor(nu, err_u, 0.8 * error - min(err_v, 0.4 * error), last,
                                        FIRST_ORDER, margin=1.1, cap=6.0, highest=4.0)
            if not axis.split and factor <= 2.0:
                # halving the spacing reuses every row computed (the nodes and the
                # midpoints): 2 (nu - 1) new rows, never more than a smaller factor
                # would compute afresh
                factor = 2.0
            nu, last = axis.segments * (int(math.ceil((nu // axis.segments - 1) * factor)) + 1), (nu, err_u)
        if err_v > 0.5 * error:      # a finer v axis (unsheared: new rows next round)
            spacing *= 0.75 * (0.5 * error / err_v) ** 0.25
            if shear is None:
                budget.spend(rows.points)
    stats["result"] = "over budget"
    return None


def _fringe_shear(side: SideData, axis) -> Shear | None:
    """The :class:`Shear` of :func:`build_band_table`'s v axis for a side lit from the
    ambient (rows that do not depend on the indices: the v axis follows the films'
    fringes); ``None`` where the axis needs the exit medium's index."""
    if axis.needs_n_exit:
        return None
    return Shear.of([side.films[i] for i in side.fringe_films],
                    complex(np.asarray(side.n0(np.array([SHEAR_WAVELENGTH])))[0]))


def _sheared_nv(shear: Shear, sigma: float, spacing: float) -> int:
    """v nodes of a sheared axis: ``spacing`` times the Gaussian's width in ``ν'``
    where it is narrowest (``σ P_min``)."""
    span = SIGMA_MAX - shear.low
    return max(int(math.ceil(span / (spacing * sigma * shear.min_factor))) + 1, 16)


def _rows(side: SideData, axis: AngleAxis, resolution: float, spacing: float,
          shear: Shear | None) -> Rows:
    """The rows of a build: on a sheared axis, bins over every wavenumber a node
    ``ν'_t / P`` of any row (ghosts included) can ask for."""
    extent = None
    if shear is not None:
        dv = (SIGMA_MAX - shear.low) / (_sheared_nv(shear, sigma_nu(resolution), spacing) - 1)
        margin = (GHOST + 1) * dv
        extent = ((shear.low - margin) / shear.max_factor, (SIGMA_MAX + margin) / shear.min_factor)
    return Rows(side, axis, resolution, spacing, extent=extent)


def _sheared_samples(rows: Rows, shear: Shear, xn: np.ndarray, xm: np.ndarray, nv: int):
    """:func:`_samples` on a sheared v axis (:class:`Shear`) of ``nv`` nodes: the
    rows sampled at their nodes' ``ν'_t / P(s)``; a midpoint counts where its
    wavelength is within a node of 360-830 nm (the lookups' range) and outside
    the grazing sliver."""
    g = GHOST
    pn = shear.factor_np(1.0 - band_cos(xn) ** 2)
    pm = shear.factor_np(1.0 - band_cos(xm) ** 2)
    t = np.arange(-g, nv + g, dtype=np.float64)
    nodes_v = shear.node_wavenumbers(t, nv)                       # ν' of every v node
    mids_v = shear.node_wavenumbers(np.arange(nv - 1) + 0.5, nv)
    dv = (SIGMA_MAX - shear.low) / (nv - 1)
    nodes = np.swapaxes(rows.sample(xn, nodes_v[None, :] / pn[:, None]), 0, 1)
    mid_u = np.swapaxes(rows.sample(xm, nodes_v[None, g:-g] / pm[:, None]), 0, 1)
    mid_v = np.swapaxes(rows.sample(xn[g:-g], mids_v[None, :] / pn[g:-g, None]), 0, 1)

    def counted(v, p, x):      # (len v, len p): in the lookups' range, not grazing
        return ((v[:, None] >= p[None, :] * SIGMA_MIN - dv) & (v[:, None] <= p[None, :] * SIGMA_MAX + dv)
                & (band_cos(x) >= GRAZING_COS)[None, :])
    return (nodes, mid_u, mid_v, counted(nodes_v[g:-g], pm, xm),
            counted(mids_v, pn[g:-g], xn[g:-g]), None)


def _samples(rows: Rows, xn: np.ndarray, xm: np.ndarray):
    """What :func:`_fit` checks a table of the node rows ``xn`` (midpoint rows ``xm``)
    and ``rows.nv`` wavelength nodes by: ``(nodes, mid_u, mid_v, keep_u, keep_v,
    ends)``, the values at the nodes ``(nv + 2g, rows, C)``, between them along the
    angle ``(nv, mids, C)`` and along the wavelength ``(nv - 1, nu, C)``, where a
    midpoint counts (outside the grazing sliver), and a split axis's ghost ends."""
    g, axis, nv, b0 = GHOST, rows.axis, rows.nv, rows.b0
    real = np.arange(xn.size - (0 if axis.split else 2 * g)) + (0 if axis.split else g)
    vn, vm = rows.values(xn), rows.values(xm)
    tv = b0 + 2 * np.arange(-g, nv + g)                      # the v nodes' bins
    cos_m, cos_n = rows.bin_cos(xm, tv[g:-g]), rows.bin_cos(xn[real], tv[g:-g])
    nodes = np.swapaxes(vn[:, tv], 0, 1)                      # (nv + 2g, rows, C)
    mid_u = np.swapaxes(vm[:, tv[g:-g]], 0, 1)                # (nv, mids, C)
    mid_v = np.swapaxes(vn[:, tv[g:-g - 1] + 1], 0, 1)        # (nv - 1, rows, C)
    return (nodes, mid_u, mid_v[:, real], cos_m >= GRAZING_COS,
            (cos_n[:-1] >= GRAZING_COS) & (cos_n[1:] >= GRAZING_COS), axis.ends if axis.split else None)


def _fit(nodes: np.ndarray, mid_u: np.ndarray, mid_v: np.ndarray, keep_u: np.ndarray,
         keep_v: np.ndarray, ends) -> tuple:
    """The spline coefficients of a table through the node values ``nodes`` and its
    errors ``(coefficients, err_u, err_v)``: the largest difference between the spline
    and the midpoint values along the angle (``mid_u``) and the wavelength (``mid_v``)
    where ``keep_u``, ``keep_v`` count them (:func:`_samples`). ``ends``: a split axis's
    ghost ends (:attr:`~thinfilm_mi.tabulate.axes.AngleAxis.ends`; its segments are
    fitted apart), or ``None``: the node rows hold the ghosts."""
    g, nv = GHOST, mid_u.shape[0]
    if ends is not None:
        m = nodes.shape[1] // 2
        segs = [np.moveaxis(with_ghosts(np.moveaxis(part, 1, 0), *e), 0, 1)
                for part, e in zip((nodes[:, :m], nodes[:, m:]), ends)]
        cu = [bspline_coefficients(s, axis=1) for s in segs]
        approx_u = np.concatenate([bspline_midpoints(c[g:-g], 1, g, m) for c in cu], axis=1)
        cu = np.concatenate(cu, axis=1)
        real = np.arange(2 * m)
        cols = real + g + np.where(real >= m, 2 * g, 0)
    else:
        nu = nodes.shape[1] - 2 * g
        cu = bspline_coefficients(nodes, axis=1)
        approx_u = bspline_midpoints(cu[g:-g], 1, g, nu)
        cols = np.arange(nu) + g
    coeffs = bspline_coefficients(cu, axis=0)
    err_u = float(np.max(np.where(keep_u, np.abs(mid_u - approx_u).max(axis=-1), 0.0)))
    # the spline along v through node column j: the u spline's (1, 4, 1) / 6 of
    # the coefficients
    cv = (coeffs[:, cols - 1] + 4.0 * coeffs[:, cols] + coeffs[:, cols + 1]) / 6.0
    dev = np.abs(mid_v - bspline_midpoints(cv, 0, g, nv)).max(axis=-1)
    return coeffs, err_u, float(np.max(np.where(keep_v, dev, 0.0)))
