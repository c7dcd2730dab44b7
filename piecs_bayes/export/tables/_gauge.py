"""Gauge studies (`jobs.GaugeStudy`) as fixed-width text and as JSON.

`gauge_text` prints the type-1 table, the ANOVA table, the variance components with
their intervals, the average-and-range cross-check, the VDA 5 budget and the
verdicts, lengths in µm; `gauge_json` writes everything (schema
`piecs_bayes.gauge_study`, docs/formats.md) in mm. JSON is strict: NaN -> null.
"""

from __future__ import annotations

import json
from dataclasses import asdict

from ._jobs import json_safe

SCHEMA_VERSION = 1
_UM = 1e3


def _ci(iv, scale: float = 1.0, fmt: str = ".3g") -> str:
    return "-" if iv is None else f"[{iv.lower * scale:{fmt}}, {iv.upper * scale:{fmt}}]"


def _yes(ok) -> str:
    return {True: "yes", False: "NO", None: ""}[ok]


def type1_text(t) -> str:
    """The type-1 study: bias, s, Cg, Cgk with intervals, resolution, verdict."""
    st, ref = t.settings, t.reference
    lvl = f"{st.confidence:.0%} CI"
    sig = "significant" if t.bias_significant else "not significant"
    head = f"{'':<20}{'value':>10}  {lvl:<22}{'limit':>10}  ok"
    rows = [
        f"{'bias (um)':<20}{t.bias * _UM:>+10.3f}  {_ci(t.bias_ci, _UM, '+.3f'):<22}"
        f"{'':>10}  t = {t.bias_t:.2f}, p = {t.bias_p:.3g}: {sig}",
        f"{'s (um)':<20}{t.s * _UM:>10.3f}  {_ci(t.s_ci, _UM, '.3f'):<22}",
        f"{'Cg':<20}{t.cg:>10.2f}  {_ci(t.cg_ci, 1, '.2f'):<22}{f'>= {st.cg_limit:g}':>10}  "
        f"{_yes(t.cg_ok)}",
        f"{'Cgk':<20}{t.cgk:>10.2f}  {_ci(t.cgk_ci, 1, '.2f'):<22}{f'>= {st.cgk_limit:g}':>10}  "
        f"{_yes(t.cgk_ok)}",
        f"{'resolution / T':<20}{t.resolution_share:>10.1%}  {'':<22}"
        f"{f'<= {st.resolution_share:.0%}':>10}  {_yes(t.resolution_ok)}",
    ]
    why = "" if t.capable else ": " + "; ".join(t.reasons)
    return "\n".join(
        [
            f"Type-1 study: {t.n} readings of the reference {ref.value:.6g} mm (U = "
            f"{ref.expanded_uncertainty * _UM:.3g} um, k = {ref.coverage_factor:g}); T = "
            f"{t.tolerance * _UM:.4g} um, resolution {t.resolution * _UM:.3g} um",
            head,
            "-" * len(head),
            *rows,
            f"Cg = {st.k_share:.0%} T / ({st.l_spread:g} s), Cgk = ({st.k_share / 2:.0%} T - "
            f"|bias|) / ({st.l_spread / 2:g} s); Cg: chi-square interval, Cgk: Bissell's "
            "approximation",
            f"verdict: {t.verdict.upper()}{why}",
        ]
    )


def grr_text(g) -> str:
    """The gauge R&R: ANOVA table(s), components, cross-check, verdict and notes."""
    p, o, r = g.data.shape
    lines = [
        f"Gauge R&R (ANOVA, crossed): {p} parts x {o} {g.appraiser_is}s x {r} trials"
        + ("" if g.tolerance is None else f"; T = {g.tolerance * _UM:.4g} um"),
        "",
        *_anova_text(g.anova_full, g.appraiser_is),
    ]
    if g.pooled:
        lines += ["", *_anova_text(g.anova, g.appraiser_is)]
    lvl = f"{g.settings.confidence:.0%} CI"
    head = (
        f"{'component':<20}{'sd (um)':>9}  {lvl + ' (um)':<20}{'%contrib':>9}{'%study':>8}"
        f"{'%tol':>8}"
    )
    lines += ["", head, "-" * len(head)]
    for k, c in g.components.items():
        tol = "" if c.pct_tolerance is None else f"{c.pct_tolerance:8.1f}"
        name = k.replace("appraiser", g.appraiser_is)
        lines.append(
            f"{name:<20}{c.sd * _UM:>9.3f}  {_ci(c.sd_ci, _UM, '.3f'):<20}"
            f"{c.pct_contribution:>9.1f}{c.pct_study:>8.1f}{tol:>8}"
        )
    lines += ["", *_grr_summary(g), *_range_text(g)]
    lines += [f"  - {n}" for n in g.notes]
    return "\n".join(lines)


