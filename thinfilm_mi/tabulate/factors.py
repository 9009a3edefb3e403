"""The coated-diffuse model's spectral factors in spectral variants as one table
(:class:`FactorTable`; no plugin classes here): ``k_r(θ, λ)`` and ``t(θ, λ)`` of
:class:`~thinfilm_mi.render.layered.factors.DiffuseFactors` (the coating's reflectance, and the
power that reaches the base: ``k_t k_a``, or ``T n_0/n_b`` for model "exact"), with
``R_dh(λ)`` and ``T_hemi(λ)``, read by the kernel in place of the stack's recursion or
its tables of ``R`` and ``T``: one bilinear read at ``θ_i`` serves ``k_r``, ``t`` and the
hemispherical terms, one read of ``t`` alone each ``θ_o``. (The RGB and mono variants
integrate the diffuse term instead: :mod:`thinfilm_mi.tabulate.diffuse`.)
"""
from __future__ import annotations

import math

import drjit as dr
import numpy as np

from thinfilm_mi.materials.model import SPECTRAL_RANGE
from thinfilm_mi.tabulate.base import GRAZING_COS, BuildReport
from thinfilm_mi.tabulate.refine import convergence_factor

__all__ = ["FactorTable", "FACTOR_FIRST_NODES", "FACTOR_STEPS", "FACTOR_MAX_FLOATS",
           "FACTOR_ANGLE_SHARE"]

#: Angle nodes (uniform in ``sqrt(cos θ)`` over [0, 1]) of the first grid of a
#: :class:`FactorTable`; doubled (less one) until the lookup is within the target.
FACTOR_FIRST_NODES = 33
#: Wavelength steps (nm) of a :class:`FactorTable`: the first everywhere, a finer one
#: (the first that is within the target) in a band of angles towards grazing incidence.
#: (Nodes uniform in wavenumber, as a stack's fringes, fail more often: under "SiO2 500;
#: Au 5" the paper's factors need 0.5 nm at 830 nm as well, where Au's index varies.)
FACTOR_STEPS = (1.0, 0.5, 0.25, 0.125)   # (the first: R_dh, T_hemi's 1 nm grid too)
#: Most floats of a :class:`FactorTable` (8 MiB of float32): beyond, the factors are
#: evaluated exactly (the kernel's recursion).
FACTOR_MAX_FLOATS = 1 << 21
#: The share of the target the angle nodes are refined to (the rest is the wavelength
#: nodes'), as the cubic tables' refinement aims each axis at half of it.
FACTOR_ANGLE_SHARE = 0.5


def _check_points(step: float, kinks) -> tuple:
    """The wavelength nodes over 360-830 nm ``step`` nm apart, and the wavelengths where
    the linear lookup between them is checked: the midpoints, and the indices' kinks
    (where a dataset's slope jumps, linear interpolation errs most at the kink) that
    are not nodes."""
    lo, hi = SPECTRAL_RANGE
    wl = np.linspace(lo, hi, int(round((hi - lo) / step)) + 1)
    x = (np.asarray(kinks, np.float64) - lo) / step
    kinks = np.asarray(kinks, np.float64)[(x > 0) & (x < wl.size - 1)
                                          & (np.abs(x - np.round(x)) > 1e-6)]
    return wl, np.unique(np.concatenate([0.5 * (wl[:-1] + wl[1:]), kinks]))


