"""Report sections that frame the others: the decisions per feature (one row per
feature as drawn, the reasons behind each verdict) and the inputs (files, versions,
settings, how to reproduce the run). `summary_rows` feeds the verdict page too."""

from __future__ import annotations

import math

import numpy as np

from ...fit import coverage_factor
from ...geometry import drawn_scale
from ..tables import risk_text
from .model import Bullets, Fig, Para, Pre, Table, Tables, css_class, num

#: coverage probability of a k = 2 interval under the normal (JCGM 100 G.6)
K2_COVERAGE = 0.9544997361036416

#: the coordinate of a drawn tolerance, as a table shows it
ON_SIGN = {"diameter": "Ø", "radius": "R", "length": "Z", "normal": "normal"}


def _nominal_text(f) -> str:
    """The feature as on the drawing, compactly (X as diameter Ø, mm)."""
    (x0, z0), (x1, z1) = f.p0, f.p1
    if f.kind == "arc":
        cx, cz = f.center
        return f"R{f.radius:.3f} {'ccw' if f.ccw else 'cw'}, centre Ø{2 * cx:.3f} Z{cz:.3f}"
    if abs(x1 - x0) < 1e-9:
        return f"Ø{2 * x0:.3f}, Z{z0:.3f} to {z1:.3f}"
    if abs(z1 - z0) < 1e-9:
        return f"face Z{z0:.3f}, Ø{2 * x0:.3f} to {2 * x1:.3f}"
    return f"taper Ø{2 * x0:.3f} Z{z0:.3f} to Ø{2 * x1:.3f} Z{z1:.3f}"


def tolerance_text(lo_um: float, hi_um: float, coordinate: str) -> str:
    """A drawn tolerance as a drawing writes it: `"Ø ±20"`, `"Z -10/+30"` (µm)."""
    on = ON_SIGN.get(coordinate, coordinate)
    if math.isclose(-lo_um, hi_um, rel_tol=1e-9, abs_tol=1e-9):
        return f"{on} ±{hi_um:g}"
    return f"{on} {lo_um:+g}/{hi_um:+g}"


def _empty_row(f, fit, gain: float) -> dict:
    k = drawn_scale(f)
    lo, hi = sorted((k * f.tolerance[0], k * f.tolerance[1]))
    return {
        "feature": f.id,
        "nominal": _nominal_text(f),
        "coordinate": f.tolerance_on,
        "scale": k,
        "tol_lower_um": lo * 1e3,
        "tol_upper_um": hi * 1e3,
        "at": "",
        "deviation_um": math.nan,
        "u_um": math.nan,
        "U_um": math.nan,
        "dof": math.nan,
        "bayes_um": math.nan,
        "bayes_U_um": math.nan,
        "verdict": "not measured" if f.id not in fit.fits else "–",
        "gain": gain,
        "correction_um": math.nan,
        "null_band_um": math.nan,
        "conformance": "",
        "p_exceed": math.nan,
        "risk": "",
    }


def summary_rows(res) -> list[dict]:
    """One row per profile feature, every length as drawn (`coordinate`: on the
    diameter for a diameter, on Z for a face, along the normal for tapers and arcs;
    `scale` times the normal deviation): nominal, tolerance, deviation with its
    expanded uncertainty U = k u (robust fit, and Bayesian when sampled), null band,
    verdict, applied gain and correction. Without decisions the deviations are the
    job's `characteristics`. Lengths in µm except `nominal`."""
    study, fit = res.study, res.fit
    dec = res.decisions
    by_dec = {}
    if dec is not None:
        for d, c in zip(dec.decisions, dec.estimates, strict=True):
            by_dec[d.feature] = (d, c)
    chars = (res.characteristics or {}) if dec is None else {}
    rows = []
    for f in study.profile.features:
        row = _empty_row(f, fit, float(res.gains.get(f.id, 0.0)))
        k, a = row["scale"] * 1e3, abs(row["scale"]) * 1e3
        if f.id in by_dec:
            d, c = by_dec[f.id]
            row.update(
                at=c.at if c is not None else "",
                deviation_um=d.estimate * k,
                u_um=d.u_estimate * a,
                U_um=d.conformance_before.expanded * a,
                dof=d.dof,
                verdict=d.verdict + (f" (+{d.more_points} points)" if d.more_points else ""),
                gain=d.gain,
                correction_um=d.correction * k,
                null_band_um=d.null_band * a,
                conformance=d.conformance_before.state,
                p_exceed=d.p_exceed,
                risk=risk_text(d.risk("before")),
            )
        elif f.id in chars:
            c = chars[f.id]
            cov = coverage_factor(c.dof, K2_COVERAGE)
            row.update(
                at=c.at, deviation_um=c.mean * k, u_um=c.sd * a, U_um=cov * c.sd * a, dof=c.dof
            )
        bc = (res.bayes_characteristics or {}).get(f.id)
        if bc is not None:
            row["bayes_um"], row["bayes_U_um"] = bc[0] * k, 2 * bc[1] * a
        rows.append(row)
    return rows


