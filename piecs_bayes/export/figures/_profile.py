"""Figures of the part: the profile with the adjusted tool path, and the path's offset
from nominal with its bands (see `_base.py` for the conventions)."""

from __future__ import annotations

import numpy as np

from ...geometry import drawn_limits, drawn_scale
from ._base import contour_s, label_features, new_figure, nice_step


def auto_exaggeration(res) -> float:
    """A round factor (1, 2 or 5 x 10^k) that draws the largest deviation (fitted
    features, inlier probe points, the adjusted path's band) at about 1/6 of the
    part's radial extent. Outliers are left out: a chip would shrink everything else."""
    prof = res.study.profile
    pts = np.vstack([f.drawn_at(np.linspace(0, 1, 5))[0] for f in prof.features])
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
    return nice_step(extent / 6 / big)


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
    d = -f.drawn_distance(q, ff.values)
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


def _diameter_label(radius: float, _pos) -> str:
    """A radius tick labelled as the diameter (a module-level function: the figure
    pickles, and is drawn in the helper process, `export.raster`)."""
    return f"{2 * radius:g}"


def profile_figure(res, exaggeration: float | None = None):
    """The profile as drawn (the vertical axis labelled with diameters, as on the
    drawing), each feature's tolerance zone, the measured points and fitted features,
    and the adjusted tool path with its simultaneous 95 % band, deviations exaggerated."""
    fig = new_figure((10.5, 4.4))
    ax = fig.add_subplot()
    prof = res.study.profile
    fac = exaggeration or auto_exaggeration(res)
    t = np.linspace(0.0, 1.0, 80)
    fits = res.fit.fits
    curves = [f.drawn_at(t) for f in prof.features]
    all_x = np.concatenate([q[:, 0] for q, _ in curves])
    label_gap = 0.22 * max(float(np.ptp(all_x)), 1.0)
    unc = None if res.uncertainty is None else res.uncertainty["linearised"]
    once = _Once()
    for i, f in enumerate(prof.features):
        q, n = curves[i]
        ax.plot(q[:, 1], q[:, 0], color="k", lw=1.4, label=once("nominal", "nominal profile"))
        lo, hi = (q + fac * v * n for v in f.tolerance)
        zone = np.vstack([lo, hi[::-1]])
        ax.fill(zone[:, 1], zone[:, 0], color="C3", alpha=0.13, lw=0,
                label=once("tol", "tolerance zone (exagg.)"))  # fmt: skip
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
    z_all = np.concatenate([q[:, 1] for q, _ in curves])
    ax.plot(
        [z_all.min(), z_all.max()], [0.0, 0.0], color="0.4", lw=0.8, ls="-.", label="spindle axis"
    )
    from matplotlib.ticker import FuncFormatter

    ax.set_aspect("equal", adjustable="datalim")
    ax.yaxis.set_major_formatter(FuncFormatter(_diameter_label))
    ax.set_xlabel("Z (mm, along the spindle axis)")
    ax.set_ylabel("Ø (mm; half section drawn true to scale)")
    ax.set_title(
        f"Profile, measured part and adjusted tool path (part frame); deviations exaggerated "
        f"× {fac:g}"
    )
    ax.legend(loc="lower left", framealpha=0.9)
    return fig


_SIGN = {"diameter": "Ø", "radius": "R", "length": "Z", "normal": "normal"}


