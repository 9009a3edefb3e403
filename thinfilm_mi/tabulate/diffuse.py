"""``thinfilm_diffuse`` in RGB and mono variants: the coated Lambertian term
integrated over wavelengths as a product (no plugin classes here).

In a spectral variant the plugin multiplies, per wavelength,
``f = k_d t(θ_i) t(θ_o) S / π`` with ``t = k_t k_a`` and the interreflection
series ``S = 1/(1 - k_d R_dh)`` ("multiple") or ``1`` ("single"). An RGB value
must be the *integral of that product* against colour matching, not a product
of integrated factors (the fringes of ``t(θ_i)`` and ``t(θ_o)`` line up at some
angles and cancel at others). ``k_d`` is the user's colour (``reflectance``,
per channel as in Mitsuba's ``diffuse``), so with ``ŵ_c`` the channel weights
of :mod:`thinfilm_mi.tabulate.colour` (unit integral):

    π f_c(θ_i, θ_o) = ∫ ŵ_c(λ) t(λ, θ_i) t(λ, θ_o) G(k_d,c, R_dh(λ)) dλ,
    G(k, r) = k / (1 - k r)   ("multiple"),   G(k, r) = k   ("single").

``G`` is interpolated in ``r`` over the range of ``R_dh`` by a polynomial on
:math:`K` Chebyshev nodes ``r_j`` (``K`` chosen so that the interpolation is
within :data:`SERIES_TOLERANCE` relative for every ``k_d`` in [0, 1]; ``G`` is
analytic in ``r`` up to its pole at ``1/k_d >= 1``), which separates ``k_d``
from the wavelengths exactly up to that error:

    π f_c = Σ_j G(k_d,c, r_j) M_jc(θ_i, θ_o),   M_jc = ∫ ŵ_c t t ℓ_j(R_dh) dλ

with ``ℓ_j`` the Lagrange basis. Where ``reflectance`` does not vary over the
surface the expansion is not needed: ``G`` is integrated with the albedo itself
(one basis function, ``M_c = ∫ ŵ_c t t S_c dλ``, ``S_c = G(k_d,c, R_dh)/k_d,c``)
and the kernel multiplies by ``k_d``. The ``M_jc`` are a 2-D table over both
angles (uniform in the angle coordinate of :func:`tables.u_texel`): the angle
nodes are doubled until the 4-point rule predicts the new ones within
:data:`LEVEL_ABS` (at most :data:`MAX_NODES`), then subdivided for the linear
lookup until it is within :data:`LINEAR_ABS` (at most :data:`MAX_TABLE_FLOATS`);
the albedo estimate of the lobe-selection probability, ``Σ_j G(k_d, r_j)
A_jc(θ_i)`` with ``A_jc = ∫ ŵ_c t T_hemi ℓ_j(R_dh) dλ``, is a 1-D table. ``R_dh``
and ``T_hemi`` are the float64 hemispherical factors of
:mod:`thinfilm_mi.tabulate.hemispherical`. The wavelength grid is uniform, halved from
1 nm until ``π f`` at ``k_d = 1`` changes by at most :data:`LEVEL_ABS` (at most
1/16 nm).
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from thinfilm_mi.colour import cie
from thinfilm_mi.materials.model import SPECTRAL_RANGE
from thinfilm_mi.tabulate.axes import PLAIN
from thinfilm_mi.tabulate.base import BuildReport, grid_coordinate, linear_texture, opaque_float
from thinfilm_mi.tabulate.refine import Budget, LinearAxis, interleave, linear_error, subdivide

#: Relative error of the Chebyshev interpolation of ``G(k_d, r)`` in ``r``.
SERIES_TOLERANCE = 1e-5
#: Most Chebyshev nodes in ``r``.
MAX_SERIES_NODES = 24
#: Angle nodes of the first grid, and the most nodes per axis.
FIRST_NODES = 17
MAX_NODES = 129
#: Most floats in the 2-D table (16 MiB), which bounds the linear refinement.
MAX_TABLE_FLOATS = 1 << 22
#: Finest wavelength step (nm): 2^-MAX_LEVEL.
MAX_LEVEL = 4
#: Largest change per channel of ``π f`` (at ``k_d = 1``) accepted between two
#: wavelength steps, and between a grid and its 4-point prediction. Absolute, not
#: CIEDE2000: ``π f`` falls to 0 towards grazing incidence, where ΔE2000 of a
#: near-black colour (~4000 x the abs error) would refine for no visible change;
#: 1e-4 of a white diffuse is ΔE2000 <= 0.05 wherever Y >= 0.01.
LEVEL_ABS = 1e-4
#: Largest abs error of the lookup's linear interpolation (against the 4-point rule):
#: 3e-4 of ``π f`` is ΔE2000 <= 0.1 wherever the colour's Y >= 0.05 (L* varies as
#: Y^(1/3)); darker values lie towards grazing incidence, where ``cos θ_o`` dims them.
LINEAR_ABS = 3e-4


def series_nodes(r_min: float, r_max: float, model: str, kd_max: float = 1.0) -> np.ndarray:
    """The Chebyshev nodes ``r_j`` on ``[r_min, r_max]`` for ``G`` (one node for
    "single", or when ``R_dh`` is constant)."""
    if model == "single" or r_max - r_min < 1e-12:
        return np.array([0.5 * (r_min + r_max)])
    kd = np.linspace(0.0, kd_max, 65)[1:, None]
    r = np.linspace(r_min, r_max, 257)[None, :]
    exact = kd / (1.0 - kd * r)
    for K in range(2, MAX_SERIES_NODES + 1):
        nodes = _chebyshev(r_min, r_max, K)
        approx = _g(kd, nodes[None, :], model) @ lagrange_basis(nodes, r[0]).T
        if np.max(np.abs(approx - exact) / exact) <= SERIES_TOLERANCE:
            return nodes
    return nodes


def _chebyshev(lo: float, hi: float, K: int) -> np.ndarray:
    x = np.cos((2 * np.arange(K) + 1) * math.pi / (2 * K))
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * x


def _g(kd, r, model: str):
    return kd if model == "single" else kd / (1.0 - kd * r)


def lagrange_basis(nodes: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``ℓ_j(r)``, shape ``(len r, len nodes)``."""
    r = np.asarray(r, np.float64)
    out = np.ones((r.size, nodes.size))
    for j, rj in enumerate(nodes):
        for m, rm in enumerate(nodes):
            if m != j:
                out[:, j] *= (r - rm) / (rj - rm)
    return out


