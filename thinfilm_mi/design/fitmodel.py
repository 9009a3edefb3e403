"""The forward model of a fit: the measured spectra from the parameters, with their exact Jacobian.

Each data set's point ``i`` at wavelength ``λ_i`` and angle ``θ_i`` is modelled as
``scale · Σ_q w_q Q(λ_i + δ_q, θ_q)``: ``Q`` the stack's R or T (the average of
the data set's polarisations), and the quadrature ``(w_q, δ_q, θ_q)`` the
instrument's:

* **bandwidth**: a Gaussian slit function of FWHM ``bandwidth_nm``, by
  Gauss–Hermite quadrature in :data:`BANDWIDTH_NODES` wavelengths (exact for a
  spectrum that is a polynomial of degree ``2 · nodes - 1`` across the slit;
  interference fringes of period ``p`` are attenuated by
  ``exp(-(π FWHM / p)² / (4 ln 2))`` and the quadrature follows them while
  ``FWHM`` stays below about ``p / 2``);
* **cone of incidence**: light uniform in solid angle within ``cone_half_angle``
  of the nominal direction, by Gauss–Legendre quadrature in ``cos ψ``
  (:data:`CONE_RINGS` rings) and the midpoint rule in azimuth
  (:data:`CONE_AZIMUTHS` directions over a half turn, the other half being its
  mirror), each direction at its own angle of incidence. The planes of incidence
  of the tilted directions turn by less than the half-angle, so s and p keep
  their names (a polarised measurement's cross terms are of second order in it).

A thick substrate (``substrate_thickness_mm``) adds its back side
incoherently, as tmm's ``inc_tmm`` does: with the coated face's ``Rf, Tf``
(from the ambient), ``Rb, Tb`` (from inside the substrate), the bare back
face's ``R2, T2`` and the power kept in one pass ``P = exp(-4π Im(q) D / λ)``,
``R = Rf + Tf Tb P² R2 / (1 - Rb R2 P²)`` and ``T = Tf P T2 / (1 - Rb R2 P²)``,
per polarisation. Light travels inside an absorbing substrate with its full
``n + ik``; at its faces the real part stands for it (an error of order
``k / n`` in the face's R and T, 1e-4 for a glass that absorbs 90 % in 1 mm).

R and T and their derivatives with respect to every film's thickness, ``n``
and ``k`` are :func:`.matrices.film_index_response`; the derivatives with
respect to dispersion parameters are chained through
:meth:`.dispersion.DispersionModel.index_and_derivatives` point by point.
"""
from __future__ import annotations

import math

import numpy as np

from thinfilm_mi.design.fitfile import DATA_SCALE, DISPERSION, QUANTITIES, THICKNESS, Measurement
from thinfilm_mi.design.matrices import Response, film_index_response, normal_index, stack_response
from thinfilm_mi.optics.polarization import Component

__all__ = ["FitModel", "film_matrix", "powers", "BANDWIDTH_NODES", "CONE_RINGS", "CONE_AZIMUTHS"]

#: Gauss–Hermite wavelengths per point across a Gaussian bandwidth.
BANDWIDTH_NODES = 7
#: Gauss–Legendre rings (in cos ψ) and azimuths (over a half turn) across the cone of incidence.
CONE_RINGS = 3
CONE_AZIMUTHS = 4
FWHM_TO_SIGMA = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))


def bandwidth_nodes(fwhm: float) -> tuple[np.ndarray, np.ndarray]:
    """``(offsets nm, weights)`` of a Gaussian slit of ``fwhm`` (one node at 0 for 0)."""
    if fwhm <= 0:
        return np.zeros(1), np.ones(1)
    x, w = np.polynomial.hermite_e.hermegauss(BANDWIDTH_NODES)
    return x * fwhm * FWHM_TO_SIGMA, w / w.sum()


