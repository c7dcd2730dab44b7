"""Report sections that frame the others: the summary (headline, one row per
feature, the reasons behind each verdict) and the inputs (files, versions,
settings, how to reproduce the run)."""

from __future__ import annotations

import math

import numpy as np

from ..fit import coverage_factor
from ._report_model import _f, _Para, _Pre, _Table

__all__ = ["summary_rows"]


#: coverage probability of a k = 2 interval under the normal (JCGM 100 G.6)
K2_COVERAGE = 0.9544997361036416


def _nominal_text(f) -> str:
    """The feature as on the drawing, compactly (X as diameter Ø, mm)."""
    (x0, z0), (x1, z1) = f.p0, f.p1
    if f.kind == "arc":
        cx, cz = f.center
        return f"arc R{f.radius:.3f} {'ccw' if f.ccw else 'cw'}, centre Ø{2 * cx:.3f} Z{cz:.3f}"
    if abs(x1 - x0) < 1e-9:
        return f"Ø{2 * x0:.3f}, Z{z0:.3f} to {z1:.3f}"
    if abs(z1 - z0) < 1e-9:
        return f"face Z{z0:.3f}, Ø{2 * x0:.3f} to {2 * x1:.3f}"
    return f"taper Ø{2 * x0:.3f} Z{z0:.3f} to Ø{2 * x1:.3f} Z{z1:.3f}"


def summary_rows(res) -> list[dict]:
    """One row per profile feature: nominal, tolerance, normal deviation with its
    expanded uncertainty U = 2u (robust fit, and Bayesian when sampled), verdict,
    gain and correction. Lengths in µm except `nominal`."""
    study, fit = res.study, res.fit
    dec = res.decisions
    by_dec = {}
    if dec is not None:
        for d, c in zip(dec.decisions, dec.estimates, strict=True):
            by_dec[d.feature] = (d, c)
    chars = {}
    if dec is None:
        from ..jobs import characteristics

        chars = characteristics(study, fit, at="worst")
    rows = []
    for f in study.profile.features:
        lo, hi = f.tolerance
        row = {
            "feature": f.id,
            "nominal": _nominal_text(f),
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
            "gain": float(res.gains.get(f.id, 0.0)),
            "correction_um": math.nan,
            "conformance": "",
            "p_exceed": math.nan,
        }
        if f.id in by_dec:
            d, c = by_dec[f.id]
            row.update(
                at=c.at if c is not None else "",
                deviation_um=d.estimate * 1e3,
                u_um=d.u_estimate * 1e3,
                U_um=d.conformance_before.expanded * 1e3,
                dof=d.dof,
                verdict=d.verdict + (f" (+{d.more_points} points)" if d.more_points else ""),
                gain=d.gain,
                correction_um=d.correction * 1e3,
                conformance=d.conformance_before.state,
                p_exceed=d.p_exceed,
            )
        elif f.id in chars:
            c = chars[f.id]
            k = coverage_factor(c.dof, K2_COVERAGE)
            row.update(
                at=c.at, deviation_um=c.mean * 1e3, u_um=c.sd * 1e3, U_um=k * c.sd * 1e3, dof=c.dof
            )
        bc = (res.bayes_characteristics or {}).get(f.id)
        if bc is not None:
            row["bayes_um"], row["bayes_U_um"] = bc[0] * 1e3, 2 * bc[1] * 1e3
        rows.append(row)
    return rows


