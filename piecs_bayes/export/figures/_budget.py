"""Figure of the uncertainty budget by source (see `_base.py` for the conventions)."""

from __future__ import annotations

import math

import numpy as np

from ._base import contour_s, label_features, new_figure, param_unit

_SOURCE_COLOURS = {
    "repeatability": "#4C72B0",
    "ball_radius": "#DD8452",
    "pretravel": "#937860",
    "x_centre": "#55A868",
    "z_offset": "#8C8C8C",
    "scale_x": "#C44E52",
    "scale_z": "#8172B3",
    "rotation": "#DA8BC3",
    "thermal": "#CCB974",
    "probe calibration": "#64B5CD",
}


def budget_figure(tpu, profile):
    """Uncertainty budget (linearised): share of each source in the variance of every
    feature parameter, and the variance of the path offset along the contour by source."""
    budget = tpu.deviation_budget
    sources = [s for s in budget if s != "total"]
    rows, totals = [], []
    for f in profile.features:
        for p in f.param_names:
            rows.append(f"{f.id}.{p}")
    tot = np.asarray(budget["total"], dtype=float)
    n = min(len(rows), len(tot))
    rows = rows[:n]
    for i, r in enumerate(rows):
        fac, unit = param_unit(r)
        totals.append(f"{r}  (u = {math.sqrt(max(tot[i], 0.0)) * fac:.3g} {unit})")
    fig = new_figure((10.5, 0.23 * n + 5.3))
    gs = fig.add_gridspec(2, 1, height_ratios=[0.23 * n + 1.0, 3.4])
    ax = fig.add_subplot(gs[0])
    left = np.zeros(n)
    y = np.arange(n)
    for s in sources:  # a parameter without variance (a feature not measured): no share
        part = np.asarray(budget[s], dtype=float)[:n]
        share = np.divide(part, tot[:n], out=np.zeros(n), where=tot[:n] > 0) * 100
        ax.barh(y, share, left=left, color=_SOURCE_COLOURS.get(s), label=s, height=0.75)
        left += share
    ax.set_yticks(y, totals, fontsize=7.5)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("share of the variance (%)")
    ax.set_title("Feature parameters: variance share by source (linearised, GUM)")
    ax.grid(axis="y", visible=False)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), title="source")
    ax2 = fig.add_subplot(gs[1])
    s_along, starts = contour_s(profile, tpu.grid)
    ob = tpu.offset_budget or {}
    base = np.zeros(len(s_along))
    for s in sources:
        if s not in ob:
            continue
        v = np.asarray(ob[s], dtype=float) * 1e6
        for i in range(len(profile)):
            sel = tpu.grid.feature == i
            ax2.fill_between(
                s_along[sel],
                base[sel],
                base[sel] + v[sel],
                color=_SOURCE_COLOURS.get(s),
                lw=0,
                label=s if i == 0 else None,
            )
        base = base + v
    label_features(ax2, profile, starts)
    ax2.set_xlim(starts[0], starts[-1])
    ax2.set_ylim(bottom=0)
    ax2.set_xlabel("position along the nominal contour from its start (mm)")
    ax2.set_ylabel("variance of the path offset (µm²)")
    ax2.set_title("Adjusted tool path: variance of the normal offset by source", pad=26)
    return fig
