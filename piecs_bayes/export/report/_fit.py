"""Report sections on the fit and its uncertainty: profile and adjusted tool path,
residuals, posterior diagnostics, uncertainty budget."""

from __future__ import annotations

import math

import numpy as np

from ..figures import (
    auto_exaggeration,
    budget_figure,
    corner_feature,
    corner_figure,
    diagnostics_figure,
    offset_figure,
    param_unit,
    profile_figure,
    residuals_figure,
    trace_figure,
)
from .model import Fig, Para, Table, micro, num


def _vertex_table(res) -> Table:
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
            num(v[0] - n[0], "+.1f", 2e3),
            num(v[1] - n[1], "+.1f"),
            num(sd[0], ".1f", 2e3),
            num(sd[1], ".1f"),
        ]
        if mc is not None:
            row += [num(mc.vertex_sd[k][0], ".1f", 2e3), num(mc.vertex_sd[k][1], ".1f")]
        rows.append(row)
    headers = ["vertex", "nominal Ø (mm)", "nominal Z (mm)", "ΔØ (µm)", "ΔZ (µm)"]
    headers += ["u(Ø) linearised (µm)", "u(Z) linearised (µm)"]
    if mc is not None:
        headers += ["u(Ø) Monte Carlo (µm)", "u(Z) Monte Carlo (µm)"]
    return Table(
        headers,
        rows,
        caption="Adjusted tool-path vertices (the corners of the finish cut): move from "
        "nominal on the diameter and in Z, and standard uncertainty, linearised (GUM: the "
        "Guide to the expression of Uncertainty in Measurement) and by Monte Carlo from the "
        "posterior (JCGM 101).",
    )


def profile_section(res) -> list:
    blocks: list = []
    fac = auto_exaggeration(res)
    blocks.append(
        Fig(
            "profile",
            lambda: profile_figure(res, exaggeration=fac),
            f"The part as drawn (black; vertical axis labelled with diameters) with each "
            f"feature's tolerance zone (red shade), the probe points and fitted features (blue) "
            f"and the adjusted tool path (green) with its simultaneous 95 % band; deviations "
            f"exaggerated × {fac:g} along the outward normal.",
        )
    )
    if res.uncertainty is not None:
        blocks.append(
            Fig(
                "offset",
                lambda: offset_figure(res),
                "Along the nominal contour, every value as drawn (Ø for diameters, Z for faces, "
                "normal for tapers and arcs; µm). Top: the measured part's fitted deviation "
                "(blue) with the tolerance limits (red) and each decision point with ± U "
                "(black). Bottom: the adjusted tool path's change from nominal (the mirrored "
                "deviation times the applied gain) with its pointwise and simultaneous 95 % "
                "bands; the simultaneous band covers the whole path with 95 % probability.",
                full=True,
            )
        )
        blocks.append(_vertex_table(res))
    else:
        why = res.unavailable.get("uncertainty", "switched off")
        blocks.append(Para(f"Tool-path uncertainty not available: {why}", "warn"))
    return blocks


def _sigma_cell(fit) -> str:
    s = getattr(fit, "sigma", None)
    if s is None:
        return "–"
    dof = "∞" if math.isinf(s.dof) else f"{s.dof:.0f}"
    return f"{s.value * 1e3:.2f} ({s.source}, {dof})"