def _summary_table(res) -> _Table:
    rows, classes = [], []
    bayes = res.bayes_characteristics is not None
    for r in summary_rows(res):
        cells = [
            r["feature"],
            r["nominal"],
            f"{r['tol_lower_um']:+g}/{r['tol_upper_um']:+g}",
            r["at"] or "–",
            _f(r["deviation_um"], scale=1) + " ± " + _f(r["U_um"], ".2f", 1),
        ]
        if bayes:
            cells.append(_f(r["bayes_um"], scale=1) + " ± " + _f(r["bayes_U_um"], ".2f", 1))
        cells += [
            r["conformance"] or "–",
            _f(r["p_exceed"], ".3f", 1),
            r["verdict"],
            f"{r['gain']:.2f}",
            _f(r["correction_um"], scale=1),
        ]
        rows.append(cells)
        classes.append(r["verdict"].split(" (")[0].replace(" ", "-"))
    headers = [
        "feature",
        "nominal (X as Ø, mm)",
        "tolerance (µm)",
        "at",
        "deviation ± U (µm, 95.45 %)",
    ]
    if bayes:
        headers.append("Bayes ± U (µm, k=2)")
    headers += ["conformance", "P(|δ|>band)", "verdict", "gain", "correction (µm)"]
    short = ["feature", "nominal (Ø, mm)", "tol. (µm)", "at", "δ ± U (µm)"]
    short += (["Bayes δ ± U"] if bayes else []) + ["conformance", "P>band", "verdict"]
    short += ["gain", "corr. (µm)"]
    return _Table(
        headers,
        rows,
        short=short,
        caption="Deviation: normal deviation δ of the fitted feature from nominal at the "
        "point 'at' (+ outward, i.e. more material on a shaft; for a diameter the "
        "diameter error is 2δ), robust fit; U = 2u with u combining the fit and the "
        "study's systematic sources. Bayes: the same δ from the posterior draws. "
        "Gain: fraction of the fitted deviation mirrored into the finish cut.",
        classes=classes,
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
    if res.decisions is not None:
        verdicts = [d.verdict for d in res.decisions.decisions]
        n_comp = verdicts.count("compensate")
        largest = max(abs(d.correction) for d in res.decisions.decisions) * 1e3
        others = ", ".join(
            f"{v}: {verdicts.count(v)}" for v in dict.fromkeys(verdicts) if v != "compensate"
        )
        out.append(
            f"Decision: compensate {n_comp} of {len(verdicts)} features"
            + (f" (largest correction {largest:.1f} µm)" if n_comp else "")
            + (f"; {others}" if others else "")
            + "."
        )
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


def _summary_section(res) -> list:
    blocks = [_Para(t) for t in _headline(res)]
    for step, why in res.unavailable.items():
        blocks.append(_Para(f"{step}: not available: {why}", "warn"))
    if res.skipped:
        blocks.append(_Para(f"Steps not run (switched off): {', '.join(res.skipped)}.", "note"))
    blocks.append(_summary_table(res))
    if res.decisions is not None:
        lines = []
        for d in res.decisions.decisions:
            lines.append(f"{d.feature}: {d.verdict}")
            lines += [f"  - {r}" for r in d.reasons]
        if res.decisions.unmeasured:
            lines.append(f"not measured (no decision): {', '.join(res.decisions.unmeasured)}")
        blocks.append(_Pre(lines, caption="The reasons behind each verdict"))
    return blocks


def _inputs_section(res) -> list:
    base = res.study.path.parent
    rows = []
    for f in res.inputs:
        try:
            shown = str(f.path.resolve().relative_to(base.resolve().parent))
        except ValueError:
            shown = str(f.path)
        rows.append([f.role, shown, str(f.size), f.sha256])
    vers = [[k, v] for k, v in res.versions.items()]
    sets = [[k, "–" if v is None else str(v)] for k, v in res.settings.items() if k != "command"]
    times = [[k, f"{v:.1f}"] for k, v in res.timings.items()]
    cmd = [f"piecs-bayes report {res.study.path} --out DIR --seed {res.settings.get('seed', 0)}"]
    if res.bayes is None:
        cmd[0] += " --no-bayes"
    if res.part:
        cmd[0] += f" --part {res.part}"
    if res.nose_radius is not None:
        cmd[0] += f" --nose-radius {res.nose_radius:g}"
    blocks = [
        _Table(["role", "file", "bytes", "SHA-256"], rows, caption="Input files"),
        _Table(["package", "version"], vers, caption="Versions"),
        _Table(["setting", "value"], sets, caption="Settings of this run"),
        _Table(["step", "seconds"], times, caption="Wall time per step"),
        _Pre(cmd, caption="To reproduce (same inputs, versions and seed)"),
    ]
    if res.settings.get("command"):
        blocks.append(_Pre([str(res.settings["command"])], caption="This run's command line"))
    if res.warnings:
        blocks.append(_Pre(list(res.warnings), caption="Warnings issued during the run"))
    return blocks
