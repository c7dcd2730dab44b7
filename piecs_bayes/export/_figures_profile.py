"""Figures of the part: the profile with the adjusted tool path, and the path's offset
from nominal with its bands (see `_figures.py` for the conventions)."""

from __future__ import annotations

import numpy as np

from ..uncertainty import normal_deviation_at
from ._figures import _contour_s, _figure, _label_features, _nice

__all__ = ["auto_exaggeration", "profile_figure", "offset_figure"]


def auto_exaggeration(res) -> float:
    """A round factor (1, 2 or 5 x 10^k) that draws the largest deviation (fitted
    features, inlier probe points, the adjusted path's band) at about 1/6 of the
    part's radial extent. Outliers are left out: a chip would shrink everything else."""
    prof = res.study.profile
    pts = np.vstack([np.asarray(f.point_at(np.linspace(0, 1, 5))) for f in prof.features])
    extent = max(float(np.ptp(pts[:, 0])), 1e-3)
    big = 0.0
    for f in res.fit:
        keep = np.ones(f.n, dtype=bool)
        keep[np.asarray(f.outliers, dtype=int)] = False
        if keep.any():
            big = max(big, float(np.max(np.abs(np.asarray(f.error_vectors)[keep]))))
    if res.uncertainty is not None:
        b = res.uncertainty["linearised"].bands
        big = max(big, float(np.max(np.abs(b.simultaneous_lower))))
        big = max(big, float(np.max(np.abs(b.simultaneous_upper))))
    if big <= 0:
        return 1.0
    return _nice(extent / 6 / big)


class _Once:
    """Each legend label once: the first artist of a kind gets it, later ones none."""

    def __init__(self):
        self._seen: set[str] = set()

    def __call__(self, key: str, label: str) -> str | None:
        if key in self._seen:
            return None
        self._seen.add(key)
        return label


def _draw_fitted(ax, f, ff, q, n, fac, once):
    """One fitted feature at nominal points `q` (normals `n`), its probe points and
    outliers, deviations exaggerated by `fac`."""
    d = np.asarray(normal_deviation_at(f, ff.values, q))
    p = q + fac * d[:, None] * n
    ax.plot(p[:, 1], p[:, 0], color="C0", lw=1.0, label=once("fit", "fitted feature (exagg.)"))
    meas = np.asarray(ff.nominal_points) + fac * np.asarray(ff.error_vectors)
    keep = np.ones(ff.n, dtype=bool)
    keep[np.asarray(ff.outliers, dtype=int)] = False
    ax.plot(
        meas[keep, 1],
        meas[keep, 0],
        "o",
        ms=3,
        color="C0",
        alpha=0.8,
        label=once("meas", "probe points (exagg.)"),
    )
    if (~keep).any():
        ax.plot(
            meas[~keep, 1],
            meas[~keep, 0],
            "x",
            ms=7,
            mew=1.8,
            color="C3",
            label=once("out", "outliers (exagg.)"),
        )


def _draw_band(ax, unc, i, fac, once):
    """The adjusted tool path along feature `i` with its simultaneous band (exaggerated)."""
    sel = unc.grid.feature == i
    g, nn = unc.grid.points[sel], unc.grid.normals[sel]
    lo = g + fac * unc.bands.simultaneous_lower[sel, None] * nn
    hi = g + fac * unc.bands.simultaneous_upper[sel, None] * nn
    poly = np.vstack([lo, hi[::-1]])
    ax.fill(
        poly[:, 1],
        poly[:, 0],
        color="C2",
        alpha=0.3,
        lw=0,
        label=once("band", "simultaneous 95 % band (exagg.)"),
    )
    c = g + fac * unc.offset[sel, None] * nn
    ax.plot(
        c[:, 1],
        c[:, 0],
        color="C2",
        lw=1.6,
        label=once("path", "adjusted tool path (exagg.)"),
    )