def residuals_section(res) -> list:
    rows = []
    for f in res.fit:
        rows.append(
            [
                f.id,
                str(f.n),
                str(len(f.outliers)),
                ", ".join(str(int(f.lines[i])) for i in f.outliers) or "–",
                num(f.residual_sd, ".2f"),
                str(f.residual_dof),
                _sigma_cell(res.fit),
                f.result.status.name if hasattr(f.result, "status") else "",
            ]
        )
    return [
        Fig(
            "residuals",
            lambda: residuals_figure(res),
            "Residuals (distance of each probe point from the fitted feature, µm) along each "
            "feature; shaded: ±2σ of the probe. Red ×: an outlier (left out of the fit) with "
            "its probe-file line; red ▲ or ▼: an outlier beyond the scale, its value printed.",
        ),
        Table(
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
        Para(
            "Every standard uncertainty uses the probe sigma in the 'sigma used' column, "
            "not a feature's own residual sd (a few points say little about sigma): "
            + (micro(res.fit.sigma.describe()) if res.fit.sigma is not None else "not recorded")
            + ". An expanded uncertainty U is a standard uncertainty times a coverage factor "
            "slightly above 2: the factor grows when the uncertainty rests on few points "
            "(Student-t with the effective degrees of freedom of the combined uncertainty, "
            "Welch-Satterthwaite; docs/uncertainty.md)."
        ),
    ]


def _posterior_table(post) -> Table:
    """Posterior mean, sd, 95 % interval and convergence diagnostics per parameter;
    rows failing a convergence criterion get the class "bad"."""
    lo, hi = post.interval(0.95)
    rows, classes = [], []
    crit = post.criteria or {}
    for j, name in enumerate(post.names):
        fac, unit = param_unit(name)
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
                num(post.mean[j], f"+.{nd}f", fac),
                num(post.sd[j], f".{nd}f", fac),
                num(lo[j], f"+.{nd}f", fac),
                num(hi[j], f"+.{nd}f", fac),
                f"{post.tau[j]:.0f}" + ("" if post.tau_reliable[j] else "*"),
                f"{post.ess[j]:.0f}",
                f"{post.rhat[j]:.4f}",
            ]
        )
        classes.append("" if ok else "bad")
    return Table(
        ["parameter", "unit", "mean", "sd", "2.5 %", "97.5 %", "τ (steps)", "ESS", "R-hat"],
        rows,
        caption="Posterior summary: mean, standard deviation and 95 % interval of each "
        "parameter. τ: autocorrelation time, the steps between nearly independent draws "
        f"(* not trusted: the kept chain is shorter than {crit.get('tau_factor', 50):g} τ); "
        "ESS: effective sample size, the independent draws the chain is worth; R-hat: "
        "agreement of the independent ensembles (1 is perfect; above "
        f"{crit.get('rhat_max', 1.01):g} they disagree). Red rows fail a criterion.",
        classes=classes,
    )


def posterior_section(res) -> list:
    if res.bayes is None:
        why = res.unavailable.get("bayes", "the Bayesian fit was switched off (--no-bayes)")
        return [Para(f"No Bayesian fit: {why}", "warn")]
    post = res.bayes.posterior
    table = _posterior_table(post)
    state = (
        "The run converged: every parameter's split R-hat, effective sample size and "
        "autocorrelation time pass."
        if post.converged
        else "The run has NOT converged; do not trust these numbers: " + "; ".join(post.problems)
    )
    feat = corner_feature(res)
    blocks = [
        Para(state, "p" if post.converged else "warn"),
        Para(
            f"Sampler: {post.sampler}, {post.n_ensembles} independent ensembles of "
            f"{post.nwalkers} walkers, "
            f"{post.nsteps} steps each, burn-in {post.burn}, thin {post.thin}; "
            f"{post.wall_time:.1f} s sampling, {post.ess_per_second:.0f} effective samples "
            "per second (smallest ESS). "
            f"Likelihood: {res.bayes.likelihood}."
        ),
        table,
        Fig(
            "traces",
            lambda: trace_figure(post),
            "Traces after burn-in: mixing and stationarity at a glance; the ensembles should "
            "overlap.",
            full=True,
        ),
        Fig(
            "diagnostics",
            lambda: diagnostics_figure(post),
            "Autocorrelation time, effective sample size and split R-hat against the limits "
            "of the convergence verdict.",
        ),
    ]
    if feat is not None:
        blocks.append(
            Fig(
                "corner",
                lambda: corner_figure(res, feat),
                f"Corner plot of {feat!r}: the posterior against the robust fit's linearised "
                "normal approximation.",
                shrink=1.0,
            )
        )
    return blocks


def budget_section(res) -> list:
    if res.uncertainty is None:
        why = res.unavailable.get("uncertainty", "switched off")
        return [Para(f"No uncertainty budget: {why}", "warn")]
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
            fac, unit = param_unit(p)
            share = [
                f"{100 * float(budget[s][i]) / tot[i]:.1f}" if tot[i] > 0 else "–" for s in sources
            ]
            rows.append([f"{f.id}.{p}", f"{math.sqrt(max(tot[i], 0)) * fac:.3g} {unit}", *share])
            i += 1
    return [
        Fig(
            "budget",
            lambda: budget_figure(lin, res.study.profile),
            "Uncertainty budget (linearised, GUM): which declared source contributes how much "
            "to each fitted parameter and to the adjusted path; the shares sum to the total "
            "variance. Sources: repeatability of the probe, ball_radius (stylus calibration), "
            "pretravel, scale_x / scale_z (axis scale errors), x_centre (centre-line offset), "
            "z_offset (work offset in Z), rotation (of the probe frame).",
            full=True,
        ),
        Table(
            ["parameter", "u", *[f"{s} (%)" for s in sources]],
            rows,
            caption="Variance share of each source (%) per feature parameter.",
        ),
    ]
