"""Decision tables and capability studies as JSON, CSV and fixed-width text.

The jobs return data (`jobs.DecisionTable`, `jobs.CapabilityStudy`); these render
it. JSON is strict: NaN and infinity are written as null.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict

import numpy as np

from ._csv import to_csv

SCHEMA_VERSION = 1


def decisions_csv(table) -> str:
    """One row per feature (`DecisionTable.rows`)."""
    return to_csv(table.rows())


def decisions_json(table, *, apply: Mapping | None = None) -> str:
    """decisions.json (schema `piecs_bayes.decisions`, docs/formats.md); `apply`, the
    route to the machine with its files (`MachineFiles.as_dict()`), when given."""
    feats = []
    for d, c in zip(table.decisions, table.estimates, strict=True):
        row = {k: v for k, v in d.as_row().items() if k != "reasons"}
        row["tolerance_mm"] = list(d.tolerance)
        row["characteristic"] = None if c is None else json_safe(asdict(c))
        row["conformance_before"] = json_safe(asdict(d.conformance_before))
        row["conformance_after"] = json_safe(asdict(d.conformance_after))
        row["conformity_risk_before"] = d.risk("before").as_dict()
        row["conformity_risk_after"] = d.risk("after").as_dict()
        row["actions"] = [json_safe(asdict(a)) for a in d.actions]
        row["reasons"] = list(d.reasons)
        feats.append(row)
    doc = {
        "schema": "piecs_bayes.decisions",
        "version": SCHEMA_VERSION,
        "study": table.study,
        "part": table.part,
        "method": table.method,
        "characteristic": table.characteristic,
        "units": {"length": "mm", "x": "radius"},
        "settings": json_safe(asdict(table.settings)),
        "features": [json_safe(f) for f in feats],
        "unmeasured": list(table.unmeasured),
    }
    if apply is not None:
        doc["apply"] = json_safe(dict(apply))
    return json.dumps(doc, indent=2) + "\n"


def decisions_text(table) -> str:
    """A fixed-width verdict table (µm, as drawn), then the reasons per feature."""
    head = (
        f"{'feature':<11}{'on':<9}{'at':<7}{'dev µm':>8}{'U µm':>7}{'tol µm':>13}"
        f"{'band µm':>8}{'P(>band)':>9}  {'conformance':<17}{'verdict':<18}{'gain':>5}"
        f"{'corr µm':>9}"
    )
    lines = [
        f"Decisions for {table.study!r}, part {table.part or '-'} ({table.method}). Values "
        "as drawn: on the diameter for diameters, on Z for faces, along the normal for "
        f"tapers and arcs, at the {table.characteristic} point of each feature; U: expanded "
        "uncertainty (95 %); band: the null band, deviations inside it are not worth "
        "correcting; P(>band): probability the deviation is beyond it; gain: applied; "
        "corr: the correction of the finish cut.",
        head,
        "-" * len(head),
    ]
    for d, c in zip(table.decisions, table.estimates, strict=True):
        lo, hi = d.drawn_tolerance
        verdict = d.verdict.upper() if d.verdict == "compensate" else d.verdict
        if d.verdict == "measure more" and d.more_points is not None:
            verdict += f" +{d.more_points}"
        lines.append(
            f"{d.feature:<11}{d.coordinate:<9}{(c.at if c else '-'):<7}"
            f"{d.drawn_estimate * 1e3:>+8.2f}{d.drawn_expanded * 1e3:>7.2f}"
            f"{f'[{lo * 1e3:+g},{hi * 1e3:+g}]':>13}{d.drawn_null_band * 1e3:>8.2f}"
            f"{d.p_exceed:>9.3f}  {d.conformance_before.state:<17}{verdict:<18}"
            f"{d.gain:>5.2f}{d.drawn_correction * 1e3:>+9.2f}"
        )
    if table.unmeasured:
        lines.append(f"not measured (no decision): {', '.join(table.unmeasured)}")
    lines += ["", _risk_lines(table)]
    for d in table.decisions:
        lines.append(f"{d.feature}: {d.verdict}")
        lines += [f"  - {r}" for r in d.reasons]
    return "\n".join(lines)


def risk_text(risk) -> str:
    """'accept, consumer's risk 0.12 %' (JCGM 106's specific risk of the decision)."""
    if risk.decision == "accept":
        return f"accept, consumer's risk {percent(risk.specific_consumer_risk)}"
    return f"reject, producer's risk {percent(risk.specific_producer_risk)}"


def percent(p: float) -> str:
    """A probability as a percentage to 2 significant digits; below 0.01 %: '< 0.01 %'."""
    return "< 0.01 %" if p < 1e-4 else f"{100 * p:.2g} %"


def _risk_lines(table) -> str:
    """Each feature's conformity decision, as measured and after the correction,
    with its specific risk (JCGM 106), then a blank line."""
    out = ["Conformity decisions with their risks (JCGM 106; accepted inside the "
           "acceptance zone, the tolerance less the guard band U):"]  # fmt: skip
    for d in table.decisions:
        out.append(f"  {d.feature:<11} as measured: {risk_text(d.risk('before')):<36} "
                   f"after the correction: {risk_text(d.risk('after'))}")  # fmt: skip
    return "\n".join(out) + "\n"


def capability_json(study) -> str:
    """capability.json (schema `piecs_bayes.capability`, docs/formats.md): lengths as
    drawn (`*_drawn_mm`, on each feature's `coordinate`), with the per-part values
    and the summary's limits and mean also as normal deviations (`*_mm`)."""
    feats = []
    for f in study.features.values():
        s = f.stability
        feats.append(
            {
                **f.summary(),
                "scale": f.scale,
                "indices": f.capability.table(),
                "sigma_method": f.capability.sigma_method,
                "df_within": f.capability.df_within,
                "stability": {
                    "center_drawn_mm": s.center,
                    "sigma_drawn_mm": s.sigma,
                    "lcl_drawn_mm": s.lcl,
                    "ucl_drawn_mm": s.ucl,
                    "mr_ucl_drawn_mm": s.mr_ucl,
                    "beyond_limits": [f.parts[i] for i in s.beyond_limits],
                    "runs": [[f.parts[a], f.parts[b]] for a, b in s.runs],
                    "trends": [[f.parts[a], f.parts[b]] for a, b in s.trends],
                    "moving_range_beyond": [f.parts[i] for i in s.mr_beyond],
                    "step_before_part": f.step_part,
                    "step_drawn_mm": s.step_size,
                    "step_t": s.step_t,
                    "findings": f.findings(),
                },
                "verdict_reason": f.verdict_reason(),
                "corrected_for_measurement": (None if f.corrected is None else f.corrected.table()),
                "predicted": _predicted_json(f.predicted),
                "predicted_within": _predicted_json(f.predicted_within),
                "notes": list(f.notes),
                "values": [
                    {
                        "part": p,
                        "value_drawn_mm": float(v),
                        "u_drawn_mm": float(u),
                        "value_mm": float(vn),
                        "u_mm": float(un),
                    }
                    for p, v, u, vn, un in zip(
                        f.parts, f.values, f.u, f.normal_values, f.normal_u, strict=True
                    )
                ],
            }
        )
    doc = {
        "schema": "piecs_bayes.capability",
        "version": SCHEMA_VERSION,
        "study": study.study,
        "method": study.method,
        "confidence": study.confidence,
        "units": {"length": "mm", "x": "radius"},
        "parts": list(study.parts),
        "steps": {p: list(v) for p, v in study.steps.items()},
        "notes": list(study.notes),
        "features": [json_safe(f) for f in feats],
    }
    return json.dumps(doc, indent=2) + "\n"


def _process_lines(study) -> list[str]:
    """The measuring process (VDA 5 Q_MP), the indices corrected for measurement
    variation, the global risks (JCGM 106) and the verdict, one row per feature."""
    h = (
        f"{'feature':<10}{'U_MP um':>8}{'Q_MP':>7}{'Cp corr':>8}{'Cpk corr':>9}"
        f"{'consumer':>10}{'producer':>10}{'GB 2% um':>9}  verdict"
    )
    out = [h, "-" * len(h)]
    for f in study.features.values():
        cc, risks = f.corrected, f.risks()
        cp, cpk = ("-", "-") if cc is None else (f"{cc.cp:.2f}", f"{cc.cpk:.2f}")
        cr, pr, gb = (("-",) * 3 if risks is None else
                      (percent(risks[0].global_consumer_risk),
                       percent(risks[0].global_producer_risk),
                       f"{risks[1].guard_band * 1e3:.2f}"))  # fmt: skip
        out.append(
            f"{f.feature:<10}{f.U_mp * 1e3:>8.2f}{f.q_mp:>7.1%}{cp:>8}{cpk:>9}{cr:>10}{pr:>10}"
            f"{gb:>9}  {f.verdict}"
        )
    lim = sorted({f"{f.q_mp_limit:.0%}" for f in study.features.values()})
    ks = sorted({f"{f.coverage_factor:g}" for f in study.features.values()})
    out.append(
        f"U_MP = k u_MP (k = {', '.join(ks)}), u_MP^2 = rms(u_fit)^2 + u_systematic^2 (the "
        f"study's budget); Q_MP = 2 U_MP / T, capable of the tolerance at most "
        f"{', '.join(lim)} (VDA 5 / ISO 22514-7); above it no capability is claimed. 'corr': "
        "Cp, Cpk with the measurement's share taken off (sigma_p^2 = sigma^2 - rms(u_fit)^2). "
        "consumer / producer: global risks of judging a part by its measured value against "
        "the tolerance (JCGM 106, 9.5); GB 2%: the guard band for a 2 % consumer's risk. "
        "verdict: Cpk against the threshold (Ppk for a process not in statistical control)."
    )
    return out


def capability_text(study) -> str:
    """Two fixed-width tables (indices; stability and prediction), then the findings;
    lengths in µm as drawn (the `on` column)."""
    lvl = f"{study.confidence:.0%}"
    h1 = (
        f"{'feature':<10}{'on':<9}{'n':>3}{'mean um':>9}{'tol um':>13}{'s_w um':>8}"
        f"{'s_o um':>8}{'Cp':>7}{f'[{lvl} CI]':>15}{'Cpk':>7}{f'[{lvl} CI]':>15}"
        f"{'Pp':>7}{f'[{lvl} CI]':>15}{'Ppk':>7}{f'[{lvl} CI]':>15}"
    )
    lines = [
        f"Capability of {study.study!r}: {len(study.parts)} parts, fits {study.method}. "
        "Values as drawn (um): on the diameter for diameters, on Z for faces, along the "
        "normal for tapers and arcs, at each feature's characteristic point; tol: the "
        "tolerance on the same coordinate.",
        h1,
        "-" * len(h1),
    ]
    for f in study.features.values():
        c = f.capability
        lo, hi = f.tolerance
        lines.append(
            f"{f.feature:<10}{f.coordinate:<9}{c.n:>3}{c.mean * 1e3:>+9.2f}"
            f"{f'[{lo * 1e3:+g},{hi * 1e3:+g}]':>13}{c.sigma_within * 1e3:>8.2f}"
            f"{c.sigma_overall * 1e3:>8.2f}{c.cp:>7.2f}{_ci(c.cp_ci):>15}{c.cpk:>7.2f}"
            f"{_ci(c.cpk_ci):>15}{c.pp:>7.2f}{_ci(c.pp_ci):>15}{c.ppk:>7.2f}"
            f"{_ci(c.ppk_ci):>15}"
        )
    h2 = (
        f"{'feature':<10}{'Bayes Cp':>9}{f'[{lvl} CrI]':>15}{'Bayes Cpk':>10}"
        f"{f'[{lvl} CrI]':>15}{'P(>1.33)':>9}  {'stability':<27}{'Cpk after':>10}"
        f"{f'[{lvl} CI]':>15}{'if stable':>10}{f'[{lvl} CI]':>15}"
    )
    lines += ["", h2, "-" * len(h2)]
    for f in study.features.values():
        b, p, pw, s = f.capability.bayes, f.predicted, f.predicted_within, f.stability
        if s.in_control:
            stab = "in control"
        else:
            stab = f"{len(s.out_of_control)}/{s.n} flagged"
            stab += f", step@{f.step_part}" if f.step_part else ""
        bayes = (
            f"{b.cp:>9.2f}{_ci(b.cp_interval):>15}{b.cpk:>10.2f}{_ci(b.cpk_interval):>15}"
            f"{b.p_cpk_above:>9.3f}"
            if b is not None
            else f"{'-':>58}"
        )
        lines.append(
            f"{f.feature:<10}{bayes}  {stab:<27}{p.cpk:>10.2f}{_ci(p.cpk_ci):>15}"
            f"{pw.cpk:>10.2f}{_ci(pw.cpk_ci):>15}"
        )
    lines += ["", *_process_lines(study)]
    lines += [
        "",
        "Cp, Cpk: within sigma (moving range), chi-square and Bissell intervals; Pp, Ppk: "
        "overall sigma. Bayes: i.i.d. normal values, prior 1/sigma (overall spread: compare "
        "with Pp, Ppk), equal-tailed credible intervals. 'Cpk after': the mean moved to the "
        "target by the compensation (gain "
        + ", ".join(sorted({f"{f.gain:g}" for f in study.features.values()}))
        + "), overall spread kept; 'if stable': with the within spread, i.e. if compensation "
        "also removed the drift and steps (per-part PIECS).",
    ]
    for part, feats in sorted(study.steps.items(), key=lambda kv: -len(kv[1])):
        if len(feats) > 1:
            lines.append(
                f"STEP before {part} on {len(feats)} of {len(study.features)} features "
                f"({', '.join(feats)}): a change of tool or setup there; the parts on either "
                "side are different processes (do not pool them for a capability claim)"
            )
        else:
            lines.append(
                f"step before {part} on {feats[0]} only: a drift can look like a step there"
            )
    for f in study.features.values():
        reasons = f.findings()
        if reasons or f.notes:
            lines.append(f"{f.feature}:")
            lines += [f"  - {r}" for r in reasons]
            lines += [f"  - {n}" for n in f.notes]
    if study.notes:
        lines.append("notes:")
        lines += [f"  - {n}" for n in study.notes]
    return "\n".join(lines)


def capability_csvs(study) -> dict[str, str]:
    """The three capability tables by file name: one row per feature and index, one
    per feature, one per part and feature."""
    return {
        "capability.csv": to_csv(study.index_rows()),
        "capability_summary.csv": to_csv(study.summary_rows()),
        "capability_parts.csv": to_csv(study.part_rows()),
    }


def _predicted_json(p) -> dict:
    """A predicted capability for JSON, its lengths named as drawn (`*_drawn_mm`)."""
    d = asdict(p)
    for key in ("offset", "u_offset", "mean_after", "sigma"):
        d[f"{key}_drawn_mm"] = d.pop(key)
    return json_safe(d)


def _ci(iv) -> str:
    lo, hi = iv
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "-"
    return f"[{lo:.2f}, {hi:.2f}]"


def json_safe(obj):
    """JSON-safe: NaN/inf -> None, numpy -> Python, tuples -> lists (recursively)."""
    if isinstance(obj, Mapping):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
