"""Report section on a capability study: indices with their intervals, the
Bayesian Cpk, stability findings and the charts."""

from __future__ import annotations

from ..figures import capability_chart_figure, capability_index_figure
from ..tables import percent
from .model import Fig, Para, Pre, Table, interval_text, num

#: the drawn coordinate in a table cell
_ON = {"diameter": "Ø", "radius": "R", "length": "Z", "normal": "normal"}


def _index_row(fc) -> list[str]:
    """A feature's classical indices with their confidence intervals (lengths in µm as
    drawn, on the feature's coordinate)."""
    c = fc.capability
    lo, hi = fc.tolerance
    return [
        fc.feature,
        _ON.get(fc.coordinate, fc.coordinate),
        fc.characteristic,
        str(c.n),
        f"{lo * 1e3:+g} … {hi * 1e3:+g}",
        num(c.mean, "+.2f"),
        num(c.sigma_within, ".2f"),
        num(c.sigma_overall, ".2f"),
        f"{c.cp:.2f} {interval_text(c.cp_ci)}",
        f"{c.cpk:.2f} {interval_text(c.cpk_ci)}",
        f"{c.pp:.2f} {interval_text(c.pp_ci)}",
        f"{c.ppk:.2f} {interval_text(c.ppk_ci)}",
    ]


def _after_row(fc) -> list[str]:
    """A feature's Bayesian Cpk, stability and the Cpk predicted after compensation."""
    b, p, pw, s = fc.capability.bayes, fc.predicted, fc.predicted_within, fc.stability
    stab = "in control" if s.in_control else f"{len(s.out_of_control)}/{s.n} flagged"
    if fc.step_part:
        stab += f", step before {fc.step_part}"
    return [
        fc.feature,
        "–" if b is None else f"{b.cpk:.2f} {interval_text(b.cpk_interval)}",
        "–" if b is None else f"{b.p_cpk_above:.3f}",
        stab,
        f"{p.cpk:.2f} {interval_text(p.cpk_ci)}",
        f"{pw.cpk:.2f} {interval_text(pw.cpk_ci)}",
    ]


def _process_row(fc) -> list[str]:
    """A feature's measuring process (Q_MP), its indices corrected for the
    measurement's spread, the global risks of judging a part, and the verdict."""
    cc, risks = fc.corrected, fc.risks()
    if risks is None:
        cr = pr = gb = "–"
    else:
        cr, pr = (percent(r) for r in (risks[0].global_consumer_risk,
                                       risks[0].global_producer_risk))  # fmt: skip
        gb = num(risks[1].guard_band, ".2f")
    return [
        fc.feature,
        num(fc.U_mp, ".2f"),
        f"{fc.q_mp:.1%}" + ("" if fc.measuring_process_capable else " (over limit)"),
        "–" if cc is None else f"{cc.cp:.2f}",
        "–" if cc is None else f"{cc.cpk:.2f}",
        cr,
        pr,
        gb,
        f"{fc.verdict}: {fc.verdict_reason()}",
    ]


def capability_section(res) -> list:
    cap = res.capability
    if cap is None:
        why = res.unavailable.get("capability", "switched off")
        return [Para(f"No capability study: {why}", "note")]
    rows = [_index_row(fc) for fc in cap.features.values()]
    rows2 = [_after_row(fc) for fc in cap.features.values()]
    lvl = f"{cap.confidence:.0%}"
    findings = []
    for fc in cap.features.values():
        for line in fc.findings() + list(fc.notes):
            findings.append(f"{fc.feature}: {line}")
    findings += list(cap.notes)
    thr = next(
        (fc.capability.bayes.threshold for fc in cap.features.values() if fc.capability.bayes),
        1.33,
    )
    blocks = [
        Para(
            f"{len(cap.parts)} parts ({cap.parts[0]} … {cap.parts[-1]}), fits {cap.method}; "
            "values: the deviation at each feature's characteristic point, as drawn (on the "
            "diameter Ø for diameters, on Z for faces, along the normal for tapers and arcs), "
            "with the tolerance on the same coordinate."
        ),
        Table(
            [
                "feature",
                "on",
                "at",
                "n",
                "tolerance (µm)",
                "mean (µm)",
                "σ within (µm)",
                "σ overall (µm)",
                f"Cp [{lvl} CI]",
                f"Cpk [{lvl} CI]",
                f"Pp [{lvl} CI]",
                f"Ppk [{lvl} CI]",
            ],
            rows,
            caption="Capability indices: Cp = tolerance width / 6σ (does the spread fit the "
            "tolerance?), Cpk the same from the nearer limit (centring counts); 1.33 is the "
            "usual minimum. Cp, Cpk use the within-run σ (from the moving range of successive "
            "parts), Pp, Ppk the overall σ (drift and steps included). CI: confidence interval "
            "(chi-square and Bissell).",
        ),
        Table(
            [
                "feature",
                "Bayes Cpk [CrI]",
                f"P(Cpk > {thr:g})",
                "stability",
                f"Cpk after [{lvl} CI]",
                f"if stable [{lvl} CI]",
            ],
            rows2,
            caption="Bayes: Cpk from the posterior of the mean and the overall σ (independent "
            "normal values, prior 1/σ) with its equal-tailed credible interval (CrI) and the "
            "probability that Cpk exceeds the threshold. 'Cpk after': the mean moved to the "
            "target by the compensation, overall spread kept; 'if stable': with the within "
            "spread (if compensation also removed drift and steps).",
        ),
        Table(
            [
                "feature",
                "U_MP (µm)",
                "Q_MP",
                "Cp corr.",
                "Cpk corr.",
                "consumer's risk",
                "producer's risk",
                "guard band 2 % (µm)",
                "verdict",
            ],
            [_process_row(fc) for fc in cap.features.values()],
            caption="Can the probe judge the tolerance, and what does judging a part risk? "
            "U_MP = k u_MP, the expanded uncertainty of one measured value (the parts' fit "
            "uncertainties with the study's systematic budget); Q_MP = 2 U_MP / T, at most "
            f"{_limits(cap)} (VDA 5 / ISO 22514-7), else no capability is claimed. 'corr.': "
            "Cp, Cpk with the measurement's share taken off the spread (σp² = σ² − rms(u)²). "
            "Risks: global consumer's and producer's risks of judging a part by its "
            "measured value against the tolerance (JCGM 106, 9.5), and the guard band that "
            "brings the consumer's risk to 2 %. The verdict reads Cpk, or Ppk for a process "
            "not in statistical control.",
        ),
    ]
    if findings:
        blocks.append(Pre(findings, caption="Stability findings and notes"))
    blocks += [
        Fig(
            "capability_chart",
            lambda: capability_chart_figure(cap),
            "Individuals charts over the run (production order) with control limits, "
            "tolerance and the most likely step.",
        ),
        Fig(
            "capability_indices",
            lambda: capability_index_figure(cap),
            "Capability indices with their intervals, and the Cpk predicted after compensation.",
        ),
    ]
    return blocks


def _limits(cap) -> str:
    return ", ".join(sorted({f"{fc.q_mp_limit:.0%}" for fc in cap.features.values()}))