def _anova_text(table, who: str) -> list[str]:
    """The ANOVA table, sums of squares in um^2; F tests of the random model."""
    what = "interaction pooled into repeatability" if table.pooled else "with interaction"
    head = f"{'source':<22}{'df':>4}{'SS (um^2)':>14}{'MS (um^2)':>14}{'F':>10}{'p':>9}"
    lines = [f"ANOVA, {what}", head, "-" * len(head)]
    for row in table.rows:
        f = "" if row.f is None else f"{row.f:.3f}"
        p = "" if row.p is None else f"{row.p:.4f}"
        lines.append(
            f"{row.source.replace('appraiser', who):<22}{row.df:>4}"
            f"{row.ss * _UM**2:>14.5g}{row.ms * _UM**2:>14.5g}{f:>10}{p:>9}"
        )
    return lines


def _grr_summary(g) -> list[str]:
    st = g.settings
    tol = (
        ""
        if g.tolerance is None
        else f"%GRR of T = {g.pct_grr_tolerance:.1f} % {_ci(g.pct_grr_tolerance_ci, 1, '.1f')}, "
    )
    return [
        f"{tol}%GRR of study variation = {g.pct_grr_study:.1f} %, ndc = {g.ndc} "
        f"(>= {st.ndc_min}: {_yes(g.ndc_ok)})",
        f"verdict on %GRR of the {st.grr_basis}: {g.verdict.upper()} (< "
        f"{st.grr_acceptable:.0%} acceptable, <= {st.grr_conditional:.0%} conditional); "
        "intervals: modified large-sample (Burdick & Larsen)",
    ]


def _range_text(g) -> list[str]:
    rc = g.cross_check
    tol = "" if rc.pct_grr_tolerance is None else f", {rc.pct_grr_tolerance:.1f} % of T"
    return [
        f"cross-check, average and range (K1 {rc.k1:.4f}, K2 {rc.k2:.4f}, K3 {rc.k3:.4f}, "
        f"{rc.constants}): EV {rc.ev * _UM:.3f} um, AV {rc.av * _UM:.3f} um, GRR "
        f"{rc.grr * _UM:.3f} um ({rc.pct('grr'):.1f} % of TV{tol}), PV {rc.pv * _UM:.3f} um, "
        f"ndc {rc.ndc}",
    ]


def budget_text(b) -> str:
    """The VDA 5 / ISO 22514-7 budget: one row per component, then U and Q."""
    st = b.settings
    head = f"{'symbol':<8}{'source':<36}{'u (um)':>9}  {'MS':<3}{'MP':<3} origin"
    mp = b.u_mp is not None
    lines = [
        "VDA 5 / ISO 22514-7 uncertainty budget (standard uncertainties)",
        head,
        "-" * len(head),
    ]
    for c in b.components:
        ms_mark = "x" if c.in_ms else ""
        mp_mark = ("x" if c.in_mp else "") if mp else ""
        lines.append(
            f"{c.symbol:<8}{c.name[:35]:<36}{c.u * _UM:>9.4f}  {ms_mark:<3}{mp_mark:<3} {c.origin}"
        )
    k = st.coverage_factor
    lines.append(
        f"U_MS = {b.U_ms * _UM:.3f} um (k = {k:g}), Q_MS = 2 U_MS / T = {b.q_ms:.1%} "
        f"(<= {st.q_ms_limit:.0%}: {_yes(b.q_ms_ok)}); smallest T for the system "
        f"{b.t_min_ms * _UM:.3g} um"
    )
    if mp:
        lines.append(
            f"U_MP = {b.U_mp * _UM:.3f} um (k = {k:g}), Q_MP = 2 U_MP / T = "
            f"{b.q_mp:.1%} (<= {st.q_mp_limit:.0%}: {_yes(b.q_mp_ok)}); smallest T for "
            f"the process {b.t_min_mp * _UM:.3g} um"
        )
    rule = "the larger of u_RE and the repeatability" if st.resolution_rule == "max" else "both"
    lines.append(f"resolution and repeatability: {rule} counted; verdict: {b.verdict.upper()}")
    return "\n".join(lines)