def summary_table(res) -> Table:
    rows, classes, cells = [], [], []
    bayes = res.bayes_characteristics is not None
    for r in summary_rows(res):
        row = [
            r["feature"],
            r["nominal"],
            tolerance_text(r["tol_lower_um"], r["tol_upper_um"], r["coordinate"]),
            r["at"] or "–",
            num(r["deviation_um"], "+.1f", 1) + " ± " + num(r["U_um"], ".1f", 1),
        ]
        if bayes:
            row.append(num(r["bayes_um"], "+.1f", 1) + " ± " + num(r["bayes_U_um"], ".1f", 1))
        row += [
            r["conformance"] or "–",
            num(r["null_band_um"], ".1f", 1),
            num(r["p_exceed"], ".3f", 1),
            r["verdict"],
            f"{r['gain']:.2f}",
            num(r["correction_um"], "+.1f", 1) if r["gain"] > 0 else "–",
        ]
        rows.append(row)
        cls = [""] * len(row)
        cls[5 + bayes] = css_class(r["conformance"]) if r["conformance"] else ""
        cls[8 + bayes] = css_class(r["verdict"])
        cells.append(cls)
        classes.append("")
    headers = ["feature", "nominal (mm)", "tolerance (µm)", "at", "deviation ± U (µm)"]
    if bayes:
        headers.append("Bayes: deviation ± U (µm)")
    headers += [
        "conformance as measured",
        "null band ± (µm)",
        "P(beyond null band)",
        "verdict",
        "applied gain",
        "correction (µm)",
    ]
    return Table(
        headers,
        rows,
        caption="Every length as drawn: on the diameter Ø for a diameter, on the axial "
        "position Z for a face or shoulder, along the surface normal for tapers and arcs "
        "(+: more material). Deviation: of the fitted feature from nominal at the point "
        "'at' (start, mid or end: the worst of them), robust fit; U: expanded uncertainty "
        "(95 %, about 2 standard uncertainties, from the fit and the study's systematic "
        "sources). Bayes: the same deviation from the posterior draws. Null band: "
        "deviations inside it are not worth correcting (10 % of the tolerance width unless "
        "the study sets it). Applied gain: the fraction of the deviation mirrored into the "
        "finish cut; correction: the resulting change of the cut.",
        classes=classes,
        cells=cells,
    )


def _headline(res) -> list[str]:
    study, fit = res.study, res.fit
    out = [
        f"Study {study.name!r} ({study.path.name}), part {res.part or '–'}: "
        f"{sum(f.n for f in fit)} probe points on {len(fit.fits)} of {len(study.profile)} "
        f"features, {fit.method} fit"
        + (f" ({study.fit.loss} loss)" if fit.method == "robust" else "")
        + f". Report made {res.created} with piecs_bayes {res.versions.get('piecs_bayes', '?')}."
    ]
    if getattr(res, "part_note", ""):
        out.append(res.part_note[0].upper() + res.part_note[1:] + ".")
    if res.path is not None:
        out.append(
            f"Adjusted tool path: {len(res.path.vertices)} vertices, largest vertex move "
            f"{float(np.max(np.linalg.norm(res.path.shift, axis=1))) * 1e3:.1f} µm."
        )
    if res.bayes is not None:
        post = res.bayes.posterior
        out.append(
            "Bayesian fit: "
            + ("converged" if post.converged else "NOT converged: " + "; ".join(post.problems))
            + f" ({post.nsteps} steps × {post.n_ensembles} ensembles × {post.nwalkers} walkers, "
            f"{post.wall_time:.0f} s, {post.ess_per_second:.0f} effective samples/s)."
        )
    if res.program is not None:
        out.append(f"Part program: {len(res.program.changes)} blocks rewritten.")
    return out


