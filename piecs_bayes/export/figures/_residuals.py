"""Figure of the fit's residuals per feature (see `_base.py` for the conventions)."""

from __future__ import annotations

import math

import numpy as np

from ._base import grid_axes, new_figure


def _along(feature, q):
    """Distance (mm) along the nominal feature from its start of nominal points `q`."""
    q = np.asarray(q, dtype=float)
    if feature.kind == "line":
        p0, p1 = np.array(feature.p0), np.array(feature.p1)
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        return (q - p0) @ d
    c = np.array(feature.center)
    a0 = math.atan2(feature.p0[0] - c[0], feature.p0[1] - c[1])
    a = np.arctan2(q[:, 0] - c[0], q[:, 1] - c[1])
    da = np.angle(np.exp(1j * (a - a0)))
    return np.abs(da) * feature.radius


def residuals_figure(res):
    """Residuals of every fitted feature along it, outliers marked with their file line."""
    fits = list(res.fit)
    nrows, ncols = grid_axes(len(fits), 4)
    fig = new_figure((11.0, 2.35 * nrows + 0.7))
    axs = fig.subplots(nrows, ncols, squeeze=False)
    sigma = res.study.probe.repeatability * 1e3
    for k, ax in enumerate(axs.flat):
        if k >= len(fits):
            ax.set_visible(False)
            continue
        ff = fits[k]
        x = _along(ff.feature, ff.nominal_points)
        r = np.asarray(ff.residuals) * 1e3
        keep = np.ones(ff.n, dtype=bool)
        keep[np.asarray(ff.outliers, dtype=int)] = False
        ax.axhline(0.0, color="k", lw=0.7)
        ax.axhspan(-2 * sigma, 2 * sigma, color="C0", alpha=0.08, lw=0)
        ax.plot(x[keep], r[keep], "o", ms=3.5, color="C0")
        inl = np.abs(r[keep]) if keep.any() else np.zeros(1)
        lim = max(3 * sigma, float(np.max(inl)) * 1.3)
        for j in np.flatnonzero(~keep):
            clipped = abs(r[j]) > 0.9 * lim
            yj = math.copysign(0.85 * lim, r[j]) if clipped else r[j]
            marker = ("^" if r[j] > 0 else "v") if clipped else "x"
            ax.plot(x[j], yj, marker, ms=8, mew=2, color="C3")
            right = x[j] > 0.5 * (float(np.min(x)) + float(np.max(x)))
            ax.annotate(
                f"line {int(ff.lines[j])}\n{r[j]:+.1f} µm" + (" (off scale)" if clipped else ""),
                (x[j], yj),
                xytext=(-7 if right else 7, -4 if r[j] > 0 else 4),
                textcoords="offset points",
                ha="right" if right else "left",
                va="top" if r[j] > 0 else "bottom",
                fontsize=7,
                color="C3",
                zorder=6,
            )
        ax.set_ylim(-lim, lim)
        s_txt = (
            f"s = {ff.residual_sd * 1e3:.2f} µm ({ff.residual_dof} dof)"
            if np.isfinite(ff.residual_sd)
            else "no residual dof"
        )
        ax.set_title(f"{ff.id}: {ff.n} points, {s_txt}", fontsize=8.5)
        ax.set_xlabel("along feature (mm)", fontsize=8)
        ax.set_ylabel("residual (µm)", fontsize=8)
    fig.suptitle(
        f"Residuals per feature ({res.fit.method} fit); shaded: ±2σ of the probe "
        f"(σ = {sigma:.2f} µm); red: outliers (probe-file line; triangles: off scale)"
    )
    return fig
