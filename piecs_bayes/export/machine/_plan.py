"""The files of a probe plan: `plan.json`, the gauging program and a figure.

`plan.json` (format in docs/formats.md): the study and its SHA-256, the units of
the numbers (the study's; X always a radius, as LinuxCNC's probe files write it),
the program's X mode, the controller, the frame (the finish program's work
coordinates: the study's part frame), the settings, the per-feature predictions
(designed and uniform), one entry per point in program order and, when the plan
leaves features out, `unreachable` (each not measured: why, and the largest clearance,
end clearance and spacing that reach it).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from ...gcode import GAUGING_NAMES, GaugingOptions, gauging_program
from ...io import write_text_atomic

_MM_PER = {"mm": 1.0, "in": 25.4}


def _num(v, scale=1.0):
    return None if v is None or not math.isfinite(v) else round(float(v) / scale, 9)


def _sha256(path) -> str:
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _header(plan) -> list[str]:
    from ... import __version__

    study = plan.study
    sha = _sha256(study.path)
    return [
        f"piecs_bayes {__version__} gauging program",
        f"study {study.path.name} sha256 {sha}",
        f"plan: {plan.n_points} points on {len(plan.features)} features, "
        f"controller {plan.settings.controller}",
    ] + [
        f"not measured: {u.feature}, the probe cannot reach it, see plan.json"
        for u in plan.unreachable
    ]


def plan_program(plan) -> str:
    """The gauging program text of the plan, for its controller."""
    study, s = plan.study, plan.settings
    options = GaugingOptions(
        controller=s.controller, units=study.units,
        x_mode=s.x_mode, tool=study.probe.tool, feed_mm_min=study.probe.feed,
        probe_file=s.probe_file, log_file=s.log_file,
        probe_on=s.probe_on,
        probe_off=s.probe_off, program_number=s.program_number,
    )  # fmt: skip
    return gauging_program(plan.home, plan.path, plan.points, options=options, header=_header(plan))


def plan_json(plan) -> str:
    study = plan.study
    k = _MM_PER[study.units]

    def pt(p):
        return [_num(p[0], k), _num(p[1], k)]

    def pred(p):
        return {
            "n": p.n, "at_t": _num(p.t), "u_fit": _num(p.u_fit, k),
            "u_systematic": _num(p.u_systematic, k), "u": _num(p.u, k), "dof": _num(p.dof),
            "U": _num(p.expanded, k), "ratio": _num(p.ratio),
        }  # fmt: skip

    body = {
        "format": "piecs_bayes probe plan 1",
        "study": str(study.path.name),
        "study_sha256": _sha256(study.path),
        "units": study.units,
        "x": "radius",
        "program_x_mode": plan.settings.x_mode,
        "controller": plan.settings.controller,
        "frame": "part (the finish program's work coordinates)",
        "probe": {
            "tool": study.probe.tool,
            "feed_per_min": _num(study.probe.feed, k),
            "ball_radius": _num(study.probe.ball_radius, k),
            "repeatability": _num(study.probe.repeatability, k),
        },  # fmt: skip
        "settings": {
            key: (
                _num(v, k)
                if key
                in ("clearance", "end_clearance", "overtravel", "spacing", "stock", "rapid_feed")
                else v
            )
            for key, v in sorted(plan.settings.as_dict().items())
        },  # fmt: skip
        "sigma_dof": _num(plan.dof),
        "predicted_time_s": _num(plan.time_s),
        "travel": _num(plan.travel_mm, k),
        "home": pt(plan.home),
        "features": [
            {
                "feature": f.feature,
                "window": [_num(f.window[0]), _num(f.window[1])],
                "fractions": [_num(t) for t in f.fractions],
                "designed": pred(f.designed),
                "uniform": pred(f.uniform),
            }
            for f in plan.features
        ],  # fmt: skip
        "points": [
            {
                "index": p.index,
                "feature": p.feature,
                "t": _num(p.t),
                "contact": pt(p.contact),
                "centre": pt(p.centre),
                "approach": [_num(p.approach[0]), _num(p.approach[1])],
                "start": pt(p.start),
                "target": pt(p.target),
                "inside": p.inside,
            }
            for p in plan.points
        ],  # fmt: skip
    }
    if plan.unreachable:  # the features left out: not measured (absent: none)
        body["unreachable"] = [
            {
                "feature": u.feature,
                "reason": u.reason,
                "clearance": _num(u.clearance, k),
                "end_clearance": _num(u.end_clearance, k),
                "spacing": _num(u.spacing, k),
            }
            for u in plan.unreachable
        ]
    return json.dumps(body, indent=2) + "\n"


def plan_figure(plan):
    """The profile with the planned contact points, approach vectors and the safe path."""
    import matplotlib.pyplot as plt
    import numpy as np

    from ...geometry import feature_polyline

    fig, ax = plt.subplots(figsize=(9, 4.5), layout="constrained")
    left_out = {u.feature for u in plan.unreachable}
    for f in plan.study.profile.features:
        poly = feature_polyline(f)
        ax.plot(poly[:, 1], poly[:, 0], "k-", lw=1.5)
        if f.id in left_out:
            ax.plot(poly[:, 1], poly[:, 0], "--", color="C3", lw=3, label=f"{f.id}: not measured")
    path = [plan.home] + [p for _, p in plan.path]
    zx = np.array([(p[1], p[0]) for p in path])
    ax.plot(zx[:, 0], zx[:, 1], "-", color="0.7", lw=0.8, label="moves")
    c = np.array([p.contact for p in plan.points])
    a = np.array([p.approach for p in plan.points])
    inside = np.array([p.inside for p in plan.points])
    if len(c):
        ax.quiver(c[:, 1] - 2 * a[:, 1], c[:, 0] - 2 * a[:, 0], 2 * a[:, 1], 2 * a[:, 0],
                  angles="xy", scale_units="xy", scale=1, width=0.003, color="C0")  # fmt: skip
        ax.plot(c[~inside, 1], c[~inside, 0], "o", color="C0", ms=4, label="designed")
        ax.plot(c[inside, 1], c[inside, 0], "s", color="C1", ms=4, label="spread inside")
    ax.set_xlabel("z (mm)")
    ax.set_ylabel("x (radius, mm)")
    ax.set_aspect("equal")
    ax.set_title(f"Probe plan: {plan.n_points} points, {plan.time_s:.0f} s predicted")
    ax.legend(loc="best", fontsize=8)
    return fig


def write_plan(plan, out, *, protect=(), figure: bool = True) -> list[Path]:
    """Write `plan.json`, the gauging program and `plan.png` into `out` (atomically;
    never over a file in `protect`)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    protect = [plan.study.path, *protect]
    written = [
        write_text_atomic(out / "plan.json", plan_json(plan), protect=protect),
        write_text_atomic(
            out / GAUGING_NAMES[plan.settings.controller], plan_program(plan), protect=protect
        ),
    ]
    if figure:
        import io

        import matplotlib.pyplot as plt

        from ...io import write_bytes_atomic

        fig = plan_figure(plan)
        png = io.BytesIO()
        fig.savefig(png, format="png", dpi=120)
        plt.close(fig)
        written.append(write_bytes_atomic(out / "plan.png", png.getvalue(), protect=protect))
    return written