def _cell_errors(cos, at, between, wl, checks):
    """The bilinear lookup's error per angle cell, the largest over wavelengths and
    channels, from the exact values ``at`` the node wavelengths ``wl`` and at the
    ``checks`` between them (angle x wavelength x channel) at the angles ``cos``, the
    nodes' and their midpoints alternating: ``err_u + err_w`` (``err_u``: at the cell's
    midpoints at the node wavelengths; ``err_w``: the larger of its two nodes' at the
    checks) and ``err_c`` (at its midpoints at the checks), the larger; 0 in the grazing
    sliver (a cell counts where both its nodes lie outside it)."""
    step = wl[1] - wl[0]
    j = np.clip(np.floor((checks - wl[0]) / step).astype(int), 0, wl.size - 2)
    w = ((checks - wl[j]) / step)[None, :, None]
    nodes = at[0::2]
    err_u = np.abs(0.5 * (nodes[:-1] + nodes[1:]) - at[1::2]).max(axis=(1, 2))
    linear = (1.0 - w) * nodes[:, j] + w * nodes[:, j + 1]
    err_w = np.abs(linear - between[0::2]).max(axis=(1, 2))
    err_c = np.abs(0.5 * (linear[:-1] + linear[1:]) - between[1::2]).max(axis=(1, 2))
    keep = cos[0::2] >= GRAZING_COS
    err = np.maximum(err_u + np.maximum(err_w[:-1], err_w[1:]), err_c)
    return np.where(keep[:-1] & keep[1:], err, 0.0)


