"""The coated-diffuse term in RGB and mono variants, integrated over wavelengths as a
product: :class:`ColourDiffuse`, and :class:`ScaledColourDiffuse` over the thickness
scale of a ``thickness`` texture (no plugin classes here).

In a spectral variant the plugin multiplies, per wavelength,
``f = k_d t(θ_i) t(θ_o) S / π`` with ``t = k_t k_a`` and the interreflection
series ``S = 1/(1 - k_d R_dh)`` (models with interreflection) or ``1`` ("single"). An RGB value
must be the *integral of that product* against colour matching, not a product
of integrated factors (the fringes of ``t(θ_i)`` and ``t(θ_o)`` line up at some
angles and cancel at others). ``k_d`` is the user's colour (``reflectance``,
per channel as in Mitsuba's ``diffuse``), so with ``ŵ_c`` the channel weights
of :mod:`thinfilm_mi.tabulate.integrated` (unit integral):

    π f_c(θ_i, θ_o) = ∫ ŵ_c(λ) t(λ, θ_i) t(λ, θ_o) G(k_d,c, R_dh(λ)) dλ,
    G(k, r) = k / (1 - k r)   (interreflection),   G(k, r) = k   ("single").

``G`` is the model's: the tables take the coated-diffuse model object
(:data:`thinfilm_mi.render.layered.models.DIFFUSE_MODELS`), read through its ``g(k, r)``
(``G``), ``series(k, r)`` (``G/k``) and ``interreflection`` (whether ``G`` depends on
``r``), numpy arrays in, numpy arrays out.

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
angles (uniform in the angle coordinate of :data:`thinfilm_mi.tabulate.axes.PLAIN`): the angle
nodes are doubled until the 4-point rule predicts the new ones within
:data:`LEVEL_ABS` (at most :data:`MAX_NODES`), then subdivided for the linear
lookup until it is within :data:`LINEAR_ABS` (at most :data:`MAX_TABLE_FLOATS`);
the albedo estimate of the lobe-selection probability, ``Σ_j G(k_d, r_j)
A_jc(θ_i)`` with ``A_jc = ∫ ŵ_c t T_hemi ℓ_j(R_dh) dλ``, is a 1-D table. ``R_dh``
and ``T_hemi`` are the float64 hemispherical factors of
:mod:`thinfilm_mi.tabulate.hemispherical`. The wavelength grid is uniform, halved from
1 nm until ``π f`` at ``k_d = 1`` changes by at most :data:`LEVEL_ABS` (at most
1/16 nm).

**Under a thickness texture.** Every film's thickness is multiplied by the texture's value ``s`` at the hit, so the
integrated product of :class:`~thinfilm_mi.tabulate.diffuse.ColourDiffuse` becomes a
function of ``s`` as well::

    π f_c(θ_i, θ_o, s) = Σ_j G(k_d,c, r_j) M_jc(θ_i, θ_o, s),
    M_jc = ∫ ŵ_c t(λ, θ_i, s) t(λ, θ_o, s) ℓ_j(R_dh(λ, s)) dλ

(one basis function for a constant ``reflectance``, as there), and the albedo estimate
``A_jc(θ_i, s)``. :class:`ScaledColourDiffuse` tabulates ``M`` over ``(s, θ_i, θ_o)``
and ``A`` over ``(s, θ_i)`` for ``s`` in the texture's range ``[s_min, s_max]`` (read
at load; a texture edit rebuilds the table):

* The wavelength step and the exact angle nodes are those that :class:`ColourDiffuse`
  chooses at ``s_max``, where the films are thickest and their fringes narrowest.
  Texels are then added along both angles by the 4-point rule while linear
  interpolation at any scale node is off by more than
  :data:`~thinfilm_mi.tabulate.diffuse.LINEAR_ABS` and :data:`MAX_ANGLE_FLOATS` allows (as
  :class:`ColourDiffuse` does within its budget).
* The scale nodes are uniform in ``sqrt(s / s_max)`` over the range (a thin metal
  film's terms curve most near ``s = 0``), from :data:`FIRST_SCALE_NODES`,
  doubled until the lookup's interpolation over them (cubic, :func:`cubic_stencil`:
  four slices per lookup) predicts the exact tables at every midpoint within
  :data:`SCALE_ABS` (of ``π f`` and its albedo at ``k_d = 1``). Linear interpolation
  would need about four times the nodes (measured: 129 cubic nodes are within 6.8e-4
  for ``SiO2 500; Au 4`` over ``s`` in [0, 1.5], linear ones 4.2e-3).
* The Chebyshev nodes ``r_j`` are shared by every scale: they span the range of
  ``R_dh`` over the first scale nodes (widened by :data:`RANGE_MARGIN`; where a new
  scale node's ``R_dh`` leaves it, the nodes are recomputed over the wider range and
  every slice rebuilt).
* Memory is bounded: the tables may hold :data:`MAX_SCALED_FLOATS` floats; a texture
  whose range needs more scale nodes is refused (a ``ThinFilmError`` naming
  ``thickness`` and its maximum), before the work where the first grid already exceeds it.
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from thinfilm_mi.colour import cie
from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.materials.model import SPECTRAL_RANGE
from thinfilm_mi.tabulate.axes import PLAIN
from thinfilm_mi.tabulate.base import BuildReport, grid_coordinate, linear_texture, opaque_float
from thinfilm_mi.tabulate.integrated import TOLERANCE_ABS_2D
from thinfilm_mi.tabulate.refine import Budget, LinearAxis, interleave, linear_error, subdivide

__all__ = ["ColourDiffuse", "ScaledColourDiffuse", "series_nodes", "lagrange_basis", "level_weights",
           "integrate", "cubic_stencil", "cubic_weights", "cubic_midpoints",
           "SERIES_TOLERANCE", "MAX_SERIES_NODES", "FIRST_NODES", "MAX_NODES", "MAX_TABLE_FLOATS",
           "MAX_LEVEL", "LEVEL_ABS", "LINEAR_ABS", "FIRST_SCALE_NODES", "MAX_SCALE_NODES",
           "MAX_SCALED_FLOATS", "MAX_ANGLE_FLOATS", "RANGE_MARGIN", "SCALE_ABS"]

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

#: Scale nodes of the first grid (uniform in ``sqrt(s / s_max)``), and the most.
FIRST_SCALE_NODES = 5
MAX_SCALE_NODES = 257
#: Largest abs error of the lookup's cubic interpolation over the scale, of ``π f`` and
#: its albedo at ``k_d = 1`` (checked at every midpoint of the scale nodes): the
#: tolerance of the colour tables' nodes over the scale
#: (:data:`~thinfilm_mi.tabulate.integrated.TOLERANCE_ABS_2D`), ΔE2000 <= ~0.2 where Y >= 0.05.
SCALE_ABS = TOLERANCE_ABS_2D
#: Most floats in the 3-D table and its albedo table (128 MiB of float32).
MAX_SCALED_FLOATS = 1 << 25
#: Most floats once texels are added along the angles (32 MiB): the 4-point rule's
#: texels make linear lookups finer than the exact nodes (~3e-4 at 129 nodes), but
#: fourfold in a 3-D table; the build's ``angle_error`` says what the lookup kept.
MAX_ANGLE_FLOATS = 1 << 23
#: The range of ``R_dh`` spanned by the Chebyshev nodes is widened by this fraction
#: of its width (plus 1e-3) on each side, so that scale nodes added later rarely leave it.
RANGE_MARGIN = 0.05


def series_nodes(r_min: float, r_max: float, model, kd_max: float = 1.0) -> np.ndarray:
    """The Chebyshev nodes ``r_j`` on ``[r_min, r_max]`` for the ``G`` of ``model`` (one
    node for a model without interreflection, or when ``R_dh`` is constant)."""
    if not model.interreflection or r_max - r_min < 1e-12:
        return np.array([0.5 * (r_min + r_max)])
    kd = np.linspace(0.0, kd_max, 65)[1:, None]
    r = np.linspace(r_min, r_max, 257)[None, :]
    exact = model.g(kd, r)
    for K in range(2, MAX_SERIES_NODES + 1):
        nodes = _chebyshev(r_min, r_max, K)
        approx = model.g(kd, nodes[None, :]) @ lagrange_basis(nodes, r[0]).T
        if np.max(np.abs(approx - exact) / exact) <= SERIES_TOLERANCE:
            return nodes
    return nodes


def _chebyshev(lo: float, hi: float, K: int) -> np.ndarray:
    x = np.cos((2 * np.arange(K) + 1) * math.pi / (2 * K))
    return 0.5 * (lo + hi) + 0.5 * (hi - lo) * x


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


def integrate(t, w, r_dh, t_hemi, model, kd=None, nodes=None):
    """``(M, A, nodes)``: the tables ``M[i, o, j, c] = Σ_l t[i, l] t[o, l] b[l, j, c]`` and
    ``A[i, j, c] = Σ_l t[i, l] T_hemi[l] b[l, j, c]`` of the transmittances ``t`` (angles x
    wavelengths) against the normalised weights ``w`` ``(C, n)``, with ``b`` the ``j``-th
    function of ``R_dh`` times ``w``: the Lagrange basis on the Chebyshev ``nodes``
    (default: :func:`series_nodes` over the range of ``r_dh``), or for a fixed albedo
    ``kd`` (per channel) the one function ``G(k_d, R_dh)/k_d`` (``nodes`` ``[0]``);
    ``G`` is ``model``'s (module docstring)."""
    C = w.shape[0]
    t = np.ascontiguousarray(t)     # (a strided view would take numpy's matmul off BLAS)
    if kd is not None:
        k = np.asarray(kd, np.float64).reshape(C, 1)
        s = model.series(k, r_dh[None, :])
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


