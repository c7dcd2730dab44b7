"""The job report: a [`JobResults`][piecs_bayes.workflow.JobResults] as one
self-contained HTML file and as a PDF.

Both are pure writers (`results -> str` / `results -> bytes`): they read the
bundle and never re-fit. The content is built once as a list of sections, each
a list of blocks (paragraphs, tables, preformatted text, figures), and rendered
twice: to HTML (figures embedded as base64 PNG, no external resource) and to PDF
(matplotlib `PdfPages`, A4 landscape: text pages for the tables and one page
per figure). Sections, in order (`SECTIONS`): summary, profile and adjusted
tool path, residuals, posterior diagnostics, uncertainty budget, capability,
adjusted part program, error specification and tool offsets, inputs.

A section whose step was not run or could not be done is kept, with the reason.
"""

from __future__ import annotations

import base64
import html
import io
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..fit._sigma import coverage_factor

__all__ = [
    "SECTIONS",
    "report_html",
    "report_pdf",
    "report_files",
    "summary_rows",
    "summary_html",
]

#: (id, title) of the report's sections, in order
SECTIONS = (
    ("summary", "Summary"),
    ("profile", "Profile and adjusted tool path"),
    ("residuals", "Residuals"),
    ("posterior", "Posterior diagnostics"),
    ("budget", "Uncertainty budget"),
    ("capability", "Capability"),
    ("program", "Adjusted part program"),
    ("errspec", "Error specification and tool offsets"),
    ("inputs", "Inputs and reproducibility"),
)


# --------------------------------------------------------------------------- blocks


@dataclass
class _Para:
    text: str
    kind: str = "p"  # "p" | "note" | "warn"


@dataclass
class _Table:
    headers: list[str]
    rows: list[list[str]]
    caption: str = ""
    classes: list[str] = field(default_factory=list)  # per row css class ("" for none)
    short: list[str] | None = None  # headers of the PDF's narrower text tables


@dataclass
class _Pre:
    lines: list[str]
    caption: str = ""
    diff: bool = False


@dataclass
class _Fig:
    name: str
    make: Callable
    caption: str


def _f(x, fmt="+.2f", scale=1e3) -> str:
    """A number in display units, or an en dash when missing."""
    if x is None:
        return "–"
    try:
        x = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not math.isfinite(x):
        return "–"
    return format(x * scale, fmt)


def _ci(iv, fmt=".2f") -> str:
    lo, hi = iv
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "–"
    return f"[{lo:{fmt}}, {hi:{fmt}}]"


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
        from ..decisions import characteristics

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


def summary_html(res) -> str:
    """The summary table alone, as an HTML fragment (notebooks)."""
    return _render_html_block(_summary_table(res))


# --------------------------------------------------------------------------- sections


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


def _vertex_table(res) -> _Table:
    lin = res.uncertainty["linearised"]
    mc = res.uncertainty.get("monte_carlo")
    nom = res.study.profile.vertices
    rows = []
    for k, (v, n) in enumerate(zip(lin.vertices, nom, strict=True)):
        sd = lin.vertex_sd[k]
        row = [
            str(k),
            f"{2 * n[0]:.3f}",
            f"{n[1]:.3f}",
            _f(v[0] - n[0]),
            _f(v[1] - n[1]),
            _f(sd[0], ".2f"),
            _f(sd[1], ".2f"),
        ]
        if mc is not None:
            row += [_f(mc.vertex_sd[k][0], ".2f"), _f(mc.vertex_sd[k][1], ".2f")]
        rows.append(row)
    headers = ["vertex", "nominal Ø (mm)", "nominal Z (mm)", "ΔX radius (µm)", "ΔZ (µm)"]
    headers += ["u(X) GUM (µm)", "u(Z) GUM (µm)"]
    if mc is not None:
        headers += ["u(X) MC (µm)", "u(Z) MC (µm)"]
    return _Table(
        headers,
        rows,
        caption="Adjusted tool-path vertices (part frame, X as radius for the moves): move "
        "from nominal and standard uncertainty, linearised (GUM) and Monte Carlo from the "
        "posterior (JCGM 101).",
    )


