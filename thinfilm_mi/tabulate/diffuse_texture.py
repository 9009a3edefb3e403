"""``thinfilm_diffuse`` in RGB and mono variants under a ``thickness`` texture that
varies over the surface: the integrated diffuse tables of
:mod:`thinfilm_mi.tabulate.diffuse` over the thickness scale too (no plugin classes here).

Every film's thickness is multiplied by the texture's value ``s`` at the hit, so the
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

import drjit as dr
import numpy as np

from thinfilm_mi.errors import ThinFilmError
from thinfilm_mi.tabulate.base import BuildReport, linear_texture, opaque_float
from thinfilm_mi.tabulate.colour import TOLERANCE_ABS_2D
from thinfilm_mi.tabulate.diffuse import LINEAR_ABS, ColourDiffuse, integrate, level_weights, series_nodes
from thinfilm_mi.tabulate.refine import Budget, LinearAxis, interleave, linear_error, subdivide

__all__ = ["ScaledColourDiffuse", "cubic_stencil", "cubic_weights", "cubic_midpoints", "FIRST_SCALE_NODES",
           "MAX_SCALE_NODES", "MAX_SCALED_FLOATS", "MAX_ANGLE_FLOATS", "RANGE_MARGIN", "SCALE_ABS"]

#: Scale nodes of the first grid (uniform in ``sqrt(s / s_max)``), and the most.
FIRST_SCALE_NODES = 5
MAX_SCALE_NODES = 257
#: Largest abs error of the lookup's cubic interpolation over the scale, of ``π f`` and
#: its albedo at ``k_d = 1`` (checked at every midpoint of the scale nodes): the
#: tolerance of the colour tables' nodes over the scale
#: (:data:`~thinfilm_mi.tabulate.colour.TOLERANCE_ABS_2D`), ΔE2000 <= ~0.2 where Y >= 0.05.
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


class ScaledColourDiffuse(ColourDiffuse):
    """:class:`~thinfilm_mi.tabulate.diffuse.ColourDiffuse` over the thickness scale
    ``s`` in ``[s_min, s_max]`` (module docstring): ``factors`` (a
    :class:`~thinfilm_mi.render.diffuse.DiffuseFactors` at scale 1, whose
    ``at_scale(s)`` and ``hemispherical_scales`` give the terms at ``s``), ``model``,
    ``channels`` and ``kd`` as there. ``plugin`` names the BSDF in errors. The lookups
    take the hit's ``scale`` (clamped to the range)."""

    def __init__(self, factors, model: str, channels: str, kd: np.ndarray | None, s_max: float,
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
        wl, w = level_weights(level, channels)
        cos = LinearAxis().cos(nu0)
        report = BuildReport(kind="plain", points=top.report["points"], result="table")
        budget = Budget(points=0, texels=MAX_SCALED_FLOATS)
        state = {"nodes": None, "range": None}

        def refused(why):
            return ThinFilmError(f"{plugin}: 'thickness': a texture reaching {s_max:g} {why} "
                                 f"(at most {MAX_SCALED_FLOATS} floats and {MAX_SCALE_NODES} "
                                 "scale nodes); lower its maximum, or use a spectral variant")

        def widen(r_dh):
            lo, hi = float(r_dh.min()), float(r_dh.max())
            if state["range"] is not None:
                lo, hi = min(lo, state["range"][0]), max(hi, state["range"][1])
            pad = RANGE_MARGIN * (hi - lo) + 1e-3
            state["range"] = (max(lo - pad, 0.0), min(hi + pad, 0.5 * (1.0 + hi)))
            state["nodes"] = series_nodes(*state["range"], model)

        def build(s):
            """``(M, A)`` at the scales ``s``: ``(ns, nu, nu, K, C)``, ``(ns, nu, K, C)``; the
            Chebyshev nodes widened first where ``R_dh`` there leaves their range."""
            r_dh, t_hemi = factors.hemispherical_scales(wl, s)
            if not self.fixed and (state["range"] is None or r_dh.min() < state["range"][0]
                                   or r_dh.max() > state["range"][1]):
                widen(r_dh)
            Ms, As = [], []
            for k, sk in enumerate(s):
                t = factors.at_scale(float(sk)).t(cos, wl)
                report["points"] += t.size
                M, A, _ = integrate(t, w, r_dh[k], t_hemi[k], model, kd, state["nodes"])
                Ms.append(M)
                As.append(A)
            return np.stack(Ms), np.stack(As)

        u = np.linspace(0.0, 1.0, FIRST_SCALE_NODES) if span > 0.0 else np.zeros(1)
        if not self.fixed:      # the Chebyshev nodes first: a table too large is refused before the work
            widen(factors.hemispherical_scales(wl, at(u))[0])
        if not budget.allows(texels=u.size * nu * (nu + 1) * (1 if self.fixed else state["nodes"].size) * self.C):
            raise refused("needs more floats than the budget allows")
        M, A = build(at(u))
        while u.size > 1:
            if 2 * u.size - 1 > MAX_SCALE_NODES or not budget.allows(
                    texels=(2 * u.size - 1) * nu * (nu + 1) * M.shape[3] * self.C):
                raise refused("needs more scale nodes than the budget allows")
            mid = 0.5 * (u[:-1] + u[1:])
            nodes = state["nodes"]
            M_mid, A_mid = build(at(mid))
            if nodes is not state["nodes"]:      # the range widened: rebuild the nodes' slices
                M, A = build(at(u))
            nodes = state["nodes"]
            err = max(float(np.max(np.abs(self.at_one(cubic_midpoints(M) - M_mid, nodes)))),
                      float(np.max(np.abs(self.at_one(cubic_midpoints(A) - A_mid, nodes)))))
            report["scale_error"] = err
            if err <= SCALE_ABS:     # the lookup (cubic in u) is verified on these nodes
                break
            u, M, A = interleave(u, mid, 0), interleave(M, M_mid, 0), interleave(A, A_mid, 0)
        # the angle axis, checked at every scale node
        while True:
            m = self.at_one(M, state["nodes"] if not self.fixed else np.zeros(1))
            err = max(float(np.max(np.abs(linear_error(m, ax, True)))) for ax in (1, 2))
            report["angle_error"] = err
            if err <= LINEAR_ABS or u.size * (2 * nu - 1) * (2 * nu) * M.shape[3] * self.C > MAX_ANGLE_FLOATS:
                break     # (as ColourDiffuse: the texels the budget allows)
            M, A = subdivide(subdivide(M, 1, True), 2, True), subdivide(A, 1, True)
            nu = 2 * nu - 1
        nodes = np.zeros(1) if self.fixed else state["nodes"]
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
        #: model "single" only, where it drops out (the other models refuse film-parameter
        #: gradients together with a texture)
        self._r_dh = top._r_dh

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