class _Levels:
    """The wavelength levels of a :class:`ColourDiffuse` build: each level's wavelengths,
    normalised weights ``(C, n)`` and hemispherical factors (a finer level evaluates only
    its new wavelengths), and the transmittances ``t``, counted into ``report``."""

    def __init__(self, factors, channels: str, report: BuildReport):
        self.factors, self.channels, self.report = factors, channels, report
        self.levels = {}

    def data(self, level: int):
        """``(wavelengths, weights, R_dh, T_hemi)`` of ``level``."""
        levels = self.levels
        if level not in levels:
            wl, w = level_weights(level, self.channels)
            if level - 1 in levels:     # the coarser level's wavelengths are every other one
                _, _, r_c, t_c = levels[level - 1]
                r_new, t_new = self.factors.hemispherical(wl[1::2])
                r_dh, t_hemi = np.empty(wl.size), np.empty(wl.size)
                r_dh[0::2], r_dh[1::2], t_hemi[0::2], t_hemi[1::2] = r_c, r_new, t_c, t_new
            else:
                r_dh, t_hemi = self.factors.hemispherical(wl)
            levels[level] = (wl, w, r_dh, t_hemi)
        return levels[level]

    def t(self, cos, wl):
        """The transmittance factor ``t`` at the angles ``cos`` and wavelengths ``wl``."""
        self.report["points"] += cos.size * wl.size
        return self.factors.t(cos, wl)

    def tables(self, level: int, t, model, kd):
        """:func:`integrate`'s ``(M, A, nodes)`` of ``t`` on ``level``'s wavelengths."""
        _, w, r_dh, t_hemi = self.data(level)
        return integrate(t, w, r_dh, t_hemi, model, kd)