def _profile_section(res) -> list:
    from . import _figures as F

    blocks: list = []
    fac = F.auto_exaggeration(res)
    blocks.append(
        _Fig(
            "profile",
            lambda: F.profile_figure(res, exaggeration=fac),
            f"The part as drawn (black), the probe points and fitted features and the adjusted "
            f"tool path with its simultaneous 95 % band; deviations exaggerated × {fac:g} "
            "along the outward normal.",
        )
    )
    if res.uncertainty is not None:
        blocks.append(
            _Fig(
                "offset",
                lambda: F.offset_figure(res),
                "Normal offset of the adjusted tool path from nominal along the contour (µm): "
                "the mirrored fitted deviation, its pointwise and simultaneous 95 % bands. The "
                "simultaneous band covers the whole path with 95 % probability.",
            )
        )
        blocks.append(_vertex_table(res))
    else:
        why = res.unavailable.get("uncertainty", "switched off")
        blocks.append(_Para(f"Tool-path uncertainty not available: {why}", "warn"))
    return blocks


#: coverage probability of a k = 2 interval under the normal (JCGM 100 G.6)
K2_COVERAGE = 0.9544997361036416


def _sigma_cell(fit) -> str:
    s = getattr(fit, "sigma", None)
    if s is None:
        return "–"
    dof = "∞" if math.isinf(s.dof) else f"{s.dof:.0f}"
    return f"{s.value * 1e3:.2f} ({s.source}, {dof})"


def _residuals_section(res) -> list:
    from . import _figures as F

    rows = []
    for f in res.fit:
        rows.append(
            [
                f.id,
                str(f.n),
                str(len(f.outliers)),
                ", ".join(str(int(f.lines[i])) for i in f.outliers) or "–",
                _f(f.residual_sd, ".2f"),
                str(f.residual_dof),
                _sigma_cell(res.fit),
                f.result.status.name if hasattr(f.result, "status") else "",
            ]
        )
    return [
        _Fig(
            "residuals",
            lambda: F.residuals_figure(res),
            "Residuals (distance of each probe point from the fitted feature, µm) along each "
            "feature; red crosses are outliers with their probe-file line.",
        ),
        _Table(
            [
                "feature",
                "points",
                "outliers",
                "outlier lines",
                "residual sd (µm)",
                "residual dof",
                "sigma used (µm, source, dof)",
                "solver",
            ],
            rows,
        ),
        _Para(
            "Every standard uncertainty uses the probe sigma in the 'sigma used' column, "
            "not a feature's own residual sd (a few points say little about sigma): "
            + (res.fit.sigma.describe() if res.fit.sigma is not None else "not recorded")
            + ". Expanded uncertainties use Student-t coverage factors with "
            "Welch-Satterthwaite effective degrees of freedom (docs/uncertainty.md)."
        ),
    ]


def _posterior_section(res) -> list:
    from . import _figures as F

    if res.bayes is None:
        why = res.unavailable.get("bayes", "the Bayesian fit was switched off (--no-bayes)")
        return [_Para(f"No Bayesian fit: {why}", "warn")]
    post = res.bayes.posterior
    lo, hi = post.interval(0.95)
    rows, classes = [], []
    crit = post.criteria or {}
    for j, name in enumerate(post.names):
        fac, unit = F.param_unit(name)
        nd = 0 if unit == "µrad" else 2
        ok = (
            post.rhat[j] <= crit.get("rhat_max", 1.01)
            and post.ess[j] >= crit.get("min_ess", 400)
            and bool(post.tau_reliable[j])
        )
        rows.append(
            [
                name,
                unit,
                _f(post.mean[j], f"+.{nd}f", fac),
                _f(post.sd[j], f".{nd}f", fac),
                _f(lo[j], f"+.{nd}f", fac),
                _f(hi[j], f"+.{nd}f", fac),
                f"{post.tau[j]:.0f}" + ("" if post.tau_reliable[j] else "*"),
                f"{post.ess[j]:.0f}",
                f"{post.rhat[j]:.4f}",
            ]
        )
        classes.append("" if ok else "bad")
    state = (
        "The run converged: every parameter's split R-hat, effective sample size and "
        "autocorrelation time pass."
        if post.converged
        else "The run has NOT converged; do not trust these numbers: " + "; ".join(post.problems)
    )
    feat = F.corner_feature(res)
    blocks = [
        _Para(state, "p" if post.converged else "warn"),
        _Para(
            f"Sampler: emcee, {post.n_ensembles} independent ensembles of {post.nwalkers} walkers, "
            f"{post.nsteps} steps each, burn-in {post.burn}, thin {post.thin}; "
            f"{post.wall_time:.1f} s sampling, {post.ess_per_second:.0f} effective samples "
            "per second (smallest ESS). "
            f"Likelihood: {res.bayes.likelihood}."
        ),
        _Table(
            ["parameter", "unit", "mean", "sd", "2.5 %", "97.5 %", "τ (steps)", "ESS", "R-hat"],
            rows,
            caption="Posterior summary (* τ not trusted: kept chain shorter than "
            f"{crit.get('tau_factor', 50):g} τ).",
            classes=classes,
        ),
        _Fig(
            "traces",
            lambda: F.trace_figure(post),
            "Traces after burn-in: mixing and stationarity at a glance; the ensembles should "
            "overlap.",
        ),
        _Fig(
            "diagnostics",
            lambda: F.diagnostics_figure(post),
            "Autocorrelation time, effective sample size and split R-hat against the limits "
            "of the convergence verdict.",
        ),
    ]
    if feat is not None:
        blocks.append(
            _Fig(
                "corner",
                lambda: F.corner_figure(res, feat),
                f"Corner plot of {feat!r}: the posterior against the robust fit's linearised "
                "normal approximation.",
            )
        )
    return blocks