def _part_panel(ax, res, lin, s, k):
    """The measured part along the contour, as drawn: fitted deviation, the decision's
    point with ± U, and the tolerance limits."""
    prof = res.study.profile
    dec = {} if res.decisions is None else {d.feature: d for d in res.decisions.decisions}
    est = {} if res.decisions is None else dict(zip(dec, res.decisions.estimates, strict=True))
    lengths = np.array([f.length for f in prof.features])
    starts = np.concatenate([[0.0], np.cumsum(lengths)])
    marked = False
    for i, f in enumerate(prof.features):
        sel = lin.grid.feature == i
        lo, hi = (1e3 * v for v in drawn_limits(f))
        lab = i == 0
        ax.plot([starts[i], starts[i + 1]], [lo, lo], color="C3", lw=1.2,
                label="tolerance limits" if lab else None)  # fmt: skip
        ax.plot([starts[i], starts[i + 1]], [hi, hi], color="C3", lw=1.2)
        ff = res.fit.fits.get(f.id)
        if ff is not None:
            d = -f.drawn_distance(lin.grid.points[sel], ff.values)
            ax.plot(s[sel], 1e3 * k[i] * d, color="C0", lw=1.3,
                    label="fitted deviation of the part" if lab else None)  # fmt: skip
        if f.id in dec and est.get(f.id) is not None:
            dd, c = dec[f.id], est[f.id]
            ax.errorbar(
                starts[i] + c.t * lengths[i], 1e3 * dd.drawn_estimate,
                yerr=1e3 * dd.drawn_expanded, fmt="o", ms=4, color="k", capsize=3, lw=1.0,
                label=None if marked else "decision point, ± U (95 %)",
            )  # fmt: skip
            marked = True
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_ylabel("part deviation as drawn (µm)")
    ax.set_title("The measured part: deviation from nominal as drawn, with the tolerance", pad=24)


def _path_panel(ax, res, lin, s, k):
    """The adjusted tool path's change from nominal along the contour, as drawn."""
    mc = res.uncertainty.get("monte_carlo")
    b = lin.bands
    for i, _ in enumerate(res.study.profile.features):
        sel = lin.grid.feature == i
        lab, ki = i == 0, 1e3 * k[i]
        pair = sorted((ki * b.simultaneous_lower[sel], ki * b.simultaneous_upper[sel]),
                      key=lambda v: float(np.mean(v)))  # fmt: skip
        ax.fill_between(s[sel], *pair, color="C2", alpha=0.2, lw=0,
                        label="simultaneous 95 % (linearised)" if lab else None)  # fmt: skip
        pair = sorted((ki * b.pointwise_lower[sel], ki * b.pointwise_upper[sel]),
                      key=lambda v: float(np.mean(v)))  # fmt: skip
        ax.fill_between(s[sel], *pair, color="C2", alpha=0.35, lw=0,
                        label="pointwise 95 % (linearised)" if lab else None)  # fmt: skip
        ax.plot(s[sel], ki * lin.offset[sel], color="C2", lw=1.5,
                label="adjusted tool path" if lab else None)  # fmt: skip
        if mc is not None:
            mb = mc.bands
            ax.plot(s[sel], ki * mb.simultaneous_lower[sel], color="C4", lw=0.9, ls=":",
                    label="simultaneous 95 % (Monte Carlo)" if lab else None)  # fmt: skip
            ax.plot(s[sel], ki * mb.simultaneous_upper[sel], color="C4", lw=0.9, ls=":")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_ylabel("tool-path change as drawn (µm)")
    ax.set_xlabel("position along the nominal contour from its start (mm)")
    ax.set_title(
        f"The adjusted tool path with 95 % bands (pointwise k = "
        f"{float(np.median(b.crit_pointwise)):.2f}, simultaneous k = {b.crit_simultaneous:.2f})"
    )


def offset_figure(res):
    """Along the nominal contour, as drawn (on the diameter for diameters, on Z for
    faces, along the normal for tapers and arcs): the measured part's fitted deviation
    with the tolerance limits and the decision points (± U), and the adjusted tool
    path's change with its pointwise and simultaneous 95 % bands."""
    fig = new_figure((10.5, 6.4))
    top, bottom = fig.subplots(2, 1, sharex=True)
    prof = res.study.profile
    lin = res.uncertainty["linearised"]
    s, starts = contour_s(prof, lin.grid)
    k = [drawn_scale(f) for f in prof.features]
    _part_panel(top, res, lin, s, k)
    _path_panel(bottom, res, lin, s, k)
    names = [f"{f.id} ({_SIGN.get(f.tolerance_on, f.tolerance_on)})" for f in prof.features]
    for ax in (top, bottom):
        label_features(ax, prof, starts, names, labels=ax is top)
        ax.set_xlim(starts[0], starts[-1])
        ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=7.5, framealpha=0.9)
    return fig