def cone_nodes(angle: float, half_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """``(angles of incidence in degrees, weights)`` over a cone of ``half_angle``
    degrees about the direction at ``angle`` (uniform in solid angle)."""
    if half_angle <= 0:
        return np.array([angle]), np.ones(1)
    x, w = np.polynomial.legendre.leggauss(CONE_RINGS)
    cos_a = math.cos(math.radians(half_angle))
    cos_psi = 0.5 * (1 - cos_a) * x + 0.5 * (1 + cos_a)
    sin_psi = np.sqrt(1 - cos_psi ** 2)
    phi = (np.arange(CONE_AZIMUTHS) + 0.5) * math.pi / CONE_AZIMUTHS
    t0 = math.radians(angle)
    cos_t = math.cos(t0) * cos_psi[:, None] + math.sin(t0) * sin_psi[:, None] * np.cos(phi)[None, :]
    theta = np.degrees(np.arccos(np.clip(cos_t, -1.0, 1.0))).ravel()
    weight = np.repeat(w / w.sum(), CONE_AZIMUTHS) / CONE_AZIMUTHS
    return theta, weight


def film_matrix(films, d, wl, beta2, pol: Component) -> tuple:
    """The entries ``(m11, m12, m21, m22)`` of the product ``M_1 ... M_L`` of the
    films' characteristic matrices (arguments and broadcasting as
    :func:`.matrices.stack_response`), with the real cosine and sine for a film
    whose phase is real. The films met in the reverse order have the product with
    ``m11`` and ``m22`` swapped (each ``M_j = K M_jᵀ K``, ``K`` the exchange
    matrix, as its diagonal entries are equal)."""
    k0 = 2.0 * math.pi / wl
    m11, m12, m21, m22 = np.complex128(1.0), np.complex128(0.0), np.complex128(0.0), np.complex128(1.0)
    for n, dj in zip(films, d):
        q = normal_index(n, beta2)
        eta = pol.admittance(n, q)
        phase = k0 * (q.real if not np.any(q.imag) else q) * dj
        c, s = np.cos(phase), np.sin(phase)
        sa, sb = s * (-1j / eta), s * (-1j * eta)
        m11, m12, m21, m22 = m11 * c + m12 * sb, m11 * sa + m12 * c, m21 * c + m22 * sb, m21 * sa + m22 * c
    return m11, m12, m21, m22


def powers(m: tuple, n_in, n_out, beta2, pol: Component) -> Response:
    """R and T of films whose :func:`film_matrix` is ``m``, lit from ``n_in``
    (real) with ``n_out`` the exit medium: :func:`.matrices.stack_response`'s
    without the prefix products its derivatives need."""
    eta0 = pol.admittance(n_in, normal_index(n_in.astype(np.complex128), beta2)).real
    eta_out = pol.admittance(n_out, normal_index(n_out, beta2))
    B, C = m[0] + m[1] * eta_out, m[2] + m[3] * eta_out
    D = eta0 * B + C
    return Response(np.abs((eta0 * B - C) / D) ** 2, 4.0 * eta0 * eta_out.real / np.abs(D) ** 2)


class _Group:
    """The points at one angle of incidence: wavelengths, media, fixed film indices."""

    def __init__(self, m: Measurement, angle: float, wl: np.ndarray):
        self.wl = wl
        self.n_amb = m.ambient.index(wl)
        self.n_sub = m.substrate.index(wl).astype(np.complex128)
        self.beta2 = (self.n_amb.real * math.sin(math.radians(angle))) ** 2
        self.fixed = {k: f.material.index(wl) for k, f in m.materials.items() if f.model is None}
        self.pols: set[Component] = set()
        if m.substrate_thickness_mm is not None:
            q = normal_index(self.n_sub, self.beta2)
            self.P = np.exp(-4.0 * math.pi * q.imag * m.substrate_thickness_mm * 1e6 / wl)
            self.back = {}         # pol -> (R2, T2) of the bare back face


class FitModel:
    """Residuals and Jacobian of a :class:`~.fitfile.Measurement` as a function
    of the free parameters' values ``x`` (in the order of ``measurement.parameters``)."""

    def __init__(self, m: Measurement):
        self.m = m
        self.nominal = np.array([d for _, d in m.films], dtype=np.float64)
        params = m.parameters
        cols: dict = {}                 # kind -> [(target, column)]
        for i, p in enumerate(params):
            cols.setdefault(p.kind, []).append((p.target, i))
        self.thick_cols = [i for _, i in cols.get(THICKNESS, [])]
        self.disp_cols = dict(cols.get(DISPERSION, []))
        self.scale_cols = dict(cols.get(DATA_SCALE, []))
        offsets, w_bw = bandwidth_nodes(m.bandwidth_nm)
        wanted: dict[float, list[np.ndarray]] = {}
        plan = []         # per data set: [(angle key, wavelengths (N, B), weights (B,), point mask (N,))]
        for d in m.datasets:
            rows = []
            for a in np.unique(d.angles):
                mask = d.angles == a
                wl = d.wavelengths[mask][:, None] + offsets[None, :]
                for theta, w_c in zip(*cone_nodes(float(a), m.cone_half_angle)):
                    key = round(float(theta), 9)
                    wanted.setdefault(key, []).append(wl.ravel())
                    rows.append((key, wl, w_c * w_bw, mask))
            plan.append(rows)
        self.groups = {k: _Group(m, k, np.unique(np.concatenate(v))) for k, v in wanted.items()}
        self.terms = []
        for d, rows in zip(m.datasets, plan):
            terms = []
            for key, wl, w, mask in rows:
                g = self.groups[key]
                g.pols.update(d.polarization.components)
                terms.append((key, np.searchsorted(g.wl, wl), w, mask))
            self.terms.append(terms)
        self.sigma = [d.sigma if d.sigma is not None else np.ones(d.value.shape) for d in m.datasets]
        self.points = sum(d.value.size for d in m.datasets)

    @property
    def x0(self) -> np.ndarray:
        return np.array([p.value for p in self.m.parameters], dtype=np.float64)

    def thicknesses(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(d (L,), dd/dx (L, K))``."""
        d, dd = self.m.thickness.thicknesses(x[self.thick_cols], self.nominal)
        full = np.zeros((d.size, x.size))
        full[:, self.thick_cols] = dd
        return d, full

    def _indices(self, g: _Group, x: np.ndarray):
        """Each film's index (P,) and its derivative with respect to x (P, K)."""
        K = x.size
        cache = {}
        for key, f in self.m.materials.items():
            if f.model is None:
                cache[key] = (g.fixed[key], None)
                continue
            model = f.model
            params = dict(model.values)
            for (mk, p), col in self.disp_cols.items():
                if mk == key:
                    params[p] = x[col]
            n, dn = model.index_and_derivatives(g.wl, params)
            full = np.zeros((g.wl.size, K), dtype=np.complex128)
            for i, p in enumerate(model.parameters):
                col = self.disp_cols.get((key, p))
                if col is not None:
                    full[:, col] = dn[:, i]
            cache[key] = (n, full)
        return [cache[k] for k, _ in self.m.films]

    def _chain(self, r, L, dd, dn, reverse=False):
        """dR/dx, dT/dx (P, K) from :func:`film_index_response`'s per-film derivatives."""
        order = slice(None, None, -1) if reverse else slice(None)
        out = []
        for der in (r.dR, r.dT):
            total = der[:, :L][:, order] @ dd
            if der.shape[1] == L:         # no index derivatives: no film's index is fitted
                out.append(total)
                continue
            dre, dim = der[:, L:2 * L][:, order], der[:, 2 * L:][:, order]
            for j, (_, dnj) in enumerate(dn):
                if dnj is not None:
                    total = total + dre[:, j:j + 1] * dnj.real + dim[:, j:j + 1] * dnj.imag
            out.append(total)
        return out

    def _group(self, g: _Group, x: np.ndarray, d: np.ndarray, dd: np.ndarray, jac: bool):
        """{pol: (R, T, dR, dT)} of the group's points; ``d`` (L, B) without ``jac``
        gives R and T of B stacks at once, (P, B)."""
        films = self._indices(g, x)
        pts = (lambda a: a[:, None]) if d.ndim == 2 else (lambda a: a)
        ns = [pts(n) for n, _ in films]
        L = len(ns)
        n_amb = g.n_amb.astype(np.complex128)
        fitted = jac and any(dn is not None for _, dn in films)

        def response(n_in, n_out, reverse):
            if not jac:         # the films' matrix, once for both sides
                return powers((m[3], m[1], m[2], m[0]) if reverse else m, pts(n_in), pts(n_out), pts(g.beta2), pol)
            films_, d_ = (ns[::-1], d[::-1]) if reverse else (ns, d)
            if fitted:
                return film_index_response(n_in, n_out, films_, d_, g.wl, g.beta2, pol)
            return stack_response(n_in, n_out, films_, d_, g.wl, g.beta2, pol)

        out = {}
        for pol in sorted(g.pols, key=lambda c: c.name):
            m = None if jac else film_matrix(ns, list(d), pts(g.wl), pts(g.beta2), pol)
            f = response(g.n_amb.real, g.n_sub, False)
            R, T = f.R, f.T
            dR, dT = self._chain(f, L, dd, films) if jac else (None, None)
            if self.m.substrate_thickness_mm is not None:
                if pol not in g.back:
                    b = stack_response(g.n_sub.real, n_amb, [], [], g.wl, g.beta2, pol, derivatives=False)
                    g.back[pol] = (b.R, b.T)
                R2, T2 = map(pts, g.back[pol])
                P = pts(g.P)
                b = response(g.n_sub.real, n_amb, True)
                Y = R2 * P ** 2
                den = 1.0 - b.R * Y
                R = f.R + f.T * b.T * Y / den
                T = f.T * P * T2 / den
                if jac:
                    dRb, dTb = self._chain(b, L, dd, films, reverse=True)
                    c = (Y / den)[:, None]
                    dden = -Y[:, None] * dRb
                    dR = dR + c * (f.T[:, None] * dTb + b.T[:, None] * dT) \
                        - (f.T * b.T * Y / den ** 2)[:, None] * dden
                    dT = (P * T2 / den)[:, None] * dT - (T / den)[:, None] * dden
            out[pol] = (R, T, dR, dT)
        return out

    def predict(self, x: np.ndarray, jac: bool = True, d: np.ndarray | None = None
                ) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
        """Per data set the modelled values (N,) and their Jacobian (N, K); ``d``
        (nm) overrides the films' thicknesses that ``x`` gives: (L,), or (L, S)
        without ``jac`` for S stacks at once (values (N, S))."""
        x = np.asarray(x, dtype=np.float64)
        d_x, dd = self.thicknesses(x)
        d = d_x if d is None else np.asarray(d, dtype=np.float64)
        resp = {k: self._group(g, x, d, dd, jac) for k, g in self.groups.items()}
        values, jacs = [], []
        for ds, terms in zip(self.m.datasets, self.terms):
            q = np.zeros(ds.value.shape + d.shape[1:])
            dq = np.zeros(ds.value.shape + (x.size,)) if jac else None
            pols = ds.polarization.components
            what = QUANTITIES.index(ds.quantity)          # R and T, in the order the groups hold them
            for key, idx, w, mask in terms:
                r = resp[key]
                val = sum(r[p][what][idx] for p in pols) / len(pols)          # (N, B[, S])
                q[mask] += np.einsum("nb...,b->n...", val, w)
                if jac:
                    der = sum(r[p][2 + what][idx] for p in pols) / len(pols)  # (N, B, K)
                    dq[mask] += np.einsum("nbk,b->nk", der, w)
            col = self.scale_cols.get(ds.index)
            scale = x[col] if col is not None else ds.scale
            if jac:
                dq *= scale
                if col is not None:
                    dq[:, col] = q
            values.append(scale * q)
            jacs.append(dq)
        return values, (jacs if jac else None)

    def residuals(self, x: np.ndarray, jac: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """``((model - measured) / sigma (N,), its Jacobian (N, K))``, data sets in order."""
        values, jacs = self.predict(x, jac)
        e = np.concatenate([(v - d.value) / s for v, d, s in zip(values, self.m.datasets, self.sigma)])
        J = np.concatenate([j / s[:, None] for j, s in zip(jacs, self.sigma)]) if jac else None
        return e, J

    def peak_indices(self, x: np.ndarray) -> np.ndarray:
        """Each film's largest real index over the data's points at the parameters ``x`` (L,)."""
        out = np.zeros(len(self.m.films))
        for g in self.groups.values():
            out = np.maximum(out, [float(np.max(n.real)) for n, _ in self._indices(g, x)])
        return out

    def chi2(self, x: np.ndarray, d: np.ndarray) -> np.ndarray:
        """χ² of S stacks at once: the parameters ``x`` with the films' thicknesses
        ``d`` (L, S) nm in place of those ``x`` gives; (S,)."""
        values, _ = self.predict(x, jac=False, d=d)
        return sum(np.sum(((v - ds.value[:, None]) / s[:, None]) ** 2, axis=0)
                   for v, ds, s in zip(values, self.m.datasets, self.sigma))