def _budget_section(res) -> list:
    from . import _figures as F

    if res.uncertainty is None:
        why = res.unavailable.get("uncertainty", "switched off")
        return [_Para(f"No uncertainty budget: {why}", "warn")]
    lin = res.uncertainty["linearised"]
    budget = lin.deviation_budget or {}
    sources = [s for s in budget if s != "total"]
    rows = []
    i = 0
    tot = np.asarray(budget.get("total", []), dtype=float)
    for f in res.study.profile.features:
        for p in f.param_names:
            if i >= len(tot):
                break
            fac, unit = F.param_unit(p)
            share = [
                f"{100 * float(budget[s][i]) / tot[i]:.1f}" if tot[i] > 0 else "–" for s in sources
            ]
            rows.append([f"{f.id}.{p}", f"{math.sqrt(max(tot[i], 0)) * fac:.3g} {unit}", *share])
            i += 1
    return [
        _Fig(
            "budget",
            lambda: F.budget_figure(lin, res.study.profile),
            "Uncertainty budget (linearised, GUM): which declared source contributes how much "
            "to each fitted parameter and to the adjusted path; the shares sum to the total "
            "variance.",
        ),
        _Table(
            ["parameter", "u", *[f"{s} (%)" for s in sources]],
            rows,
            caption="Variance share of each source (%) per feature parameter.",
        ),
    ]


def _capability_section(res) -> list:
    from . import _figures as F

    cap = res.capability
    if cap is None:
        why = res.unavailable.get("capability", "switched off")
        return [_Para(f"No capability study: {why}", "note")]
    rows, rows2 = [], []
    lvl = f"{cap.confidence:.0%}"
    for fc in cap.features.values():
        c, b, p, pw, s = (
            fc.capability,
            fc.capability.bayes,
            fc.predicted,
            fc.predicted_within,
            fc.stability,
        )
        stab = "in control" if s.in_control else f"{len(s.out_of_control)}/{s.n} flagged"
        if fc.step_part:
            stab += f", step before {fc.step_part}"
        rows.append(
            [
                fc.feature,
                fc.characteristic,
                str(c.n),
                _f(c.mean),
                _f(c.sigma_within, ".2f"),
                _f(c.sigma_overall, ".2f"),
                f"{c.cp:.2f} {_ci(c.cp_ci)}",
                f"{c.cpk:.2f} {_ci(c.cpk_ci)}",
                f"{c.pp:.2f} {_ci(c.pp_ci)}",
                f"{c.ppk:.2f} {_ci(c.ppk_ci)}",
            ]
        )
        rows2.append(
            [
                fc.feature,
                "–" if b is None else f"{b.cpk:.2f} {_ci(b.cpk_interval)}",
                "–" if b is None else f"{b.p_cpk_above:.3f}",
                stab,
                f"{p.cpk:.2f} {_ci(p.cpk_ci)}",
                f"{pw.cpk:.2f} {_ci(pw.cpk_ci)}",
            ]
        )
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
        _Para(
            f"{len(cap.parts)} parts ({cap.parts[0]} … {cap.parts[-1]}), fits {cap.method}; "
            "values: normal deviation at each feature's characteristic point."
        ),
        _Table(
            [
                "feature",
                "at",
                "n",
                "mean (µm)",
                "σ within (µm)",
                "σ overall (µm)",
                f"Cp [{lvl} CI]",
                f"Cpk [{lvl} CI]",
                f"Pp [{lvl} CI]",
                f"Ppk [{lvl} CI]",
            ],
            rows,
            caption="Capability indices. Cp, Cpk: within sigma (moving range), chi-square and "
            "Bissell intervals; Pp, Ppk: overall sigma.",
        ),
        _Table(
            [
                "feature",
                "Bayes Cpk [CrI]",
                f"P(Cpk > {thr:g})",
                "stability",
                f"Cpk after [{lvl} CI]",
                f"if stable [{lvl} CI]",
            ],
            rows2,
            caption="Bayes: i.i.d. normal values, prior 1/σ (overall spread), equal-tailed "
            "credible interval. 'Cpk after': the mean moved to the target by the compensation, "
            "overall spread kept; 'if stable': with the within spread (if compensation also "
            "removed drift and steps).",
        ),
    ]
    if findings:
        blocks.append(_Pre(findings, caption="Stability findings and notes"))
    blocks += [
        _Fig(
            "capability_chart",
            lambda: F.capability_chart_figure(cap),
            "Individuals charts over the run (production order) with control limits, "
            "tolerance and the most likely step.",
        ),
        _Fig(
            "capability_indices",
            lambda: F.capability_index_figure(cap),
            "Capability indices with their intervals, and the Cpk predicted after compensation.",
        ),
    ]
    return blocks