def level_weights(level: int, channels: str):
    """The uniform wavelengths of step ``2^-level`` nm over the spectral range and the
    channel weights ``ŵ_c`` there, normalised to unit sum: shapes ``(n,)``, ``(C, n)``."""
    lo, hi = SPECTRAL_RANGE
    n = int(round((hi - lo) * (1 << level)))
    wl = lo + np.arange(n + 1) * ((hi - lo) / n)
    w = cie.channel_weights(channels, wl) * cie.trapezoid_weights(wl)[None, :]
    return wl, w / w.sum(axis=1, keepdims=True)


def integrate(t, w, r_dh, t_hemi, model: str, kd=None, nodes=None):
    """``(M, A, nodes)``: the tables ``M[i, o, j, c] = Σ_l t[i, l] t[o, l] b[l, j, c]`` and
    ``A[i, j, c] = Σ_l t[i, l] T_hemi[l] b[l, j, c]`` of the transmittances ``t`` (angles x
    wavelengths) against the normalised weights ``w`` ``(C, n)``, with ``b`` the ``j``-th
    function of ``R_dh`` times ``w``: the Lagrange basis on the Chebyshev ``nodes``
    (default: :func:`series_nodes` over the range of ``r_dh``), or for a fixed albedo
    ``kd`` (per channel) the one function ``G(k_d, R_dh)/k_d`` (``nodes`` ``[0]``)."""
    C = w.shape[0]
    t = np.ascontiguousarray(t)     # (a strided view would take numpy's matmul off BLAS)
    if kd is not None:
        k = np.asarray(kd, np.float64).reshape(C, 1)
        s = 1.0 if model == "single" else 1.0 / (1.0 - k * r_dh[None, :])
        nodes, b = np.zeros(1), (w * s).T[:, None, :]
    else:
        if nodes is None:
            nodes = series_nodes(float(r_dh.min()), float(r_dh.max()), model)
        b = lagrange_basis(nodes, r_dh)[:, :, None] * w.T[:, None, :]
    # one matrix product per (j, c) (BLAS; einsum's path search alone costs more at these sizes)
    K = b.shape[1]
    M = np.empty((t.shape[0], t.shape[0], K, C))
    for j in range(K):
        for c in range(C):
            M[:, :, j, c] = (t * b[:, j, c][None, :]) @ t.T
    A = ((t * t_hemi[None, :]) @ b.reshape(b.shape[0], -1)).reshape(t.shape[0], K, C)
    return M, A, nodes