def gauge_text(result) -> str:
    """The whole gauge study as the CLI prints it."""
    s = result.study
    blocks = [f"Gauge study {s.name!r} ({s.path})"]
    if result.kind == "type1":
        blocks.append(type1_text(result.type1))
    else:
        blocks.append(grr_text(result.grr))
    if result.budget is not None:
        blocks.append(budget_text(result.budget))
    blocks += [f"note: {n}" for n in result.notes]
    return "\n\n".join(blocks)


def _type1_json(t) -> dict:
    return {
        "n": t.n,
        "readings_mm": t.readings,
        "reference": asdict(t.reference),
        "reference_u_mm": t.reference.u,
        "tolerance_mm": t.tolerance,
        "resolution_mm": t.resolution,
        "mean_mm": t.mean,
        "bias_t": t.bias_t,
        "bias_p": t.bias_p,
        "bias_significant": t.bias_significant,
        "statistics": t.table(),
        "limits_mm": t.limits,
        "capable": t.capable,
        "verdict": t.verdict,
        "reasons": list(t.reasons),
    }


def _grr_json(g) -> dict:
    return {
        "parts": list(g.parts),
        "appraiser_is": g.appraiser_is,
        "appraisers": list(g.appraisers),
        "trials": g.trials,
        "readings_mm": g.data,
        "tolerance_mm": g.tolerance,
        "anova_with_interaction": g.anova_full.table(),
        "anova_used": g.anova.table(),
        "interaction_p": g.interaction_p,
        "interaction_pooled": g.pooled,
        "components_mm": g.table(),
        "clipped": list(g.clipped),
        "pct_grr_tolerance": g.pct_grr_tolerance,
        "pct_grr_tolerance_ci": None if g.tolerance is None else g.pct_grr_tolerance_ci.as_dict(),
        "pct_grr_study": g.pct_grr_study,
        "ndc": g.ndc,
        "ndc_ok": g.ndc_ok,
        "verdict": g.verdict,
        "range_method_mm": g.cross_check.as_dict(),
        "notes": list(g.notes),
    }


def _budget_json(b) -> dict:
    return {
        "components_mm": b.table(),
        "u_ms_mm": b.u_ms,
        "U_ms_mm": b.U_ms,
        "q_ms": b.q_ms,
        "q_ms_ok": b.q_ms_ok,
        "t_min_ms_mm": b.t_min_ms,
        "u_mp_mm": b.u_mp,
        "U_mp_mm": b.U_mp,
        "q_mp": b.q_mp,
        "q_mp_ok": b.q_mp_ok,
        "t_min_mp_mm": b.t_min_mp,
        "verdict": b.verdict,
    }


def gauge_json(result) -> str:
    """gauge_type1.json / gauge_grr.json (schema `piecs_bayes.gauge_study`)."""
    s = result.study
    doc = {
        "schema": "piecs_bayes.gauge_study",
        "version": SCHEMA_VERSION,
        "kind": result.kind,
        "study": s.name,
        "file": str(s.path),
        "inputs": s.inputs,
        "units": {"length": "mm", "file": s.units},
        "settings": asdict(result.type1.settings if result.type1 else result.grr.settings),
        "type1": None if result.type1 is None else _type1_json(result.type1),
        "grr": None if result.grr is None else _grr_json(result.grr),
        "budget": None if result.budget is None else _budget_json(result.budget),
        "capable": result.capable,
        "notes": list(result.notes),
    }
    return json.dumps(json_safe(doc), indent=2) + "\n"