def summary_section(res) -> list:
    blocks: list = [Para(t) for t in _headline(res)]
    for step, why in res.unavailable.items():
        blocks.append(Para(f"{step}: not available: {why}", "warn"))
    if res.skipped:
        blocks.append(Para(f"Steps not run (switched off): {', '.join(res.skipped)}.", "note"))
    blocks.append(summary_table(res))
    if res.decisions is not None:
        blocks.append(
            Para(
                "Why each verdict (lengths as drawn, in µm; the last line of each is the "
                "conclusion):",
                "note",
            )
        )
        for d in res.decisions.decisions:
            blocks.append(
                Bullets(f"{d.feature}: {d.verdict}", list(d.reasons), css_class(d.verdict))
            )
        if res.decisions.unmeasured:
            blocks.append(
                Para(f"Not measured (no decision): {', '.join(res.decisions.unmeasured)}.")
            )
    return blocks


#: settings shown with what they mean where the bare name misleads
_SETTING_LABELS = {
    "gain": "gain ([compensation]; only without decisions)",
    "max_correction_mm": "max_correction (mm)",
    "nose_radius_mm": "nose radius (mm)",
}


def inputs_section(res) -> list:
    base = res.study.path.parent
    rows = []
    for f in res.inputs:
        try:
            shown = str(f.path.resolve().relative_to(base.resolve().parent))
        except ValueError:
            shown = str(f.path)
        rows.append([f.role, shown, str(f.size), f.sha256])
    vers = [[k, v] for k, v in res.versions.items()]
    sets = [
        [_SETTING_LABELS.get(k, k), "–" if v is None else str(v)]
        for k, v in res.settings.items()
        if k != "command"
    ]
    times = [[k, f"{v:.1f}"] for k, v in res.timings.items()]
    cmd = [f"piecs-bayes report {res.study.path} --out DIR --seed {res.settings.get('seed', 0)}"]
    if res.bayes is None:
        cmd[0] += " --no-bayes"
    if res.part:
        cmd[0] += f" --part {res.part}"
    if res.nose_radius is not None:
        cmd[0] += f" --nose-radius {res.nose_radius:g}"
    blocks = [
        Table(["role", "file", "bytes", "SHA-256"], rows, caption="Input files"),
        Tables(
            [
                Table(["package", "version"], vers, caption="Versions"),
                Table(["setting", "value"], sets, caption="Settings of this run"),
                Table(["step", "seconds"], times, caption="Wall time per step"),
            ]
        ),
        Pre(cmd, caption="To reproduce (same inputs, versions and seed)"),
    ]
    if res.settings.get("command"):
        blocks.append(Pre([str(res.settings["command"])], caption="This run's command line"))
    blocks += _calibration_blocks(res.study.probe)
    if res.warnings:
        blocks.append(Pre(list(res.warnings), caption="Warnings issued during the run"))
    return blocks


def _calibration_blocks(probe) -> list:
    """The probe calibration the fits used (`[probe] calibration`): its coefficients,
    probing error, feed and age, and r(theta) as a polar plot."""
    from ..figures import probe_calibration_figure

    cal = probe.calibration
    if cal is None:
        return []
    sd = np.sqrt(np.maximum(np.diag(cal.cov), 0.0))
    rows = [[n, f"{1e3 * v:+.2f}" if n != "r0" else f"{v:.5f} mm", f"{1e3 * u:.2f}"]
            for n, v, u in zip(cal.names, cal.coefficients, sd, strict=True)]  # fmt: skip
    age = cal.age_days()
    facts = [
        ["file", str(cal.source)],
        ["probe", str(cal.probe or "–")],
        ["date (age)", f"{cal.date} ({age:g} days)" if age is not None else "–"],
        ["probing feed", f"{cal.feed:g} mm/min" if cal.feed else "–"],
        ["probing error (range of r)", num(cal.probing_error, ".2f") + " µm"],
        ["residual sd", num(cal.residual_sd, ".2f") + " µm"],
        ["dof", "∞" if not np.isfinite(cal.dof) else f"{cal.dof:g}"],
        ["artefact", ", ".join(f"{k} {v}" for k, v in cal.artefact.items()) or "–"],
    ]
    return [
        Tables(
            [
                Table(
                    ["coefficient", "value (µm)", "u (µm)"],
                    rows,
                    caption="Probe calibration: r(θ) = r0 + Σ a_k cos kθ + b_k sin kθ",
                ),
                Table(["", ""], facts, caption="The calibration"),
            ]
        ),  # fmt: skip
        Fig(
            "probe_calibration",
            lambda: probe_calibration_figure(cal),
            "The probe's effective radius by approach angle θ (from +X toward +Z), as "
            "calibrated, about r0 (dashed), with its 95 % band. Every probe point was "
            "corrected to r(θ) at its approach; the band's uncertainty is the budget's "
            "'probe calibration'.",
        ),  # fmt: skip
    ]
