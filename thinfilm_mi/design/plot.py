"""The figure of a design: spectra against the targets, colour against angle on
the chromaticity diagram, and the tolerance spread."""
from __future__ import annotations

import numpy as np

__all__ = ["design_figure"]

#: Most (target, angle) curves drawn in the spectra panel.
MAX_CURVES = 12


def _spectra(ax, result):
    tol = result.tolerance
    drawn = 0
    spectral = [v for v in result.values if v.target.wavelengths is not None]     # R, T, A
    for i, v in enumerate(result.values):
        t = v.target
        if t.wavelengths is None:
            continue
        lo, hi = float(t.wavelengths.min()), float(t.wavelengths.max())
        pad = max(20.0, 0.1 * (hi - lo))
        grid = np.arange(max(lo - pad, 1.0), hi + pad + 0.5, 1.0)
        for a, angle in enumerate(t.angles):
            if drawn == MAX_CURVES:
                break
            R, T = result.spectrum(grid, angle, t.side, t.polarization)
            curve = t.quantity.curve(R, T)
            line, = ax.plot(grid, curve, lw=1.1, label=f"targets[{t.index}] {t.quantity.name} {angle:g}°")
            t.kind.draw(ax, t.wavelengths, t.value, t.tolerance, line.get_color())
            c = line.get_color()
            if tol is not None:
                spread = tol.achieved[i][a]                      # (wavelengths, draws)
                lo_, hi_ = np.percentile(spread, [5, 95], axis=-1)
                ax.fill_between(t.wavelengths, lo_, hi_, color=c, alpha=0.2, lw=0)
            drawn += 1
    if not spectral:
        grid = np.arange(380.0, 781.0, 2.0)
        R, T = result.spectrum(grid, 0.0)
        ax.plot(grid, R, label="R 0°")
        ax.plot(grid, T, ls="--", label="T 0°")
    ax.set_xlabel("wavelength (nm)")
    ax.set_ylabel("fraction of incident power")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6)
    title = "spectra (lines) against the targets (bars: tolerance"
    ax.set_title(title + ("; bands: 5-95 % of the tolerance draws)" if tol is not None else ")"), fontsize=8)


def _chromaticity(ax, result):
    import colour

    from thinfilm_mi.colour.report import OBSERVERS
    from thinfilm_mi.design.colourmath import colour_weights

    targets = [v for v in result.values if v.target.space is not None]            # colour targets
    observer = targets[0].target.observer
    locus = colour.XYZ_to_xy(colour.MSDS_CMFS[OBSERVERS[observer]].values)
    ax.plot(np.append(locus[:, 0], locus[0, 0]), np.append(locus[:, 1], locus[0, 1]), color="0.3", lw=1)
    angles = np.arange(0.0, 86.0, 5.0)
    pts, paths = [], {}
    for i, v in enumerate(result.values):
        t = v.target
        if t.space is None:
            continue
        wl, W, white = colour_weights(t.illuminant, t.observer)
        key = (t.of, t.illuminant, t.observer, t.side, t.polarization)
        if key not in paths:       # one path per light, observer and side; its targets share its colour
            path = []
            for angle in angles:
                R, T = result.spectrum(wl, angle, t.side, t.polarization)
                XYZ = t.of.curve(R, T) @ W
                total = XYZ.sum()          # 0 where no light passes (T beyond total reflection): a gap
                path.append(XYZ[:2] / total if total > 0 else np.full(2, np.nan))
            path = np.array(path)
            side = t.side.describe()
            line, = ax.plot(path[:, 0], path[:, 1], lw=1,
                            label=f"{t.of.name} under {t.illuminant}{side and ', ' + side}, 0-85°")
            paths[key] = (path, line.get_color())
            pts.append(path)
        c = paths[key][1]
        wanted, got = t.space.to_xy(t.reference, white), t.space.to_xy(v.achieved, white)
        wanted = np.broadcast_to(wanted, (t.angles.size, 2))
        ax.scatter(wanted[:, 0], wanted[:, 1], marker="x", color=c, s=40, zorder=4)
        ax.scatter(got[:, 0], got[:, 1], facecolors="none", edgecolors=c, s=40, zorder=4)
        for a, angle in enumerate(t.angles):
            ax.annotate(f"{angle:g}°", got[a], fontsize=6, xytext=(4, 2), textcoords="offset points")
        if result.tolerance is not None:
            ach = result.tolerance.achieved[i]                   # (angles, draws, 3|2)
            spread = t.space.to_xy(ach, white)
            ax.scatter(spread[..., 0].ravel(), spread[..., 1].ravel(), s=2, color=c, alpha=0.3, lw=0)
        pts += [wanted, got]
    pts = np.concatenate(pts)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    span = max(float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 1])), 0.05)
    centre = (pts.max(axis=0) + pts.min(axis=0)) / 2
    ax.set_xlim(centre[0] - 0.65 * span, centre[0] + 0.65 * span)
    ax.set_ylim(centre[1] - 0.65 * span, centre[1] + 0.65 * span)
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.grid(alpha=0.2)
    ax.legend(fontsize=6)
    ax.set_title("colour against angle (x: wanted, o: achieved)", fontsize=8)


def _spread(ax, result):
    tol = result.tolerance
    ax.hist(tol.merits, bins=max(10, min(40, tol.spec.draws // 5)), color="C0", alpha=0.7)
    ax.axvline(tol.nominal_merit, color="k", ls="--", label=f"nominal {tol.nominal_merit:.3g}")
    ax.set_xlabel("merit")
    ax.set_ylabel("draws")
    size = f"{100 * tol.spec.sigma:g} %" if tol.spec.relative else f"{tol.spec.sigma:g} nm"
    ax.set_title(f"merit over {tol.spec.draws} draws of {size} thickness errors ({tol.spec.distribution.name})",
                 fontsize=8)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)


def design_figure(result):
    """A matplotlib :class:`~matplotlib.figure.Figure` (not attached to pyplot)."""
    from matplotlib.figure import Figure

    panels = [_spectra]
    if any(v.target.space is not None for v in result.values):
        panels.append(_chromaticity)
    if result.tolerance is not None:
        panels.append(_spread)
    fig = Figure(figsize=(5.2 * len(panels) + 1, 4.6), dpi=110)
    for k, draw in enumerate(panels):
        draw(fig.add_subplot(1, len(panels), k + 1), result)
    fig.suptitle(f"{len(result.design.films)} films, merit {result.merit:.4g}: {result.layers}"[:160], fontsize=8)
    fig.tight_layout()
    return fig