def _program_section(res) -> list:
    adj = res.program
    if adj is None:
        why = res.unavailable.get("program", "switched off")
        return [
            _Para(
                f"No adjusted part program: {why}",
                "warn" if "program" in res.unavailable else "note",
            )
        ]
    study = res.study
    rows = [
        [
            str(c.line),
            c.feature or "(approach)",
            c.old.strip(),
            c.new.strip(),
            _f(c.shift_mm, ".1f"),
        ]
        for c in adj.changes
    ]
    nose = (
        f"checked for gouges with a nose radius of {res.nose_radius:g} mm"
        if res.nose_radius is not None
        else "not checked with the nose radius (give one: [offsets] current_r or --nose-radius)"
    )
    return [
        _Para(
            f"{study.program.name}: {len(adj.changes)} blocks rewritten, largest end-point move "
            f"{adj.max_shift_mm * 1e3:.1f} µm (limit {study.compensation.max_correction * 1e3:g} "
            f"µm); every other line is byte-identical; {nose}. Mapping of blocks to features: "
            + ", ".join(f"{k} {list(v)}" for k, v in adj.mapping.features.items())
            + "."
        ),
        _Table(
            ["line", "feature", "original", "adjusted", "end moved (µm)"],
            rows,
            caption="Rewritten blocks.",
        ),
        _Pre(adj.diff.splitlines(), caption="Unified diff against the original program", diff=True),
    ]


def _errspec_section(res) -> list:
    blocks: list = []
    spec = res.errspec
    if spec is None:
        why = res.unavailable.get("errspec", "switched off")
        blocks.append(_Para(f"No error specification: {why}", "warn"))
    else:
        rows = []
        for t in spec.tables:
            pos = np.asarray(t.position, dtype=float)
            corr = np.asarray(t.correction, dtype=float)
            u = np.asarray(t.u_correction, dtype=float)
            rows.append(
                [
                    t.name,
                    f"{t.axis.upper()} vs {t.position_axis.upper()}",
                    str(len(pos)),
                    f"{pos.min():.3f} … {pos.max():.3f}",
                    _f(float(np.max(np.abs(corr))), ".2f"),
                    _f(float(np.max(u)), ".2f"),
                    "yes" if t.axis == t.position_axis else "no (depends on another axis)",
                ]
            )
        blocks += [
            _Para(
                f"{spec.description}. Corrections are −gain × error along the corrected machine "
                "axis, machine positions, X as radius (native format: compensation.errspec.json "
                "and one CSV per table)."
            ),
            _Table(
                [
                    "table",
                    "corrects",
                    "rows",
                    "positions (mm)",
                    "max |correction| (µm)",
                    "max u (µm)",
                    "LinuxCNC joint table",
                ],
                rows,
            ),
        ]
    upd = res.offsets
    if upd is None:
        blocks.append(_Para("No tool-offset update.", "note"))
    else:
        rows = []
        for a in upd.axes:
            if a.error is None:
                rows.append([a.axis.upper(), "not measured", "–", "–", "–"])
                continue
            rows.append(
                [
                    a.axis.upper(),
                    f"{_f(a.error)} ± {_f(a.u_error, '.2f')}",
                    f"{_f(a.correction)} ± {_f(a.u_correction, '.2f')}",
                    a.status,
                    a.reason,
                ]
            )
        state = "BLOCKED" if upd.blocked else ("update" if upd.any_update else "no change")
        blocks += [
            _Para(
                f"Tool-offset (wear) update for tool {upd.tool}: {state}; X as {upd.x_mode} (µm)."
            ),
            _Table(["axis", "error ± u (µm)", "correction ± u (µm)", "status", "why"], rows),
        ]
        notes = list(upd.reasons) + list(res.offset_notes)
        if notes:
            blocks.append(_Pre([f"- {n}" for n in notes], caption="Notes"))
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


