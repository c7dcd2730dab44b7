"""Figures of a gauge study: the type-1 run chart and the gauge R&R panels
(see `_base.py` for the conventions: deviations in µm)."""

from __future__ import annotations

import numpy as np

from ._base import new_figure

_UM = 1e3


def type1_run_chart_figure(t, *, title: str | None = None):
    """The readings of a type-1 study in their order, as deviations from the reference
    (µm): the reference, reference -/+ K T / 2 (the gauge's share of the tolerance),
    the mean and mean -/+ L s / 2; Cg and Cgk in the title."""
    lim = t.limits
    ref = lim["reference"]
    fig = new_figure((9.0, 3.8))
    ax = fig.add_subplot()
    x = np.arange(1, t.n + 1)
    ax.plot(x, (t.readings - ref) * _UM, "-o", ms=3, lw=0.8, color="C0", label="reading")
    ax.axhline(0.0, color="k", lw=1.0, label="reference")
    half = f"{t.settings.k_share / 2:.0%} T"
    for key, ls in (("lower", "-"), ("upper", "-")):
        ax.axhline(
            (lim[key] - ref) * _UM,
            color="C3",
            lw=1.0,
            ls=ls,
            label=f"reference -/+ {half}" if key == "lower" else None,
        )
    ax.axhline((lim["mean"] - ref) * _UM, color="C2", lw=0.9, label="mean")
    spread = f"{t.settings.l_spread / 2:g} s"
    for key in ("mean_lower", "mean_upper"):
        ax.axhline(
            (lim[key] - ref) * _UM,
            color="C2",
            lw=0.9,
            ls="--",
            label=f"mean -/+ {spread}" if key == "mean_lower" else None,
        )
    ax.set_xlabel("reading (in the order taken)")
    ax.set_ylabel("reading - reference (µm)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7.5)
    head = title or "Type-1 study"
    ax.set_title(
        f"{head}: Cg {t.cg:.2f}, Cgk {t.cgk:.2f}, bias {t.bias * _UM:+.2f} µm, "
        f"s {t.s * _UM:.2f} µm: {t.verdict}"
    )
    return fig


def grr_figure(g, *, title: str | None = None):
    """Three panels of a gauge R&R: the components' %study variation and %tolerance,
    the readings by part and appraiser (deviation from the grand mean, µm), and the
    ranges by part and appraiser against the R chart's UCL."""
    fig = new_figure((11.0, 3.9))
    axs = fig.subplots(1, 3)
    _components_panel(axs[0], g)
    p, o, r = g.data.shape
    centre = float(g.data.mean())
    for j in range(o):
        xs = np.arange(p) + (j - (o - 1) / 2) * 0.18
        vals = (g.data[:, j, :] - centre) * _UM
        axs[1].plot(
            np.repeat(xs, r),
            vals.ravel(),
            "o",
            ms=3,
            color=f"C{j}",
            label=f"{g.appraiser_is} {g.appraisers[j]}",
        )
        axs[2].plot(
            np.arange(p), np.ptp(g.data[:, j, :], axis=1) * _UM, "-o", ms=3, color=f"C{j}", lw=0.8
        )
    axs[2].axhline(g.cross_check.r_ucl * _UM, color="C3", lw=1.0, ls="--", label="UCL (D4 R̄)")
    for ax, ylabel in ((axs[1], "reading - grand mean (µm)"), (axs[2], "range (µm)")):
        ax.set_xticks(np.arange(p), g.parts, rotation=90 if p > 12 else 0, fontsize=7)
        ax.set_xlabel("part")
        ax.set_ylabel(ylabel)
    axs[1].legend(fontsize=7)
    axs[2].legend(fontsize=7)
    tol = "" if g.tolerance is None else f"{g.pct_grr_tolerance:.1f} % of T, "
    fig.suptitle(
        f"{title or 'Gauge R&R'}: GRR {tol}{g.pct_grr_study:.1f} % of study "
        f"variation, ndc {g.ndc}: {g.verdict}"
    )
    return fig


def _components_panel(ax, g) -> None:
    names = [k for k in ("repeatability", "reproducibility", "gauge R&R", "part")]
    y = np.arange(len(names))
    study = [g.components[k].pct_study for k in names]
    ax.barh(y - 0.18, study, height=0.35, color="C0", label="% study variation")
    if g.tolerance is not None:
        tol = [g.components[k].pct_tolerance for k in names]
        ax.barh(y + 0.18, tol, height=0.35, color="C1", label="% tolerance")
    for edge in (g.settings.grr_acceptable, g.settings.grr_conditional):
        ax.axvline(100 * edge, color="C3", lw=0.8, ls=":")
    ax.set_yticks(y, [n.replace("appraiser", g.appraiser_is) for n in names], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("%")
    ax.legend(fontsize=7)
