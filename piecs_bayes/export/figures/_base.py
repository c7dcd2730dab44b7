"""Figures of a job's results (matplotlib), for reports and notebooks.

Every function takes a [`JobResults`][piecs_bayes.jobs.JobResults] (or the
part of it it draws) and returns a `matplotlib.figure.Figure` made without
`pyplot`: nothing here selects a backend or keeps figures alive, so the
functions are safe in scripts, servers and notebooks (a notebook displays a
returned figure). matplotlib is imported inside the functions.

Conventions: Z (along the spindle axis) is horizontal and X (radius) vertical,
as on the drawing; lengths of the part in mm, deviations in µm, rotations in
µrad, axis scale errors in ppm. Deviations on the profile drawing are
exaggerated by a factor stated in its title.

This module holds what the figures share (rcParams, units, layout helpers); the
figures themselves are in `_figures_*.py` by topic.
"""

from __future__ import annotations

import math

import numpy as np

#: rcParams the report is drawn with (readable at A4 landscape and on screen)
RC = {
    "font.size": 9,
    "axes.titlesize": 9.5,
    "axes.labelsize": 9,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 8,
    "figure.titlesize": 12,
    "figure.dpi": 100,
    "savefig.dpi": 110,
    "axes.grid": True,
    # titles at the top of their axes: no figure puts ticks or labels above an axes,
    # and matplotlib's automatic title position measured every x axis at each draw
    "axes.titley": 1.0,
    "grid.alpha": 0.3,
    "pdf.fonttype": 42,  # TrueType: the PDF's text can be searched and extracted
    "svg.fonttype": "none",
}


def param_unit(name: str) -> tuple[float, str]:
    """Display factor and unit of a parameter (`"dia_24.offset"`, `"scale_x"`, ...)."""
    base = name.rsplit(".", 1)[-1]
    if base == "rotation":
        return 1e6, "µrad"
    if base in ("scale_x", "scale_z", "thermal"):
        return 1e6, "ppm"
    return 1e3, "µm"


def new_figure(figsize, **kw):
    """A Figure with constrained layout (`layout=None`: margins set by the caller)."""
    from matplotlib.figure import Figure

    kw.setdefault("layout", "constrained")
    return Figure(figsize=figsize, **kw)


def grid_axes(n, ncols):
    return max(1, math.ceil(n / ncols)), min(n, ncols)


def nice_step(x: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above `x` (at least 1)."""
    if not math.isfinite(x) or x <= 1:
        return 1.0
    k = math.floor(math.log10(x))
    for m in (5, 2, 1):
        if m * 10**k <= x:
            return float(m * 10**k)
    return float(10**k)


def contour_s(profile, grid):
    """Arc length (mm) along the nominal contour of each grid point, and feature starts."""
    lengths = np.array([f.length for f in profile.features])
    starts = np.concatenate([[0.0], np.cumsum(lengths)])
    return starts[grid.feature] + grid.t * lengths[grid.feature], starts


def label_features(ax, profile, starts, names=None, *, labels=True):
    """Feature boundaries as dotted lines and the ids (or `names`) above the axes
    (staggered where neighbours are short; none with `labels=False`)."""
    from matplotlib.transforms import blended_transform_factory

    tr = blended_transform_factory(ax.transData, ax.transAxes)
    total = max(starts[-1] - starts[0], 1e-9)
    raised = False
    for k, f in enumerate(profile.features):
        ax.axvline(starts[k], color="0.5", lw=0.6, ls=":")
        short = (starts[k + 1] - starts[k]) / total < 0.1
        raised = short and not raised
        if not labels:
            continue
        ax.text(
            (starts[k] + starts[k + 1]) / 2,
            1.055 if raised else 1.01,
            f.id if names is None else names[k],
            transform=tr,
            ha="center",
            va="bottom",
            fontsize=7.5,
            clip_on=False,
        )
    ax.axvline(starts[-1], color="0.5", lw=0.6, ls=":")
