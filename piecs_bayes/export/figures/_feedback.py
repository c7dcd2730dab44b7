"""Figures of feedback over a production run (see `_base.py` for the conventions):
the tracked deviation per feature with its predictive band, steps, odd parts and each
policy's realised trace, and the policies' RMS deviation per feature. Every length as
drawn (µm on the diameter for a diameter, on Z for a face, along the normal for tapers
and arcs; the axis says which)."""

from __future__ import annotations

import io

import numpy as np

from ._base import RC, grid_axes, new_figure

#: the drawn coordinate's symbol in axis labels
_SIGN = {"diameter": "Ø", "radius": "R", "length": "Z"}

#: one colour per policy (the same in every panel)
_COLOURS = {"none": "0.55", "full": "C1", "fixed_gain": "C5", "mean_value": "C8",
            "ewma": "C2", "dewma": "C9", "bayes": "C3"}  # fmt: skip


def _ylabel(coordinate: str) -> str:
    sign = _SIGN.get(coordinate)
    return "normal deviation (µm)" if sign is None else f"deviation of {sign} (µm)"


def _panel(ax, f, policies, traces: bool):
    tr = f.track
    k = f.scale * 1e3  # drawn µm per mm of δ
    x = np.arange(1, len(f.parts) + 1)
    lo, hi = np.sort(np.vstack([tr.pred_lo * k, tr.pred_hi * k]), axis=0)
    ok = np.isfinite(lo) & np.isfinite(hi)
    ax.fill_between(x[ok], lo[ok], hi[ok], color="C0", alpha=0.18, lw=0,
                    label="95 % one-step-ahead predictive")  # fmt: skip
    ax.plot(x, tr.smooth_level * k, color="C0", lw=1.0, label="smoothed level")
    ax.errorbar(x, f.values * k, yerr=_Z * f.u * abs(k), fmt="o", ms=3, color="k", lw=0.7,
                label="measured (95 % u_fit)")  # fmt: skip
    odd = np.flatnonzero(tr.p_outlier > 0.5)
    if odd.size:
        ax.plot(x[odd], f.values[odd] * k, "o", ms=8, mfc="none", mec="C3", mew=1.5,
                label="odd part (p > 0.5)")  # fmt: skip
    if traces:
        for name in policies:
            if name in f.policies and name != "none":
                real = np.asarray(f.policies[name].realised) * k
                ax.plot(x, real, "-", lw=0.8, color=_COLOURS.get(name), alpha=0.85,
                        label=f"realised: {name}")  # fmt: skip
    for s in f.steps:
        xs = s["index"] + 0.5
        ax.axvline(xs, color="C4", lw=1.2, ls="-" if s["declared"] else ":")
        what = "tool change before" if s["declared"] else "step before"
        tail = "" if s["declared"] else f" (p {s['p_step']:.2f})"
        ax.annotate(
            f"{what} {s['part']}{tail}",
            (xs, 0.97), xycoords=("data", "axes fraction"), fontsize=7, color="C4",
            ha="left", va="top",
        )  # fmt: skip
    tlo, thi = sorted(v * k for v in f.tolerance)
    ax.axhline(tlo, color="C3", lw=1.0)
    ax.axhline(thi, color="C3", lw=1.0)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_title(f"{f.feature}: coverage {f.coverage:.0%}, "
                 f"next correction {f.next_part['correction'] * k:+.2f} µm")  # fmt: skip
    ax.set_ylabel(_ylabel(f.coordinate), fontsize=8)
    ax.set_xlabel("part (production order)", fontsize=8)


_Z = 1.959963984540054


def feedback_track_figure(res, features=None, *, traces: bool = True):
    """Per feature: the measured deviation against part number with the 95 %
    one-step-ahead predictive band, the smoothed level, declared tool changes (solid)
    and steps found (dotted), odd parts (red circles), each policy's realised trace
    (with `traces`) and the tolerance limits (red), as drawn."""
    feats = [res.features[f] for f in (features or res.features)]
    nrows, ncols = grid_axes(len(feats), 1 if len(feats) == 1 else 2)
    fig = new_figure((11.0 if ncols == 2 else 8.0, 2.9 * nrows + 1.0))
    axs = fig.subplots(nrows, ncols, squeeze=False)
    for j, ax in enumerate(axs.flat):
        if j >= len(feats):
            ax.set_visible(False)
            continue
        _panel(ax, feats[j], res.policies, traces)
    handles, labels = axs.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=4, fontsize=7.5)
    fig.suptitle(
        f"Feedback over {len(res.parts)} parts: deviation as drawn, predictive band, steps "
        f"and each policy's realised deviation (replayed on {res.replayed_on} values)"
    )
    return fig


def feedback_policy_figure(res):
    """RMS realised deviation per policy and feature, as a share of the tolerance
    half-width (anchors at their best setting on this run)."""
    feats = list(res.features.values())
    names = list(res.policies)
    fig = new_figure((10.5, 0.55 * len(feats) + 2.0))
    ax = fig.add_subplot()
    y = np.arange(len(feats))
    h = 0.8 / max(1, len(names))
    for j, name in enumerate(names):
        vals = []
        for f in feats:
            half = 0.5 * (f.tolerance[1] - f.tolerance[0])
            vals.append(f.policies[name].rmsd_mm / half if name in f.policies else np.nan)
        ax.barh(y - 0.4 + (j + 0.5) * h, vals, height=h, color=_COLOURS.get(name), label=name)
    ax.set_yticks(y, [f.feature for f in feats])
    ax.invert_yaxis()
    ax.set_xlabel("RMS realised deviation / tolerance half-width")
    ax.set_title("Policies replayed over the run (anchors tuned on the same data)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def feedback_figures(res) -> dict[str, bytes]:
    """The figures as PNG by name: `feedback_tracks` (every feature) and
    `feedback_policies`."""
    from matplotlib import rc_context

    with rc_context(RC):
        return {
            "feedback_tracks": _png(feedback_track_figure(res)),
            "feedback_policies": _png(feedback_policy_figure(res)),
        }
