"""The rows of a band-limited table (:mod:`thinfilm_mi.tabulate.band`): per angle, the
exact ``R`` (and ``T``) integrated by adaptive Simpson along the wavenumber into
B-spline bins of a fraction of the Gaussian's width, with the resonances of the
stack found as zeros of its smooth denominator ``D`` and the panels graded around
them (:class:`Rows`), and the Gaussian's width (:func:`sigma_nu`). The smooth
amplitudes ``N``, ``D`` from which ``R = |N|²/|D|²`` is sampled, their zeros and
their interpolation are :mod:`thinfilm_mi.tabulate.band_amplitudes`.
"""
from __future__ import annotations

import math

import numpy as np

from thinfilm_mi.colour import cie
from thinfilm_mi.tabulate.axes import GHOST, AngleAxis
from thinfilm_mi.tabulate.band_amplitudes import (
    GRADING,
    Amplitudes,
    near_zeros,
    samples_amplitudes,
)
from thinfilm_mi.tabulate.base import (
    GRAZING_COS,
    SIGMA_MAX,
    SIGMA_MIN,
    SideData,
    evaluate_side,
    side_indices,
)
from thinfilm_mi.tabulate.refine import optical_thickness, power_of_two_step

__all__ = ["ILLUMINANTS", "MAX_STEP", "MIN_PANEL", "MIN_PANEL_GRAZING", "REFERENCE_WAVELENGTH",
           "Rows", "TAIL", "TOLERANCE", "V_SPACING", "first_step", "fringe_step", "sigma_nu"]

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


def fringe_step(side: SideData, w: float) -> float:
    """A 32nd of an interference fringe of the stack's whole optical thickness
    (period ``1 / (2 Σ n_j d_j)`` in wavenumber), in bins of width ``w`` (nm⁻¹)."""
    ot = optical_thickness(side.films, np.linspace(360.0, 830.0, 48))
    return 1.0 / max(2.0 * ot, 1e-9) / w / 32.0


def first_step(side: SideData, w: float, fringe: float | None = None) -> float:
    """The first level's sample step (bins of width ``w``): 32 samples per
    interference fringe (:func:`fringe_step`, or ``fringe`` if given), as a power of
    two from 1/2 to :data:`MAX_STEP`. (Accepted panels stand for their quadratics,
    so the step bounds ``R_σ``'s error where no resonance refines it: measured on
    the 10-film stack against a brute-force convolution, 5e-5 at 16 samples per
    fringe, 4e-6 at 32.)"""
    return power_of_two_step(fringe_step(side, w) if fringe is None else fringe, 0.5, MAX_STEP)


def _bspline_weights(t):
    """The four uniform cubic B-spline basis values at ``t`` in [0, 1] (knots i-1 .. i+2)."""
    return ((1 - t) ** 3 / 6, (3 * t ** 3 - 6 * t ** 2 + 4) / 6,
            (-3 * t ** 3 + 3 * t ** 2 + 3 * t + 1) / 6, t ** 3 / 6)


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
    #: from its start (two polarisations, a few per panel at most).
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
        self.side, self.axis = side, axis
        self.sigma = sigma_nu(resolution)
        # the wavenumbers the bins cover (a sheared table's rows reach beyond
        # 360-830 nm, :meth:`sample`), SIGMA_MIN .. SIGMA_MAX by default
        low, self.top = extent if extent is not None else (SIGMA_MIN, SIGMA_MAX)
        span = self.top - low
        self.nv = max(int(math.ceil(span / (spacing * self.sigma))) + 1, 16)
        self.w = w = span / (2.0 * (self.nv - 1))
        self.sig = math.sqrt(self.sigma ** 2 - w * w / 3.0)
        self.reach = int(math.ceil(TAIL * self.sig / w))
        fringe = fringe_step(side, w)
        self.step = first_step(side, w, fringe)
        #: whether the adaptive panels take their values from the first level's
        #: amplitudes (:class:`Amplitudes`) instead of the films: where the first
        #: level samples them, at least 32 times per fringe
        self.interpolate = samples_amplitudes(side) and self.step <= fringe
        # margins: ghosts, the Gaussian's reach, and whole pairs of first panels
        # (nb - 1 a multiple of 4 steps; it is even, and so is every quantum)
        quantum = int(round(4 * self.step))
        b0 = 2 * GHOST + self.reach + 2
        b0 += (-(2 * (self.nv - 1) + 2 * b0)) % quantum // 2
        self.b0 = b0
        self.nb = nb = 2 * (self.nv - 1) + 2 * b0 + 1
        self.wavenumbers = self.top - (np.arange(nb) - b0) * w          # decreasing ν
        #: what is tabulated: the side's quantity (the powers, or the Mueller
        #: components, :data:`~thinfilm_mi.tabulate.quantities.QUANTITIES`)
        self.quantity = q = side.quantity
        self.channels = q.channels(side.transmission)
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
        wl, inv = np.unique(1.0 / nu, return_inverse=True)
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

    def _first(self, xs: np.ndarray, nu_pts: np.ndarray):
        """The first level: exact ``R`` [, ``T``] of every row at ``nu_pts`` (shape
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
        R, P, C = xs.size, nu_pts.size, self.channels
        rows_of = np.repeat(np.arange(R), P)
        if not samples_amplitudes(self.side):
            f, cos = self._exact(xs, rows_of, np.tile(nu_pts, R))
            return f.reshape(R, P, C), cos.reshape(R, P), _Resonances.none(), None
        wl = 1.0 / nu_pts
        idx = side_indices(self.side, wl)
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
        R, nb, w, S = xs.size, self.nb, self.w, self.step
        P = int(round((nb - 1) / S)) + 1
        at_pts = S * np.arange(P)
        f, cos, res, smooth = self._first(xs, self.wavenumbers[0] - w * at_pts)
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
            for j, bw in enumerate(_bspline_weights(0.5 + x)):
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
                for j, bw in enumerate(_bspline_weights(t)):
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
        raw = np.stack([self._bins_of[k] for k in keys])                 # (R, nb, C)
        p = (self.top - np.asarray(nus, np.float64)) / self.w + self.b0  # bin coordinates
        k0 = np.floor(p).astype(np.int64)
        R, K = p.shape
        flat = raw.reshape(R * self.nb, -1)
        base = (np.arange(R) * self.nb)[:, None]
        norm = 1.0 / (self.sig * math.sqrt(2.0 * math.pi))
        out = np.zeros((R, K, flat.shape[1]))
        for j in range(-self.reach, self.reach + 2):
            b = k0 + j
            inside = (b >= 0) & (b < self.nb)
            g = np.exp(-0.5 * ((p - b) * (self.w / self.sig)) ** 2) * norm * inside
            out += g[..., None] * flat.take((base + np.clip(b, 0, self.nb - 1)).ravel(),
                                            axis=0).reshape(R, K, -1)
        return out

    # -- colour check -------------------------------------------------------------
    def _colour_check(self, xs: np.ndarray, bins: np.ndarray) -> np.ndarray:
        """The largest CIEDE2000 between the colours of the exact and the
        band-limited values of the rows (each channel) outside the grazing sliver,
        under D65, A and F11 (an array of 3; ``∫ R W dλ = ∫ R W(1/ν) dν / ν²``;
        ``R_σ``'s colour weights the bins by the Gaussian-smoothed weights)."""
        wl_b = 1.0 / self.wavenumbers
        idx = side_indices(self.side, wl_b)
        nb = wl_b.size
        cos = self._cos(xs, np.repeat(np.arange(xs.size), nb), idx,
                        np.tile(np.arange(nb), xs.size)).reshape(xs.size, nb)
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
