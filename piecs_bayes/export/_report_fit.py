"""Report sections on the fit and its uncertainty: profile and adjusted tool path,
residuals, posterior diagnostics, uncertainty budget."""

from __future__ import annotations

import math

import numpy as np

from ._figures import param_unit
from ._figures_budget import budget_figure
from ._figures_posterior import corner_feature, corner_figure, diagnostics_figure, trace_figure
from ._figures_profile import auto_exaggeration, offset_figure, profile_figure
from ._figures_residuals import residuals_figure
from ._report_model import _f, _Fig, _Para, _Table


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
    blocks: list = []
    fac = auto_exaggeration(res)
    blocks.append(
        _Fig(
            "profile",
            lambda: profile_figure(res, exaggeration=fac),
            f"The part as drawn (black), the probe points and fitted features and the adjusted "
            f"tool path with its simultaneous 95 % band; deviations exaggerated × {fac:g} "
            "along the outward normal.",
        )
    )
    if res.uncertainty is not None:
        blocks.append(
            _Fig(
                "offset",
                lambda: offset_figure(res),
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


def _sigma_cell(fit) -> str:
    s = getattr(fit, "sigma", None)
    if s is None:
        return "–"
    dof = "∞" if math.isinf(s.dof) else f"{s.dof:.0f}"
    return f"{s.value * 1e3:.2f} ({s.source}, {dof})"


def _residuals_section(res) -> list:
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
            lambda: residuals_figure(res),
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


def _posterior_table(post) -> _Table:
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
    return _Table(
        ["parameter", "unit", "mean", "sd", "2.5 %", "97.5 %", "τ (steps)", "ESS", "R-hat"],
        rows,
        caption="Posterior summary (* τ not trusted: kept chain shorter than "
        f"{crit.get('tau_factor', 50):g} τ).",
        classes=classes,
    )


def _posterior_section(res) -> list:
    if res.bayes is None:
        why = res.unavailable.get("bayes", "the Bayesian fit was switched off (--no-bayes)")
        return [_Para(f"No Bayesian fit: {why}", "warn")]
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
        _Para(state, "p" if post.converged else "warn"),
        _Para(
            f"Sampler: emcee, {post.n_ensembles} independent ensembles of {post.nwalkers} walkers, "
            f"{post.nsteps} steps each, burn-in {post.burn}, thin {post.thin}; "
            f"{post.wall_time:.1f} s sampling, {post.ess_per_second:.0f} effective samples "
            "per second (smallest ESS). "
            f"Likelihood: {res.bayes.likelihood}."
        ),
        table,
        _Fig(
            "traces",
            lambda: trace_figure(post),
            "Traces after burn-in: mixing and stationarity at a glance; the ensembles should "
            "overlap.",
        ),
        _Fig(
            "diagnostics",
            lambda: diagnostics_figure(post),
            "Autocorrelation time, effective sample size and split R-hat against the limits "
            "of the convergence verdict.",
        ),
    ]
    if feat is not None:
        blocks.append(
            _Fig(
                "corner",
                lambda: corner_figure(res, feat),
                f"Corner plot of {feat!r}: the posterior against the robust fit's linearised "
                "normal approximation.",
            )
        )
    return blocks


def _budget_section(res) -> list:
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
            fac, unit = param_unit(p)
            share = [
                f"{100 * float(budget[s][i]) / tot[i]:.1f}" if tot[i] > 0 else "–" for s in sources
            ]
            rows.append([f"{f.id}.{p}", f"{math.sqrt(max(tot[i], 0)) * fac:.3g} {unit}", *share])
            i += 1
    return [
        _Fig(
            "budget",
            lambda: budget_figure(lin, res.study.profile),
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