class ColourDiffuse:
    """The integrated diffuse term and albedo estimate of one ``thinfilm_diffuse``
    (``factors``: a :class:`DiffuseFactors`).

    ``kd``: the base albedo per channel where it does not vary over the surface;
    then the series is integrated with it exactly (``M_c = ∫ ŵ_c t t S_c dλ``,
    ``S_c = G(k_d,c, R_dh) / k_d,c``, one basis function) and the kernel
    multiplies by ``k_d``; ``None`` for a texture: the Chebyshev expansion
    in ``R_dh`` of the module docstring."""

    def __init__(self, factors, model: str, channels: str,
                 kd: np.ndarray | None = None):
        self.model = model
        C = 1 if channels == "mono" else 3
        self.C = C
        self.fixed = kd is not None
        #: whether the lookups read a thickness scale (a table over it)
        self.scaled = False
        axis = LinearAxis()
        levels = {}

        def level_data(level):
            """Wavelengths, normalised weights ``(C, n)`` and the hemispherical factors."""
            if level not in levels:
                wl, w = level_weights(level, channels)
                if level - 1 in levels:     # the coarser level's wavelengths are every other one
                    _, _, r_c, t_c = levels[level - 1]
                    r_new, t_new = factors.hemispherical(wl[1::2])
                    r_dh, t_hemi = np.empty(wl.size), np.empty(wl.size)
                    r_dh[0::2], r_dh[1::2], t_hemi[0::2], t_hemi[1::2] = r_c, r_new, t_c, t_new
                else:
                    r_dh, t_hemi = factors.hemispherical(wl)
                levels[level] = (wl, w, r_dh, t_hemi)
            return levels[level]

        def tables(level, t):
            _, w, r_dh, t_hemi = level_data(level)
            return integrate(t, w, r_dh, t_hemi, model, kd)

        #: what the build did: ``points`` (values of ``t`` evaluated), the wavelength
        #: ``level``, the angle ``nodes`` and the table's ``texels`` (floats)
        self.report = BuildReport(kind="plain", points=0, result="table")

        def t_at(cos, wl):
            self.report["points"] += cos.size * wl.size
            return factors.t(cos, wl)

        level, nu = 0, FIRST_NODES
        cos = axis.cos(nu)
        t = t_at(cos, level_data(level)[0])
        M, A, nodes = tables(level, t)
        # wavelengths: halve the step until the table (of the single-scattering
        # term, G = k_d = 1, and of the series at k_d = 1) stops changing
        while level < MAX_LEVEL:
            t2 = t_at(cos, level_data(level + 1)[0])
            M2, A2, nodes2 = tables(level + 1, t2)
            same = self._close(M, nodes, M2, nodes2)
            level, t, M, A, nodes = level + 1, t2, M2, A2, nodes2
            if same:
                break
        # angles: double until the 4-point rule predicts the midpoints (t at the
        # new nodes only)
        wl = level_data(level)[0]
        while nu < MAX_NODES:
            t = interleave(t, t_at(axis.midpoints(nu), wl), 0)
            M2, A2, nodes2 = tables(level, t)
            pred = subdivide(subdivide(M, 0, True), 1, True)
            same = self._close(pred, nodes, M2, nodes2)
            nu, M, A, nodes = 2 * nu - 1, M2, A2, nodes2
            if same:
                break
        #: the wavelength level and the angle nodes computed exactly (before the
        #: linear subdivision), for :class:`~thinfilm_mi.tabulate.diffuse_texture.ScaledColourDiffuse`
        self.level, self.exact_nodes = level, nu
        # texels for the linear lookup (judged on the values at k_d = 1)
        budget = Budget(points=0, texels=MAX_TABLE_FLOATS)
        while nu < 4 * MAX_NODES and budget.allows(texels=(2 * nu - 1) ** 2 * M.shape[2] * C):
            m = self.at_one(M, nodes)
            if max(float(np.max(np.abs(linear_error(m, ax, True)))) for ax in (0, 1)) <= LINEAR_ABS:
                break
            M, A = subdivide(subdivide(M, 0, True), 1, True), subdivide(A, 0, True)
            nu = 2 * nu - 1
        self.nodes = nodes
        self.nu = nu
        self.report.update(level=level, nodes=nu, texels=M.size + A.size)
        self.values = M                       # (nu, nu, K, C): for tests
        self.albedo_values = A                # (nu, K, C)
        K = nodes.size
        self.nbytes = (M.size + A.size) * 4
        self._M = linear_texture(M.reshape(nu, nu, K * C))
        self._A = linear_texture(A.reshape(nu, K * C))
        self._nu = opaque_float(nu)
        self._inv_u = opaque_float(1.0 / nu)
        self._r = [opaque_float(float(r)) for r in nodes]
        #: R_dh on the 1 nm grid, for the gradient estimate (its derivatives are the
        #: plugin's DerivativeTable, on the same grid)
        r_dh = level_data(0)[2]
        self._r_dh = linear_texture(r_dh[:, None])

    def at_one(self, M, nodes):
        """``π f`` at ``k_d = 1`` (the series) and the single term (the ``ℓ_j`` sum
        to 1) of tables ``M`` of shape ``(..., K, C)``: shape ``(..., 2 C)``; with a
        fixed ``k_d``: ``M`` (twice)."""
        g = np.ones(1) if self.fixed else np.broadcast_to(_g(1.0, nodes, self.model), nodes.shape)
        return np.concatenate([np.einsum("...jc,j->...c", M, g), M.sum(axis=-2)], axis=-1)

    def _close(self, M, nodes, M2, nodes2) -> bool:
        a, b = self.at_one(M, nodes), self.at_one(M2, nodes2)
        if a.shape != b.shape:
            return False
        return float(np.max(np.abs(a - b))) <= LEVEL_ABS

    def coordinate(self, cos):
        """The angle axis's texture coordinate of ``cos``."""
        cos = dr.clip(cos, 0.0, 1.0)
        sin = dr.safe_sqrt((1.0 - cos) * (1.0 + cos))
        return (PLAIN.texel(cos, sin, 1.0, 1.0, self._nu) + 0.5) * self._inv_u

    def _weights(self, kd):
        """``G(k_d, r_j)`` per node ``j``, as ``mi.Spectrum`` (per channel); with a
        fixed ``k_d``: ``[k_d]`` (the table holds the rest)."""
        if self.fixed:
            return [kd]
        return [_g(kd, r, self.model) for r in self._r]

    def combine(self, res, kd):
        """``Σ_j G(k_d, r_j)`` times the table's channels ``res`` of node ``j``."""
        import mitsuba as mi
        C = self.C
        out = mi.Spectrum(0.0)
        for j, g in enumerate(self._weights(kd)):
            vals = res[j * C:(j + 1) * C]
            out += g * (mi.Spectrum(*vals) if C > 1 else mi.Spectrum(vals[0]))
        return out   # not clamped: see tabulate.colour.ColourTable.lookup

    def r_dh_at(self, wavelengths, active=True):
        """``R_dh`` at ``wavelengths`` (``mi.Spectrum``, nm), detached."""
        import mitsuba as mi
        return dr.detach(mi.Spectrum(*[
            self._r_dh.eval(mi.Point1f(grid_coordinate(wavelengths[k])), active)[0]
            for k in range(dr.size_v(mi.Spectrum))]))

    def series(self, kd, r_dh):
        """``G(k_d, R_dh)`` of the model (per channel ``k_d``, spectral ``R_dh``)."""
        return _g(kd, r_dh, self.model)

    def value(self, cos_i, cos_o, kd, active=True, scale=None):
        """``π f`` (``mi.Spectrum``): the diffuse term without ``1/π`` and ``cos θ_o``
        (``scale``: the thickness scale, read by a table over it only)."""
        import mitsuba as mi
        res = self._M.eval(mi.Point2f(self.coordinate(cos_o), self.coordinate(cos_i)), active)
        return self.combine(res, kd)

    def node_values(self, cos_i, cos_o, active=True, scale=None):
        """``[(r_j, M_j)]``: the nodes ``r_j`` of ``R_dh`` (opaque ``mi.Float``) and the
        table's ``M_jc = ∫ ŵ_c t(θ_i) t(θ_o) ℓ_j(R_dh) dλ`` (``mi.Spectrum``) of a table
        built without a fixed albedo, for a base other than Lambert's
        (:func:`thinfilm_mi.render.orennayar.coated_integrated`)."""
        import mitsuba as mi
        assert not self.fixed, "node_values needs a table built without a fixed albedo"
        res = self._M.eval(mi.Point2f(self.coordinate(cos_o), self.coordinate(cos_i)), active)
        C = self.C
        return [(r, mi.Spectrum(*res[j * C:(j + 1) * C]) if C > 1 else mi.Spectrum(res[j * C]))
                for j, r in enumerate(self._r)]

    def albedo(self, cos_i, kd, active=True, scale=None):
        """``∫ f cos θ_o dω_o``: the diffuse lobe's albedo for light from ``cos_i``."""
        import mitsuba as mi
        return self.combine(self._A.eval(mi.Point1f(self.coordinate(cos_i)), active), kd)