_BUILDERS = {
    "summary": _summary_section,
    "profile": _profile_section,
    "residuals": _residuals_section,
    "posterior": _posterior_section,
    "budget": _budget_section,
    "capability": _capability_section,
    "program": _program_section,
    "errspec": _errspec_section,
    "inputs": _inputs_section,
}


def _sections(res):
    return [(sid, title, _BUILDERS[sid](res)) for sid, title in SECTIONS]


# --------------------------------------------------------------------------- HTML

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;
max-width:1180px;margin:0 auto;padding:1em 1.5em;color:#222;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;
margin-top:2em}nav ol{columns:3;font-size:.95em}
table{border-collapse:collapse;margin:.6em 0 1em;font-size:.86em}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top}
th{background:#f2f2f2}td.num{text-align:right;font-variant-numeric:tabular-nums}
caption{caption-side:bottom;text-align:left;font-size:.92em;color:#555;padding-top:.3em}
tr.compensate td{background:#fff4e0}tr.measure-more td{background:#e8f0ff}
tr.bad td{background:#ffe5e5}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:.92em;color:#555}
pre{background:#f7f7f7;border:1px solid #e3e3e3;padding:.6em;overflow-x:auto;font-size:.82em}
pre .add{color:#0a6b0a;background:#eaffea}pre .del{color:#a00;background:#ffecec}
pre .hunk{color:#555}
p.warn{background:#fff0f0;border-left:4px solid #c33;padding:.4em .6em}
p.note{background:#f4f4f4;border-left:4px solid #999;padding:.4em .6em}
"""


def _is_num(s: str) -> bool:
    s = s.replace("±", "").replace("[", "").replace("]", "").replace(",", " ").strip()
    try:
        [float(t) for t in s.split() if t not in ("–",)]
    except ValueError:
        return False
    return bool(s)


def _render_html_block(b, png: dict | None = None) -> str:
    e = html.escape
    if isinstance(b, _Para):
        cls = "" if b.kind == "p" else f' class="{b.kind}"'
        return f"<p{cls}>{e(b.text)}</p>"
    if isinstance(b, _Table):
        head = "".join(f"<th>{e(h)}</th>" for h in b.headers)
        body = []
        for k, row in enumerate(b.rows):
            cls = b.classes[k] if k < len(b.classes) and b.classes[k] else ""
            cells = "".join(
                f'<td class="num">{e(c)}</td>' if _is_num(c) else f"<td>{e(c)}</td>" for c in row
            )
            body.append(f'<tr class="{cls}">{cells}</tr>' if cls else f"<tr>{cells}</tr>")
        cap = f"<caption>{e(b.caption)}</caption>" if b.caption else ""
        return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"
    if isinstance(b, _Pre):
        out = []
        for line in b.lines:
            t = e(line)
            if b.diff and line.startswith("+") and not line.startswith("+++"):
                t = f'<span class="add">{t}</span>'
            elif b.diff and line.startswith("-") and not line.startswith("---"):
                t = f'<span class="del">{t}</span>'
            elif b.diff and line.startswith("@@"):
                t = f'<span class="hunk">{t}</span>'
            out.append(t)
        cap = f"<p><strong>{e(b.caption)}</strong></p>" if b.caption else ""
        return f"{cap}<pre>{chr(10).join(out)}</pre>"
    if isinstance(b, _Fig):
        data = (png or {}).get(b.name)
        if data is None:
            data = _png(b.make())
        src = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
        return (
            f'<figure id="fig-{b.name}"><img alt="{e(b.caption)}" src="{src}">'
            f"<figcaption>{e(b.caption)}</figcaption></figure>"
        )
    raise TypeError(f"unknown report block {b!r}")


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def _html(res, sections, png) -> str:
    e = html.escape
    title = f"piecs_bayes report: {res.study.name}"
    nav = "".join(f'<li><a href="#{sid}">{e(t)}</a></li>' for sid, t, _ in sections)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{e(title)}</title><style>{_CSS}</style></head><body>",
        f"<header><h1>{e(title)}</h1>",
        f"<p>Part {e(str(res.part or '–'))} · {e(res.created)} · piecs_bayes "
        f"{e(res.versions.get('piecs_bayes', '?'))} · lengths in mm, deviations in µm, X of "
        "the part frame as radius unless marked Ø</p>",
        f"<nav><ol>{nav}</ol></nav></header>",
    ]
    for k, (sid, t, blocks) in enumerate(sections, start=1):
        parts.append(f'<section id="{sid}"><h2>{k}. {e(t)}</h2>')
        parts += [_render_html_block(b, png) for b in blocks]
        parts.append("</section>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def report_html(res) -> str:
    """The report as one self-contained HTML document (figures as base64 PNG)."""
    from matplotlib import rc_context

    from ._figures import RC

    with rc_context(RC):
        return _html(res, _sections(res), {})


# --------------------------------------------------------------------------- PDF


def _table_lines(t: _Table) -> list[str]:
    import textwrap

    headers = t.short or t.headers
    w = [len(h) for h in headers]
    for row in t.rows:
        w = [max(a, len(c)) for a, c in zip(w, row, strict=False)]
    w = [min(x, 66) for x in w]

    def fmt(cells):
        out = []
        for c, x in zip(cells, w, strict=False):
            c = c if len(c) <= x else c[: x - 1] + "…"
            out.append(c.rjust(x) if _is_num(c) else c.ljust(x))
        return "  ".join(out).rstrip()

    lines = textwrap.wrap(t.caption, 160) if t.caption else []
    lines += [fmt(headers), "  ".join("-" * x for x in w)]
    lines += [fmt(r) for r in t.rows]
    return lines


def _block_lines(b) -> list[str]:
    import textwrap

    if isinstance(b, _Para):
        prefix = "! " if b.kind == "warn" else ""
        return textwrap.wrap(prefix + b.text, 160) + [""]
    if isinstance(b, _Table):
        return _table_lines(b) + [""]
    if isinstance(b, _Pre):
        return ([b.caption + ":"] if b.caption else []) + list(b.lines) + [""]
    return []


def _pdf_pages(res, sections, on_figure=None):
    """Yield the PDF's pages as Figures (and call `on_figure(name, fig)` for figures)."""
    from ._figures import text_pages

    footer = f"piecs_bayes report · {res.study.name} · part {res.part or '–'} · {res.created}"
    for k, (sid, t, blocks) in enumerate(sections, start=1):
        head = f"{k}. {t}"
        lines: list[str] = []
        for b in blocks:
            lines += _block_lines(b)
        if lines:
            sub = f"{res.study.name}, part {res.part or '–'}" if sid == "summary" else ""
            yield from text_pages(head, lines, subtitle=sub, footer=footer)
        for b in blocks:
            if isinstance(b, _Fig):
                fig = b.make()
                if on_figure is not None:
                    on_figure(b.name, fig)
                old = fig.get_suptitle()
                fig.suptitle(f"{head}\n{old}" if old else head, fontsize=11)
                yield fig


def _pdf(pages, res) -> bytes:
    from matplotlib.backends.backend_pdf import PdfPages

    buf = io.BytesIO()
    meta = {
        "Title": f"piecs_bayes report: {res.study.name}",
        "Author": "piecs_bayes",
        "Subject": f"part {res.part}",
        "Creator": f"piecs_bayes {res.versions.get('piecs_bayes', '')}",
    }
    with PdfPages(buf, metadata=meta) as pdf:
        for fig in pages:
            pdf.savefig(fig)
    return buf.getvalue()


def report_pdf(res) -> bytes:
    """The report as PDF bytes (A4 landscape; text pages for tables, one page per figure)."""
    from matplotlib import rc_context

    from ._figures import RC

    with rc_context(RC):
        return _pdf(_pdf_pages(res, _sections(res)), res)


def report_files(res) -> tuple[str, bytes]:
    """`(html, pdf)` with every figure drawn once (what the CLI writes)."""
    from matplotlib import rc_context

    from ._figures import RC

    png: dict[str, bytes] = {}
    with rc_context(RC):
        sections = _sections(res)

        def keep(name, fig):
            png[name] = _png(fig)

        pdf = _pdf(_pdf_pages(res, sections, on_figure=keep), res)
        text = _html(res, sections, png)
    return text, pdf