class ColourDiffuse:
    """The integrated diffuse term and albedo estimate of one ``thinfilm_diffuse``
    (``factors``: a :class:`~thinfilm_mi.render.layered.factors.DiffuseFactors`; ``model``: the
    coated-diffuse model, whose ``G`` the table integrates).

    ``kd``: the base albedo per channel where it does not vary over the surface;
    then the series is integrated with it exactly (``M_c = ∫ ŵ_c t t S_c dλ``,
    ``S_c = G(k_d,c, R_dh) / k_d,c``, one basis function) and the kernel
    multiplies by ``k_d``; ``None`` for a texture: the Chebyshev expansion
    in ``R_dh`` of the module docstring."""

    def __init__(self, factors, model, channels: str,
                 kd: np.ndarray | None = None):
        self.model = model
        self.C = level_weights(0, channels)[1].shape[0]     # the channels' count (colour's fact)
        self.fixed = kd is not None
        #: whether the lookups read a thickness scale (a table over it)
        self.scaled = False
        #: what the build did: ``points`` (values of ``t`` evaluated), the wavelength
        #: ``level``, the angle ``nodes`` and the table's ``texels`` (floats)
        self.report = BuildReport(kind="plain", points=0, result="table")
        levels = _Levels(factors, channels, self.report)
        level, nu, t, M, A, nodes = self._refine_wavelengths(levels, model, kd)
        nu, M, A, nodes = self._refine_angles(levels, model, kd, level, nu, t, M, A, nodes)
        #: the wavelength level and the angle nodes computed exactly (before the
        #: linear subdivision), for :class:`ScaledColourDiffuse`
        self.level, self.exact_nodes = level, nu
        nu, M, A = self._linear_texels(nu, M, A, nodes)
        self.nodes = nodes
        self.nu = nu
        self.report.update(level=level, nodes=nu, texels=M.size + A.size)
        self.values = M                       # (nu, nu, K, C): for tests
        self.albedo_values = A                # (nu, K, C)
        K, C = nodes.size, self.C
        self.nbytes = (M.size + A.size) * 4
        self._M = linear_texture(M.reshape(nu, nu, K * C))
        self._A = linear_texture(A.reshape(nu, K * C))
        self._nu = opaque_float(nu)
        self._inv_u = opaque_float(1.0 / nu)
        self._r = [opaque_float(float(r)) for r in nodes]
        #: R_dh on the 1 nm grid, for the gradient estimate (its derivatives are the
        #: plugin's DerivativeTable, on the same grid)
        r_dh = levels.data(0)[2]
        self._r_dh = linear_texture(r_dh[:, None])

    def _refine_wavelengths(self, levels: "_Levels", model, kd):
        """``(level, nu, t, M, A, nodes)`` on :data:`FIRST_NODES` angles: the wavelength
        step halved until the table (of the single-scattering term, ``G = k_d = 1``, and
        of the series at ``k_d = 1``) stops changing."""
        level, nu = 0, FIRST_NODES
        cos = LinearAxis().cos(nu)
        t = levels.t(cos, levels.data(level)[0])
        M, A, nodes = levels.tables(level, t, model, kd)
        while level < MAX_LEVEL:
            t2 = levels.t(cos, levels.data(level + 1)[0])
            M2, A2, nodes2 = levels.tables(level + 1, t2, model, kd)
            same = self._close(M, nodes, M2, nodes2)
            level, t, M, A, nodes = level + 1, t2, M2, A2, nodes2
            if same:
                break
        return level, nu, t, M, A, nodes

    def _refine_angles(self, levels: "_Levels", model, kd, level: int, nu: int, t, M, A, nodes):
        """``(nu, M, A, nodes)``: the angle nodes doubled until the 4-point rule predicts
        the midpoints (``t`` at the new nodes only)."""
        axis = LinearAxis()
        wl = levels.data(level)[0]
        while nu < MAX_NODES:
            t = interleave(t, levels.t(axis.midpoints(nu), wl), 0)
            M2, A2, nodes2 = levels.tables(level, t, model, kd)
            pred = subdivide(subdivide(M, 0, True), 1, True)
            same = self._close(pred, nodes, M2, nodes2)
            nu, M, A, nodes = 2 * nu - 1, M2, A2, nodes2
            if same:
                break
        return nu, M, A, nodes

    def _linear_texels(self, nu: int, M, A, nodes):
        """``(nu, M, A)`` subdivided by the 4-point rule until a linear lookup is within
        :data:`LINEAR_ABS` (judged on the values at ``k_d = 1``) or the texels reach
        :data:`MAX_TABLE_FLOATS`."""
        budget = Budget(points=0, texels=MAX_TABLE_FLOATS)
        while nu < 4 * MAX_NODES and budget.allows(texels=(2 * nu - 1) ** 2 * M.shape[2] * self.C):
            m = self.at_one(M, nodes)
            if max(float(np.max(np.abs(linear_error(m, ax, True)))) for ax in (0, 1)) <= LINEAR_ABS:
                break
            M, A = subdivide(subdivide(M, 0, True), 1, True), subdivide(A, 0, True)
            nu = 2 * nu - 1
        return nu, M, A

    def at_one(self, M, nodes):
        """``π f`` at ``k_d = 1`` (the series) and the single term (the ``ℓ_j`` sum
        to 1) of tables ``M`` of shape ``(..., K, C)``: shape ``(..., 2 C)``; with a
        fixed ``k_d``: ``M`` (twice)."""
        g = np.ones(1) if self.fixed else np.broadcast_to(self.model.g(1.0, nodes), nodes.shape)
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
        return [self.model.g(kd, r) for r in self._r]

    def combine(self, res, kd):
        """``Σ_j G(k_d, r_j)`` times the table's channels ``res`` of node ``j``."""
        import mitsuba as mi
        C = self.C
        out = mi.Spectrum(0.0)
        for j, g in enumerate(self._weights(kd)):
            vals = res[j * C:(j + 1) * C]
            out += g * (mi.Spectrum(*vals) if C > 1 else mi.Spectrum(vals[0]))
        return out   # not clamped: see tabulate.integrated.ColourTable.lookup

    def r_dh_at(self, wavelengths, active=True):
        """``R_dh`` at ``wavelengths`` (``mi.Spectrum``, nm), detached."""
        import mitsuba as mi
        return dr.detach(mi.Spectrum(*[
            self._r_dh.eval(mi.Point1f(grid_coordinate(wavelengths[k])), active)[0]
            for k in range(dr.size_v(mi.Spectrum))]))

    def series(self, kd, r_dh):
        """``G(k_d, R_dh)`` of the model (per channel ``k_d``, spectral ``R_dh``)."""
        return self.model.g(kd, r_dh)

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
        (:meth:`thinfilm_mi.render.layered.models.DiffuseModel.rough_integrated`)."""
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


def _refusal(plugin: str, s_max: float):
    """The error a :class:`ScaledColourDiffuse` build raises when the scale range up to
    ``s_max`` needs more than its budget, ``why`` saying what."""
    def refused(why: str) -> ThinFilmError:
        return ThinFilmError(f"{plugin}: 'thickness': a texture reaching {s_max:g} {why} "
                             f"(at most {MAX_SCALED_FLOATS} floats and {MAX_SCALE_NODES} "
                             "scale nodes); lower its maximum, or use a spectral variant")
    return refused


class _ScaleSlices:
    """The slices of a :class:`ScaledColourDiffuse` build: ``(M, A)`` of the thickness
    scales asked for, on the wavelengths of ``level`` and the ``nu`` exact angle nodes,
    with the Chebyshev nodes in ``R_dh`` (``nodes``; ``None`` for a fixed ``kd``) widened
    whenever a scale's ``R_dh`` leaves their range; evaluations counted into ``report``."""

    def __init__(self, factors, model, channels: str, kd, level: int, nu: int,
                 report: BuildReport):
        self.factors, self.model, self.kd, self.report = factors, model, kd, report
        self.wl, self.w = level_weights(level, channels)
        self.cos = LinearAxis().cos(nu)
        self.nodes, self.range = None, None

    def widen(self, r_dh) -> None:
        """Widen the nodes' range to hold ``r_dh`` (with :data:`RANGE_MARGIN`)."""
        lo, hi = float(r_dh.min()), float(r_dh.max())
        if self.range is not None:
            lo, hi = min(lo, self.range[0]), max(hi, self.range[1])
        pad = RANGE_MARGIN * (hi - lo) + 1e-3
        self.range = (max(lo - pad, 0.0), min(hi + pad, 0.5 * (1.0 + hi)))
        self.nodes = series_nodes(*self.range, self.model)

    def build(self, s):
        """``(M, A)`` at the scales ``s``: ``(ns, nu, nu, K, C)``, ``(ns, nu, K, C)``; the
        Chebyshev nodes widened first where ``R_dh`` there leaves their range."""
        r_dh, t_hemi = self.factors.hemispherical_scales(self.wl, s)
        if self.kd is None and (self.range is None or r_dh.min() < self.range[0]
                                or r_dh.max() > self.range[1]):
            self.widen(r_dh)
        Ms, As = [], []
        for k, sk in enumerate(s):
            t = self.factors.at_scale(float(sk)).t(self.cos, self.wl)
            self.report["points"] += t.size
            M, A, _ = integrate(t, self.w, r_dh[k], t_hemi[k], self.model, self.kd, self.nodes)
            Ms.append(M)
            As.append(A)
        return np.stack(Ms), np.stack(As)