def profile_figure(res, exaggeration: float | None = None):
    """The profile as drawn, the measured points and fitted features, and the
    adjusted tool path with its simultaneous 95 % band, deviations exaggerated."""
    fig = _figure((10.5, 5.0))
    ax = fig.add_subplot()
    prof = res.study.profile
    fac = exaggeration or auto_exaggeration(res)
    t = np.linspace(0.0, 1.0, 80)
    fits = res.fit.fits
    all_x = np.concatenate([np.asarray(f.point_at(t))[:, 0] for f in prof.features])
    label_gap = 0.22 * max(float(np.ptp(all_x)), 1.0)
    unc = None if res.uncertainty is None else res.uncertainty["linearised"]
    once = _Once()
    for i, f in enumerate(prof.features):
        q = np.asarray(f.point_at(t))
        n = np.asarray(f.outward_normal(q))
        ax.plot(q[:, 1], q[:, 0], color="k", lw=1.4, label=once("nominal", "nominal profile"))
        mid = q[len(q) // 2] + n[len(q) // 2] * label_gap
        ax.annotate(
            f.id, (mid[1], mid[0]), fontsize=8, ha="center", va="center", color="0.25", zorder=5
        )
        ff = fits.get(f.id)
        if ff is not None:
            _draw_fitted(ax, f, ff, q, n, fac, once)
        if unc is not None:
            _draw_band(ax, unc, i, fac, once)
    if unc is None and res.path is not None:
        v = prof.vertices + fac * (np.asarray(res.path.vertices) - prof.vertices)
        ax.plot(v[:, 1], v[:, 0], "-", color="C2", lw=1.6, label="adjusted tool path (exagg.)")
    z_all = np.concatenate([np.asarray(f.point_at(t))[:, 1] for f in prof.features])
    ax.plot(
        [z_all.min(), z_all.max()], [0.0, 0.0], color="0.4", lw=0.8, ls="-.", label="spindle axis"
    )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("Z (mm, along the spindle axis)")
    ax.set_ylabel("X (mm, radius)")
    ax.set_title(
        f"Profile, measured part and adjusted tool path (part frame); deviations exaggerated "
        f"× {fac:g}"
    )
    ax.legend(loc="lower left", framealpha=0.9)
    return fig


def offset_figure(res):
    """Normal offset of the adjusted tool path from nominal along the contour, with
    its pointwise and simultaneous 95 % bands (linearised and Monte Carlo)."""
    fig = _figure((10.5, 4.6))
    ax = fig.add_subplot()
    prof = res.study.profile
    lin = res.uncertainty["linearised"]
    mc = res.uncertainty.get("monte_carlo")
    s, starts = _contour_s(prof, lin.grid)
    um = 1e3
    b = lin.bands
    for i, f in enumerate(prof.features):
        sel = lin.grid.feature == i
        lab = i == 0
        ax.fill_between(
            s[sel],
            um * b.simultaneous_lower[sel],
            um * b.simultaneous_upper[sel],
            color="C2",
            alpha=0.2,
            lw=0,
            label="simultaneous 95 % (GUM)" if lab else None,
        )
        ax.fill_between(
            s[sel],
            um * b.pointwise_lower[sel],
            um * b.pointwise_upper[sel],
            color="C2",
            alpha=0.35,
            lw=0,
            label="pointwise 95 % (GUM)" if lab else None,
        )
        ax.plot(
            s[sel], um * lin.offset[sel], color="C2", lw=1.5, label="adjusted path" if lab else None
        )
        ff = res.fit.fits.get(f.id)
        if ff is not None:
            d = np.asarray(normal_deviation_at(f, ff.values, lin.grid.points[sel]))
            ax.plot(
                s[sel],
                um * d,
                color="0.35",
                lw=1.0,
                ls="--",
                label="fitted deviation of the part" if lab else None,
            )
        if mc is not None:
            mb = mc.bands
            ax.plot(
                s[sel],
                um * mb.simultaneous_lower[sel],
                color="C4",
                lw=0.9,
                ls=":",
                label="simultaneous 95 % (Monte Carlo)" if lab else None,
            )
            ax.plot(s[sel], um * mb.simultaneous_upper[sel], color="C4", lw=0.9, ls=":")
    _label_features(ax, prof, starts)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlim(starts[0], starts[-1])
    ax.set_xlabel("position along the nominal contour from its start (mm)")
    ax.set_ylabel("normal offset from nominal (µm, + outward)")
    title = (
        f"Adjusted tool path: offset with 95 % bands (pointwise k = "
        f"{float(np.median(b.crit_pointwise)):.2f}, simultaneous k = {b.crit_simultaneous:.2f})"
    )
    ax.set_title(title, pad=26)
    fig.legend(loc="outside lower center", ncol=5)
    return fig
