"""Figure of a probe calibration: r(theta) around the approach directions."""

from __future__ import annotations

import numpy as np

from ._base import new_figure


def probe_calibration_figure(cal):
    """The calibrated effective radius against the approach angle, as a polar plot of
    r(theta) - r0 (um) about a base circle, with its 95 % band (k = 2) and the angles
    of a turned profile's approaches marked (faces along Z, diameters along X)."""
    theta = np.linspace(-np.pi, np.pi, 361)
    dev = 1e3 * (cal.radius(theta) - cal.r0)
    u = 1e3 * cal.radius_u(theta)
    span = max(float(np.max(np.abs(dev) + 2 * u)), 0.5)
    base = 2.0 * span  # the radius of r0 on the plot
    fig = new_figure((5.2, 4.6))
    ax = fig.add_subplot(projection="polar")
    ax.fill_between(theta, base + dev - 2 * u, base + dev + 2 * u, color="#64B5CD", alpha=0.35,
                    lw=0, label="95 % band (k = 2)")  # fmt: skip
    ax.plot(theta, base + dev, color="#1f4e79", lw=1.6, label="r(θ) − r0")
    ax.plot(theta, np.full_like(theta, base), color="0.4", lw=0.8, ls="--", label="r0")
    ax.set_ylim(0.0, base + span * 1.05)
    ticks = [base - span, base, base + span]
    ax.set_yticks(ticks, [f"{t - base:+.1f} µm" for t in ticks], fontsize=7)
    ax.set_xticks(np.deg2rad([0, 90, 180, 270]),
                  ["+X (0°)", "+Z (90°)", "−X (180°)\ndiameters", "−Z (270°)\nfaces"],
                  fontsize=8)  # fmt: skip
    ax.set_title(
        f"effective radius by approach angle: r0 = {cal.r0:.4f} mm, "
        f"probing error {1e3 * cal.probing_error:.1f} µm"
        if np.isfinite(cal.probing_error) else f"effective radius: r0 = {cal.r0:.4f} mm",
        fontsize=9,
    )  # fmt: skip
    ax.legend(loc="lower left", bbox_to_anchor=(-0.15, -0.15), fontsize=7, frameon=False)
    return fig