class FactorTable:
    """Spectral variants: the coated-diffuse model's spectral factors ``k_r(θ, λ)`` and
    ``t(θ, λ)`` on a grid uniform in ``s = sqrt(cos θ)`` over [0, 1] and in ``λ`` over
    360-830 nm, read by bilinear interpolation (four reads of each per wavelength), with
    ``R_dh(λ)`` and ``T_hemi(λ)`` every 1 nm (read linearly, as the ``regular`` spectra
    they replace).

    ``rt(cos, wl)``: the exact float64 ``(k_r, t)``, each of shape ``(len cos, len wl)``;
    ``hemispherical(wl)``: ``(R_dh, T_hemi)`` over ``wl``; ``error``: the target max abs
    error of ``k_r`` and ``t`` (``table_error``); ``kinks``: wavelengths where an index's
    slope jumps (checked too). The build compares the bilinear lookup with exact values
    at the midpoints of the angle cells at the wavelength nodes (``err_u``), at every
    angle node between the wavelength nodes (``err_w``) and at the angle cells'
    midpoints between them (``err_c``), outside the grazing sliver ``cos θ <``
    :data:`~thinfilm_mi.tabulate.base.GRAZING_COS`, which the stack's tables leave out
    of their verification too, and accepts a cell where ``err_u + err_w <= error`` (the
    larger ``err_w`` of its two nodes) and ``err_c <= error``: linear interpolation errs
    most at a cell's midpoint (for a locally constant second derivative), and the
    bilinear lookup by at most the sum of its two
    axes' errors (``f - P_u P_w f = (f - P_u f) + P_u (f - P_w f)``, ``|P_u g| <= max
    |g|``): the criterion of the cubic tables (``err_u + err_v <= table_error``,
    :mod:`thinfilm_mi.tabulate.exact`). The angle nodes grow from
    :data:`FACTOR_FIRST_NODES` (to ``2^n + 1``, by the factor the error's observed order
    asks for: :func:`~thinfilm_mi.tabulate.refine.convergence_factor`) until ``err_u`` is
    within :data:`FACTOR_ANGLE_SHARE` of the target at the first wavelength step of
    :data:`FACTOR_STEPS`; the angles where
    the wavelength nodes miss the rest (towards grazing incidence, where a film between
    media of unlike index is a cavity of high finesse: under a free-standing "SiO2 500"
    ``R`` goes from 0.33 to 0.001 between 360 and 361.5 nm at ``cos θ = 0.022``) form a
    band of their own with the first finer step that meets the target (steps that the
    ``h²`` convergence of linear interpolation rules out are skipped). :attr:`built` is
    false when that needs more than :data:`FACTOR_MAX_FLOATS` floats or a step finer
    than the finest (:attr:`report` says why); the plugin then evaluates the factors
    exactly.

    The angle coordinate ``s`` puts nodes towards grazing incidence, where ``R`` and
    ``T`` change over ``cos θ ~ 1e-3`` (``R -> 1`` at ``cos θ = 0``; under "SiO2 500;
    Au 5" at 543 nm a leaky mode takes ``R`` from 1 to 0.74 by ``cos θ = 1e-3``): nodes
    uniform in ``cos θ`` miss it (an error of 0.07 at 1025 nodes); the sliver is not
    verified, but its interpolation follows ``R -> 1``."""

    def __init__(self, rt, hemispherical, error: float, kinks=()):
        error = float(error)
        #: what the build did: ``points`` (exact evaluations), the angle ``nodes``, the
        #: ``band`` (angle cells with the finer wavelength ``fine_step``), the largest
        #: ``error`` of a cell (``err_u + err_w`` or ``err_c``), ``texels`` (floats),
        #: ``result``
        self.report = BuildReport(kind="factors", points=0, result="table")
        self.built = False

        def evaluate(cos, wl):
            self.report["points"] += cos.size * wl.size
            return np.stack(rt(cos, wl), axis=-1)

        nu, last = FACTOR_FIRST_NODES, None
        wl, checks = _check_points(FACTOR_STEPS[0], kinks)
        while True:
            if 2 * nu * wl.size > FACTOR_MAX_FLOATS:
                self._refuse(f"more than {FACTOR_MAX_FLOATS} floats for a bilinear error "
                             f"within {FACTOR_ANGLE_SHARE * error:g} along the angle")
                return
            cos = np.linspace(0.0, 1.0, 2 * nu - 1) ** 2
            at = evaluate(cos, wl)
            nodes = at[0::2]
            err_u = np.abs(0.5 * (nodes[:-1] + nodes[1:]) - at[1::2])[
                cos[1::2] >= GRAZING_COS].max(initial=0.0)
            if err_u <= FACTOR_ANGLE_SHARE * error:
                break
            # as many intervals (a power of 2) as the error's observed order asks for
            grow = convergence_factor(nu, err_u, FACTOR_ANGLE_SHARE * error, last, 2.0, 1.1, 8.0)
            last = (nu, err_u)
            nu = max(2 * nu - 1, 2 ** math.ceil(math.log2((nu - 1) * grow)) + 1)
        err = _cell_errors(cos, at, evaluate(cos, checks), wl, checks)
        # the band: angle cells 0..k-1 (nodes 0..k), up to the last cell that misses
        k = int(np.flatnonzero(err > error).max(initial=-1)) + 1
        error_max = err[k:].max(initial=0.0)
        fine, fine_step = None, FACTOR_STEPS[0]
        if k > 0:
            band_cos = cos[:2 * k + 1]
            worst = err[:k].max()
            for step in FACTOR_STEPS[1:]:
                if worst * (step / FACTOR_STEPS[0]) ** 2 > error and step != FACTOR_STEPS[-1]:
                    continue   # (linear interpolation errs as h²: this step cannot do)
                band_wl, band_checks = _check_points(step, kinks)
                if 2 * (nu * wl.size + (k + 1) * band_wl.size) > FACTOR_MAX_FLOATS:
                    break
                at_b = evaluate(band_cos, band_wl)
                band_err = _cell_errors(band_cos, at_b, evaluate(band_cos, band_checks), band_wl,
                                        band_checks).max(initial=0.0)
                if band_err <= error:
                    fine, fine_step = at_b[0::2], step
                    error_max = max(error_max, band_err)
                    break
            if fine is None:
                self._refuse(f"no wavelength step of {FACTOR_STEPS} within {FACTOR_MAX_FLOATS} "
                             f"floats for a bilinear error within {error:g}")
                return
        self.built = True
        #: angle nodes; the band's nodes (0..band, sharing node ``band`` with the rest)
        self.nu, self.band = nu, k
        #: wavelength steps (nm): of the nodes beyond the band, of the band's
        self.step, self.fine_step = FACTOR_STEPS[0], fine_step
        self.nw = wl.size
        self.nw_fine = 0 if fine is None else fine.shape[1]
        self.report.update(nodes=nu, band=k, step=self.step, fine_step=fine_step,
                           error=float(error_max))
        # (wavelength, angle) rows of k_r and of t: the band's, then the rest's
        parts = [] if fine is None else [fine.transpose(1, 0, 2).reshape(-1, 2)]
        parts.append(nodes[k:].transpose(1, 0, 2).reshape(-1, 2))
        flat = np.concatenate(parts)
        #: the offset of the rows beyond the band
        self.offset = 0 if fine is None else parts[0].shape[0]
        # R_dh, T_hemi on the wavelength nodes beyond the band (every 1 nm), read linearly
        # as the regular spectra they replace
        r_dh, t_hemi = hemispherical(wl)
        import mitsuba as mi

        def floats(values):
            return mi.Float(np.ascontiguousarray(values, np.float32))
        # one buffer per quantity: in llvm_ad_spectral (AMD EPYC) a read of four floats
        # per texel (k_r, t, R_dh, T_hemi) took ~1.4x the time of the twelve reads of one
        # float (k_r, t, and the λ-only R_dh, T_hemi at two nodes)
        self.reflectance, self.transmittance = floats(flat[:, 0]), floats(flat[:, 1])
        self.r_dh, self.t_hemi = floats(r_dh), floats(t_hemi)
        self.report["texels"] = int(flat.size + 2 * wl.size)
        self._opaque_layout()

    def _refuse(self, why: str) -> None:
        self.report["result"] = why

    #: the names of the float32 buffers of a built table (:meth:`arrays`)
    BUFFERS = ("reflectance", "transmittance", "r_dh", "t_hemi")
    #: the names of its layout's numbers (:meth:`layout`)
    LAYOUT = ("nu", "band", "step", "fine_step", "nw", "nw_fine", "offset")

    @property
    def nbytes(self) -> int:
        """The bytes of its buffers (a :class:`~thinfilm_mi.tabulate.base.TableCache` bounds them)."""
        return 4 * sum(dr.width(getattr(self, name)) for name in self.BUFFERS)

    def arrays(self) -> dict:
        """A built table's buffers as float32 numpy arrays, by :data:`BUFFERS` name."""
        return {name: np.array(getattr(self, name), dtype=np.float32) for name in self.BUFFERS}

    def layout(self) -> dict:
        """A built table's layout (angle nodes, band, wavelength steps and counts, the rows'
        offset), by :data:`LAYOUT` name."""
        return {name: getattr(self, name) for name in self.LAYOUT}

    @classmethod
    def restore(cls, layout: dict, arrays: dict, report: dict) -> "FactorTable | None":
        """The built table of ``layout`` and ``arrays`` (as :meth:`layout` and :meth:`arrays`
        give them: read back from the table store) with the build ``report``; ``None`` unless
        they are consistent: every buffer float32 and finite, as long as the layout says,
        the angle nodes and the band within range, the steps of :data:`FACTOR_STEPS`."""
        import mitsuba as mi
        try:
            nu, band, nw, nw_fine, offset = (int(layout[k]) for k in
                                             ("nu", "band", "nw", "nw_fine", "offset"))
            step, fine_step = float(layout["step"]), float(layout["fine_step"])
            values = [np.asarray(arrays[name]) for name in cls.BUFFERS]
        except (KeyError, TypeError, ValueError):
            return None
        rows, lo, hi = offset + nw * (nu - band), *SPECTRAL_RANGE
        if (step != FACTOR_STEPS[0] or fine_step not in FACTOR_STEPS or nu < 2
                or nw != round((hi - lo) / step) + 1 or not 0 <= band <= nu - 1
                or nw_fine != (round((hi - lo) / fine_step) + 1 if band else 0)
                or offset != nw_fine * (band + 1)
                or [v.shape for v in values] != [(rows,), (rows,), (nw,), (nw,)]
                or any(v.dtype != np.float32 or not np.all(np.isfinite(v)) for v in values)):
            return None
        table = cls.__new__(cls)
        table.report, table.built = BuildReport(report), True
        table.nu, table.band, table.step, table.fine_step = nu, band, step, fine_step
        table.nw, table.nw_fine, table.offset = nw, nw_fine, offset
        for name, v in zip(cls.BUFFERS, values):
            setattr(table, name, mi.Float(v))
        table._opaque_layout()
        return table

    def _opaque_layout(self) -> None:
        """The layout as the kernel reads it, opaque: a table built after an edit may have
        other angle nodes, band or wavelength step, and literals would make the render
        kernel's code change (and compile again, ~0.3-0.4 s) with them. Without a band the
        band's reads are those of the rows beyond it (never selected: no angle is in it)."""
        import mitsuba as mi
        nu, k = self.nu, self.band
        fine = (self.fine_step, self.nw_fine) if k else (self.step, self.nw)

        def axis(step, n):   # 1/step, the largest coordinate, the last cell
            return (dr.opaque(mi.Float, 1.0 / step), dr.opaque(mi.Float, n - 1.0),
                    dr.opaque(mi.UInt32, n - 2))
        self._axes = (axis(self.step, self.nw), axis(*fine))
        #: s's scale, the last angle cell, the band's cells, the strides of the band's rows
        #: and of the rest's, the offset of the rest's rows less the band
        self._angle = (dr.opaque(mi.Float, nu - 1.0), dr.opaque(mi.UInt32, nu - 2),
                       dr.opaque(mi.UInt32, k), dr.opaque(mi.UInt32, k + 1),
                       dr.opaque(mi.UInt32, nu - k), dr.opaque(mi.UInt32, self.offset - k))

    @staticmethod
    def _cells(wavelengths, axis):
        import mitsuba as mi
        inv_step, x_max, j_max = axis
        out = []
        for i in range(len(wavelengths)):
            x = (wavelengths[i] - SPECTRAL_RANGE[0]) * inv_step
            x = dr.select(x > 0.0, dr.minimum(x, x_max), 0.0)   # (NaN: 0)
            j = dr.minimum(mi.UInt32(x), j_max)
            out.append((j, x - mi.Float(j)))
        return out

    def cells(self, wavelengths):
        """Per wavelength of ``wavelengths`` (``mi.Spectrum``; clamped to 360-830 nm): its
        cell's first node and the weight of the next, on the wavelength nodes beyond the
        band and (the second of each pair) on the band's (without a band, the same)."""
        return list(zip(*(self._cells(wavelengths, axis) for axis in self._axes)))

    def lookup(self, cos_theta, cells, active=True, reflectance: bool = True):
        """``(k_r, t, R_dh, T_hemi)`` (``mi.UnpolarizedSpectrum``) at ``cos_theta`` and the
        wavelengths of ``cells`` (:meth:`cells`); only ``t`` (the others ``None``) unless
        ``reflectance``. The reads are not masked (every index lies in the table), so
        that Dr.Jit merges identical ones; the layout is read as opaque values (a band of
        no cells where there is none), so that every table compiles to the same kernel."""
        import mitsuba as mi
        scale, i_max, band, band_stride, rest_stride, rest_first = self._angle
        x = dr.sqrt(dr.select(cos_theta > 0.0, dr.minimum(cos_theta, 1.0), 0.0)) * scale
        i = dr.minimum(mi.UInt32(x), i_max)
        u = x - mi.Float(i)
        in_band = i < band
        stride = dr.select(in_band, band_stride, rest_stride)
        first = dr.select(in_band, i, i + rest_first)
        buffers = [self.transmittance] + ([self.reflectance] if reflectance else [])
        out = [[] for _ in range(4)]
        for (j0, w0), (j1, w1) in cells:
            j, w = dr.select(in_band, j1, j0), dr.select(in_band, w1, w0)
            row = j * stride + first
            for c, buffer in enumerate(buffers):
                def at(r, buffer=buffer):
                    return dr.gather(mi.Float, buffer, r)
                out[1 - c].append(dr.lerp(dr.lerp(at(row), at(row + 1), u),
                                          dr.lerp(at(row + stride), at(row + stride + 1), u), w))
            if reflectance:   # R_dh, T_hemi: on the wavelength nodes beyond the band
                for c, buffer in ((2, self.r_dh), (3, self.t_hemi)):
                    out[c].append(dr.lerp(dr.gather(mi.Float, buffer, j0),
                                          dr.gather(mi.Float, buffer, j0 + 1), w0))
        return tuple(mi.UnpolarizedSpectrum(*v) if v else None for v in out)
