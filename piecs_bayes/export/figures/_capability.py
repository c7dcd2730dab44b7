"""Figures of a capability study: individuals charts and capability indices
(see `_base.py` for the conventions)."""

from __future__ import annotations

import math

import numpy as np

from ._base import grid_axes, new_figure

#: the drawn coordinate's symbol in axis labels
_SIGN = {"diameter": "Ø", "radius": "R", "length": "Z"}


def _ylabel(coordinate: str) -> str:
    """The axis label: `deviation of Ø (µm)`, ... `normal deviation (µm)` (arcs, tapers)."""
    sign = _SIGN.get(coordinate)
    return "normal deviation (µm)" if sign is None else f"deviation of {sign} (µm)"


def capability_chart_figure(cap):
    """Individuals charts of every feature's characteristic over the run, with
    the control limits, the tolerance, flagged parts and the most likely step; every
    value as drawn, as the study holds it (on the diameter for a diameter, on Z for a
    face, along the normal for tapers and arcs; the axis says which)."""
    feats = list(cap.features.values())
    nrows, ncols = grid_axes(len(feats), 2)
    fig = new_figure((11.0, 2.3 * nrows + 0.8))
    axs = fig.subplots(nrows, ncols, squeeze=False)
    for k, ax in enumerate(axs.flat):
        if k >= len(feats):
            ax.set_visible(False)
            continue
        fc = feats[k]
        s = fc.stability
        x = np.arange(1, len(fc.values) + 1)
        g = 1e3
        v = np.asarray(fc.values) * g
        ax.plot(x, v, "-o", ms=3, lw=0.8, color="C0")
        flagged = sorted(set(s.beyond_limits) | set(s.run_points) | set(s.trend_points))
        if flagged:
            ax.plot(x[flagged], v[flagged], "o", ms=5, mfc="none", mec="C3", mew=1.4)
        ax.axhline(s.center * g, color="k", lw=0.8)
        ax.axhline(s.ucl * g, color="C1", lw=0.9, ls="--")
        ax.axhline(s.lcl * g, color="C1", lw=0.9, ls="--")
        lo, hi = fc.tolerance
        ax.axhline(lo * g, color="C3", lw=1.0)
        ax.axhline(hi * g, color="C3", lw=1.0)
        if fc.step_part:
            ax.axvline(s.step_index + 0.5, color="C4", lw=1.2, ls=":")
            ax.annotate(
                f"step before {fc.step_part}",
                (s.step_index + 0.5, 0.95),
                xycoords=("data", "axes fraction"),
                fontsize=7.5,
                color="C4",
                ha="left",
                va="top",
            )
        c = fc.capability
        ax.set_title(f"{fc.feature} ({fc.characteristic}): Cpk {c.cpk:.2f}, Ppk {c.ppk:.2f}")
        ax.set_ylabel(_ylabel(fc.coordinate), fontsize=8)
        ax.set_xlabel("part (production order)", fontsize=8)
    fig.suptitle(
        "Individuals charts: deviation per part as drawn (Ø on the diameter, Z on the axis)\n"
        "dashed: 3σ control limits (moving range); red: tolerance; circles: flagged parts"
    )
    return fig


def capability_index_figure(cap):
    """Cpk with its confidence interval, Ppk, the Bayesian Cpk with its credible
    interval and the Cpk predicted after compensation, per feature."""
    feats = list(cap.features.values())
    fig = new_figure((10.5, 0.5 * len(feats) + 1.8))
    ax = fig.add_subplot()
    y = np.arange(len(feats))
    off = {"cpk": -0.27, "ppk": -0.09, "bayes": 0.09, "after": 0.27}
    thr = 1.33

    def bar(k, val, iv, dy, colour, marker, label):
        lo, hi = iv
        if math.isfinite(lo) and math.isfinite(hi):
            ax.plot([lo, hi], [k + dy] * 2, color=colour, lw=1.4)
        ax.plot(val, k + dy, marker, color=colour, ms=5, label=label if k == 0 else None)

    for k, fc in enumerate(feats):
        c, b, p = fc.capability, fc.capability.bayes, fc.predicted
        bar(k, c.cpk, c.cpk_ci, off["cpk"], "C0", "o", f"Cpk, {cap.confidence:.0%} CI")
        bar(k, c.ppk, c.ppk_ci, off["ppk"], "C1", "s", f"Ppk, {cap.confidence:.0%} CI")
        if b is not None:
            thr = b.threshold
            bar(k, b.cpk, b.cpk_interval, off["bayes"], "C2", "D", "Bayes Cpk, credible interval")
        bar(k, p.cpk, p.cpk_ci, off["after"], "C4", "^", "Cpk predicted after compensation")
    ax.axvline(thr, color="k", ls="--", lw=1)
    ax.axvline(1.0, color="0.5", ls=":", lw=1)
    ax.set_yticks(y, [fc.feature for fc in feats])
    ax.invert_yaxis()
    ax.set_xlabel("capability index (dimensionless)")
    ax.set_title(f"Capability indices per feature; dashed: {thr:g}, dotted: 1")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig
