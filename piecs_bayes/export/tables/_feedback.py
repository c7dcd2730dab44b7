"""Feedback over a production run as JSON, CSV and text, (the files of
`piecs-bayes feedback` are written by `export.report.write_feedback`).

The job returns data (`jobs.FeedbackResult`); these render it. Lengths are normal
deviations δ in mm (`*_mm`), with the drawn coordinate alongside where a number is
stated for a person (`*_drawn_mm`: on the diameter for a diameter, ...). JSON is
strict: NaN and infinity are written as null.
"""

from __future__ import annotations

import json
import math

from ._csv import to_csv
from ._jobs import json_safe

SCHEMA_VERSION = 1


def _policy_doc(res, name: str) -> dict:
    """A policy: overall over features and parts, then per feature."""
    o = res.overall(name)
    feats = []
    for f in res.features.values():
        p = f.policies.get(name)
        if p is None:
            continue
        k = abs(f.scale)
        feats.append({
            "feature": f.feature, "settings": dict(p.settings), "rmsd_mm": p.rmsd_mm,
            "max_abs_mm": p.max_abs_mm, "out_of_tolerance": p.out_of_tolerance,
            "adjustments": p.adjustments, "flags": p.flags, "coordinate": f.coordinate,
            "rmsd_drawn_mm": p.rmsd_mm * k, "max_abs_drawn_mm": p.max_abs_mm * k,
        })  # fmt: skip
    return {**o, "features": feats}


def _feature_doc(f) -> dict:
    tr = f.track
    return {
        "feature": f.feature,
        "coordinate": f.coordinate,
        "scale": f.scale,
        "tolerance_mm": list(f.tolerance),
        "n": len(f.parts),
        "u_systematic_mm": f.u_systematic,
        "tool_changes": [f.parts[i] for i in f.tool_changes],
        "steps": f.steps,
        "odd_parts": list(f.odd_parts),
        "model": tr.model.as_dict(),
        "loglik": tr.loglik,
        "predictive_coverage": f.coverage,
        "best_anchor": f.best_anchor,
        "transfer": None if f.transfer is None else {"beta": f.transfer[0],
                                                     "u_beta": f.transfer[1]},
    }  # fmt: skip


def feedback_json(res) -> str:
    """feedback.json (schema `piecs_bayes.feedback`, docs/formats.md): `policies` (per
    policy `{name, settings, rmsd_mm, max_abs_mm, out_of_tolerance, adjustments}` over
    every feature and part, `settings` by feature, and `features`, the same per
    feature), `predictive_coverage`, `next_part` (per feature the correction and its
    u), `steps`, the finished-part check, per-feature tracking and the notes."""
    steps = [{"feature": f.feature, **s} for f in res.features.values() for s in f.steps]
    finish = res.finish_rows()
    doc = {
        "schema": "piecs_bayes.feedback",
        "version": SCHEMA_VERSION,
        "study": res.study,
        "method": res.method,
        "characteristic": res.characteristic,
        "units": {"length": "mm", "deviation": "normal", "x": "radius"},
        "parts": list(res.parts),
        "replayed_on": res.replayed_on,
        "tool_changes": list(res.tool_changes),
        "policies": [_policy_doc(res, name) for name in res.policies],
        "predictive_coverage": res.coverage(),
        "next_part": res.next_part_rows(),
        "steps": steps,
        "steps_by_part": {p: list(v) for p, v in res.steps.items()},
        "finish": {"files": list(res.finish_files), "features": finish} if finish else None,
        "features": [_feature_doc(f) for f in res.features.values()],
        "notes": list(res.notes),
    }
    return json.dumps(json_safe(doc), indent=2) + "\n"


def feedback_csvs(res) -> dict[str, str]:
    """The tables by file name: `feedback_parts.csv` (one row per part and feature,
    long, with a `unit` column), `feedback_policies.csv` (one row per feature and
    policy, and per policy over all features), `feedback_next_part.csv` (one row per
    feature) and, with finished parts, `feedback_finish.csv`."""
    out = {
        "feedback_parts.csv": to_csv(res.part_rows()),
        "feedback_policies.csv": to_csv(res.policy_rows()),
        "feedback_next_part.csv": to_csv(res.next_part_rows()),
    }
    if res.finish_rows():
        out["feedback_finish.csv"] = to_csv(res.finish_rows())
    return out


def _um(x: float, signed: bool = False) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    return f"{x * 1e3:+.2f}" if signed else f"{x * 1e3:.2f}"


def feedback_text(res) -> str:
    """A fixed-width summary: RMS per policy and feature (µm of δ), the steps, the
    coverage and the next part's correction (as drawn and as δ)."""
    names = list(res.policies)
    labels = [res.policy_label(n) for n in names]
    w = max(8, *(len(n) for n in labels))
    head = f"{'feature':<10}" + "".join(f"{n:>{w + 1}}" for n in labels)
    loop = getattr(res, "inspect_every", 1), getattr(res, "delay", 0)
    lines = [
        f"Feedback over {len(res.parts)} parts of {res.study!r} (fits {res.method}, "
        f"at {res.characteristic}; replayed on {res.replayed_on} deviations)"
        + ("" if loop == (1, 0) else f"; every {loop[0]}. part measured, results "
           f"{loop[1]} part(s) late"),
        "RMS realised deviation per policy (µm of the normal deviation). Anchors in two "
        "comparisons: (a) one setting for the machine (SHOP_SETTINGS), (b) tuned on this "
        "run (hindsight):",
        head,
    ]  # fmt: skip
    for f in res.features.values():
        lines.append(f"{f.feature:<10}" + "".join(
            f"{_um(f.policies[n].rmsd_mm):>{w + 1}}" for n in names))  # fmt: skip
    lines.append(f"{'all':<10}" + "".join(f"{_um(res.overall(n)['rmsd_mm']):>{w + 1}}"
                                          for n in names))  # fmt: skip
    lines.append(f"{'out of tol':<10}" + "".join(
        f"{res.overall(n)['out_of_tolerance']:>{w + 1}}" for n in names))  # fmt: skip
    cov = res.coverage()
    lines.append(f"95 % one-step-ahead predictive coverage: {cov['overall']:.1%} of "
                 f"{cov['n']} parts")  # fmt: skip
    steps = res.steps
    lines.append("steps: " + ("; ".join(f"before {p} ({', '.join(v)})" for p, v in
                                        steps.items()) or "none found"))  # fmt: skip
    lines.append("next part (bayes): correction ± u")
    for r in res.next_part_rows():
        lines.append(
            f"  {r['feature']:<10} {_um(r['correction_drawn_mm'], True)} ± "
            f"{_um(r['u_drawn_mm'])} µm on {r['coordinate']} (δ {_um(r['correction_mm'], True)}"
            f" ± {_um(r['u_mm'])} µm): {r['verdict']}"
        )
    for r in res.finish_rows():
        lines.append(
            f"  finish {r['feature']}: beta {r['transfer']:.3f} ± {r['u_transfer']:.3f}, "
            f"coverage {r['coverage_one_step']:.0%} (one step), "
            f"{r['coverage_from_semifinish']:.0%} (from semifinish)"
        )
    lines += [f"note: {n}" for n in res.notes]
    return "\n".join(lines) + "\n"