class ScaledColourDiffuse(ColourDiffuse):
    """:class:`~thinfilm_mi.tabulate.diffuse.ColourDiffuse` over the thickness scale
    ``s`` in ``[s_min, s_max]`` (module docstring): ``factors`` (a
    :class:`~thinfilm_mi.render.layered.factors.DiffuseFactors` at scale 1, whose
    ``at_scale(s)`` and ``hemispherical_scales`` give the terms at ``s``), ``model``,
    ``channels`` and ``kd`` as there. ``plugin`` names the BSDF in errors. The lookups
    take the hit's ``scale`` (clamped to the range)."""

    def __init__(self, factors, model, channels: str, kd: np.ndarray | None, s_max: float,
                 plugin: str = "thinfilm_diffuse", s_min: float = 0.0):
        s_max = max(float(s_max), 0.0)
        s_lo = min(max(float(s_min), 0.0), s_max)
        span = s_max - s_lo
        # nodes uniform in sqrt(s / s_max) (thin metal films curve most near s = 0)
        q_lo = float(np.sqrt(s_lo / s_max)) if s_max > 0 else 0.0

        def at(u):      # the scales of the nodes u in [0, 1]
            return s_max * (q_lo + (1.0 - q_lo) * u) ** 2
        top = ColourDiffuse(factors.at_scale(s_max), model, channels, kd)
        self.model, self.C, self.fixed, self.scaled = model, top.C, top.fixed, True
        level = top.level
        nu = nu0 = top.exact_nodes     # the exact angle nodes; texels are added at the end
        report = BuildReport(kind="plain", points=top.report["points"], result="table")
        slices = _ScaleSlices(factors, model, channels, kd, level, nu0, report)
        u = np.linspace(0.0, 1.0, FIRST_SCALE_NODES) if span > 0.0 else np.zeros(1)
        u, M, A = self._refine_scales(slices, at, u, nu, _refusal(plugin, s_max))
        nu, M, A = self._angle_texels(M, A, u.size, nu, slices.nodes, report)
        nodes = np.zeros(1) if self.fixed else slices.nodes
        K, C, ns = nodes.size, self.C, u.size
        self.nodes, self.nu, self.level, self.exact_nodes = nodes, nu, level, nu0
        self.scales = at(u)
        #: what the build did (as ColourDiffuse's report, plus the scale nodes)
        self.report = report
        report.update(level=level, nodes=nu, scale_nodes=ns, texels=M.size + A.size)
        self.values, self.albedo_values = M, A     # (ns, nu, nu, K, C), (ns, nu, K, C): for tests
        self.nbytes = (M.size + A.size) * 4
        # the slices stacked along the texture's rows: a lookup reads four slices, each
        # with bilinear filtering inside its own rows (the angle coordinate stays within
        # [0.5, nu - 0.5] texels of a slice)
        self.ns = ns
        self._M = linear_texture(M.reshape(ns * nu, nu, K * C))
        self._A = linear_texture(A.reshape(ns * nu, K * C))
        self._nu = opaque_float(nu)
        self._inv_u = opaque_float(1.0 / nu)
        self._r = [opaque_float(float(r)) for r in nodes]
        self._q_lo = opaque_float(q_lo)
        self._inv_s = opaque_float(1.0 / s_max if s_max > 0 else 0.0)
        self._inv_q = opaque_float(1.0 / (1.0 - q_lo) if span > 0 else 0.0)
        #: R_dh at s_max on the 1 nm grid (:meth:`r_dh_at`): read by the gradient estimate of
        #: models without interreflection only, where it drops out (the others refuse film-parameter
        #: gradients together with a texture)
        self._r_dh = top._r_dh

    def _refine_scales(self, slices: "_ScaleSlices", at, u, nu: int, refused):
        """``(u, M, A)``: the scale nodes ``u`` (in ``[0, 1]``, scales ``at(u)``) doubled
        until the cubic lookup over the scale predicts the midpoints' slices within
        :data:`SCALE_ABS`; ``refused(why)`` is the error raised past the budget."""
        budget = Budget(points=0, texels=MAX_SCALED_FLOATS)
        if not self.fixed:      # the Chebyshev nodes first: a table too large is refused before the work
            slices.widen(slices.factors.hemispherical_scales(slices.wl, at(u))[0])
        if not budget.allows(texels=u.size * nu * (nu + 1) * (1 if self.fixed else slices.nodes.size) * self.C):
            raise refused("needs more floats than the budget allows")
        M, A = slices.build(at(u))
        while u.size > 1:
            if 2 * u.size - 1 > MAX_SCALE_NODES or not budget.allows(
                    texels=(2 * u.size - 1) * nu * (nu + 1) * M.shape[3] * self.C):
                raise refused("needs more scale nodes than the budget allows")
            mid = 0.5 * (u[:-1] + u[1:])
            nodes = slices.nodes
            M_mid, A_mid = slices.build(at(mid))
            if nodes is not slices.nodes:      # the range widened: rebuild the nodes' slices
                M, A = slices.build(at(u))
            nodes = slices.nodes
            err = max(float(np.max(np.abs(self.at_one(cubic_midpoints(M) - M_mid, nodes)))),
                      float(np.max(np.abs(self.at_one(cubic_midpoints(A) - A_mid, nodes)))))
            slices.report["scale_error"] = err
            if err <= SCALE_ABS:     # the lookup (cubic in u) is verified on these nodes
                break
            u, M, A = interleave(u, mid, 0), interleave(M, M_mid, 0), interleave(A, A_mid, 0)
        return u, M, A

    def _angle_texels(self, M, A, ns: int, nu: int, nodes, report: BuildReport):
        """``(nu, M, A)`` subdivided along the angles, checked at every scale node, until a
        linear lookup is within :data:`LINEAR_ABS` or the texels reach
        :data:`MAX_ANGLE_FLOATS` (as :class:`ColourDiffuse`: the texels the budget allows)."""
        while True:
            m = self.at_one(M, nodes if not self.fixed else np.zeros(1))
            err = max(float(np.max(np.abs(linear_error(m, ax, True)))) for ax in (1, 2))
            report["angle_error"] = err
            if err <= LINEAR_ABS or ns * (2 * nu - 1) * (2 * nu) * M.shape[3] * self.C > MAX_ANGLE_FLOATS:
                return nu, M, A
            M, A = subdivide(subdivide(M, 1, True), 2, True), subdivide(A, 1, True)
            nu = 2 * nu - 1

    def _slices(self, scale):
        """``[(k, w_k)]``: the slices a lookup at ``scale`` reads and their weights
        (:func:`cubic_stencil`; one slice without a scale range)."""
        import mitsuba as mi
        if self.ns == 1:
            return [(mi.Float(0.0), mi.Float(1.0))]
        x = (dr.safe_sqrt(scale * self._inv_s) - self._q_lo) * self._inv_q
        # clamped to the range in value, not in gradient (the cubic continues beyond it)
        x = (x + (dr.clip(dr.detach(x), 0.0, 1.0) - dr.detach(x))) * (self.ns - 1)
        b, w = cubic_stencil(dr.detach(x), self.ns, dr)
        w = cubic_weights(x - b)
        return [(b + m, w[m]) for m in range(4)]

    def _rows(self, cos_i, k):
        """The row coordinate of ``cos_i`` in slice ``k``."""
        return (k + self.coordinate(cos_i)) * (1.0 / self.ns)

    def _table(self, cos_i, cos_o, scale, active):
        import mitsuba as mi
        u_o = self.coordinate(cos_o)
        out = None
        for k, w in self._slices(scale):
            res = self._M.eval(mi.Point2f(u_o, self._rows(cos_i, k)), active)
            out = [w * r for r in res] if out is None else [o + w * r for o, r in zip(out, res)]
        return out

    def value(self, cos_i, cos_o, kd, active=True, scale=None):
        return self.combine(self._table(cos_i, cos_o, scale, active), kd)

    def node_values(self, cos_i, cos_o, active=True, scale=None):
        import mitsuba as mi
        assert not self.fixed, "node_values needs a table built without a fixed albedo"
        res = self._table(cos_i, cos_o, scale, active)
        C = self.C
        return [(r, mi.Spectrum(*res[j * C:(j + 1) * C]) if C > 1 else mi.Spectrum(res[j * C]))
                for j, r in enumerate(self._r)]

    def albedo(self, cos_i, kd, active=True, scale=None):
        import mitsuba as mi
        out = None
        for k, w in self._slices(scale):
            res = self._A.eval(mi.Point1f(self._rows(cos_i, k)), active)
            out = [w * r for r in res] if out is None else [o + w * r for o, r in zip(out, res)]
        return self.combine(out, kd)


def cubic_stencil(x, n: int, ops=np):
    """The cubic interpolation at the node coordinate ``x`` in ``[0, n - 1]`` of ``n >= 4``
    uniform nodes: ``(b, [w_0..w_3])``, the Lagrange weights of the nodes ``b..b+3`` with
    ``b = clip(floor(x) - 1, 0, n - 4)`` (centred inside, one-sided in the end intervals).
    ``ops``: ``np`` or ``drjit`` (``b`` then a float)."""
    b = ops.clip(ops.floor(x) - 1.0, 0.0, float(n - 4))
    return b, cubic_weights(x - b)


def cubic_weights(p):
    """The Lagrange weights of the nodes 0, 1, 2, 3 at ``p``."""
    p1, p2, p3 = p - 1.0, p - 2.0, p - 3.0
    return [-p1 * p2 * p3 * (1.0 / 6.0), p * p2 * p3 * 0.5, -p * p1 * p3 * 0.5, p * p1 * p2 * (1.0 / 6.0)]


def cubic_midpoints(values: np.ndarray) -> np.ndarray:
    """The lookup's cubic interpolation (:func:`cubic_stencil`) halfway between the nodes
    along axis 0 of ``values``."""
    n = values.shape[0]
    b, w = cubic_stencil(np.arange(n - 1) + 0.5, n)
    b = b.astype(int)
    shape = (-1,) + (1,) * (values.ndim - 1)
    return sum(w[m].reshape(shape) * values[b + m] for m in range(4))
