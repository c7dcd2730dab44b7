"""Figures of the Bayesian fit: traces, convergence diagnostics and a corner plot
(see `_base.py` for the conventions)."""

from __future__ import annotations

import math

import numpy as np

from ._base import grid_axes, new_figure, param_unit


def trace_figure(posterior, *, max_points: int = 600, walkers_per_ensemble: int = 2):
    """Trace of every parameter after burn-in: the walker mean of each ensemble
    (thick) and a few single walkers (thin)."""
    names = posterior.names
    ens = posterior.ensemble_chains  # (E, S, W, D)
    n_e, n_s = ens.shape[0], ens.shape[1]
    idx = np.unique(np.linspace(0, n_s - 1, min(max_points, n_s)).astype(int))
    step = posterior.burn + idx * posterior.thin
    nrows, ncols = grid_axes(len(names), 4)
    width, height = 11.0, 1.75 * nrows + 0.9
    # margins set in inches rather than by a layout engine: a regular grid whose labels
    # have known sizes (an 8 pt title, a unit, tick labels of a few digits), where
    # constrained layout measured every tick twice (1.0 of the figure's 1.8 s)
    fig = new_figure((width, height), layout=None)
    left, right, top, bottom, gap_w, gap_h = 0.8, 0.15, 0.7, 0.8, 0.8, 0.35
    cell_w = (width - left - right - (ncols - 1) * gap_w) / ncols
    cell_h = (height - top - bottom - (nrows - 1) * gap_h) / nrows
    fig.subplots_adjust(
        left=left / width, right=1 - right / width, top=1 - top / height,
        bottom=bottom / height, wspace=gap_w / cell_w, hspace=gap_h / cell_h,
    )  # fmt: skip
    axs = fig.subplots(nrows, ncols, squeeze=False, sharex=True)
    for j, ax in enumerate(axs.flat):
        if j >= len(names):
            ax.set_visible(False)
            continue
        fac, unit = param_unit(names[j])
        for e in range(n_e):
            for w in range(min(walkers_per_ensemble, ens.shape[2])):
                ax.plot(step, fac * ens[e, idx, w, j], color=f"C{e}", lw=0.4, alpha=0.35)
            ax.plot(
                step,
                fac * ens[e, idx, :, j].mean(axis=1),
                color=f"C{e}",
                lw=1.1,
                label=f"ensemble {e + 1}" if j == 0 else None,
            )
        ax.set_title(names[j], fontsize=8)
        ax.set_ylabel(unit, fontsize=8)
        if j >= len(names) - ncols:
            ax.set_xlabel("step", fontsize=8)
            ax.tick_params(labelbottom=True)
    fig.legend(loc="lower center", ncol=n_e, bbox_to_anchor=(0.5, 0.0))
    fig.suptitle(
        f"Posterior traces after burn-in ({posterior.burn} steps): walker mean per ensemble "
        f"(thick) and {walkers_per_ensemble} walkers each (thin); {n_e} ensembles × "
        f"{posterior.nwalkers} walkers",
        fontsize=10,
    )
    return fig


def diagnostics_figure(posterior):
    """Integrated autocorrelation time, effective sample size and split R-hat per
    parameter, against the thresholds the sampler's verdict uses."""
    names = list(posterior.names)
    y = np.arange(len(names))
    crit = posterior.criteria or {}
    kept = (posterior.nsteps - posterior.burn) / max(posterior.thin, 1) * posterior.thin
    tau_lim = kept / crit.get("tau_factor", 50.0)
    fig = new_figure((11.0, 0.22 * len(names) + 1.9))
    axs = fig.subplots(1, 3, sharey=True)
    panels = [
        (
            posterior.tau,
            tau_lim,
            "τ (steps)",
            "autocorrelation time (limit {:.4g} = kept steps / "
            + f"{crit.get('tau_factor', 50):g})",
            "above",
        ),
        (
            posterior.ess,
            crit.get("min_ess", 400.0),
            "ESS (draws)",
            "effective sample size (minimum {:.4g})",
            "below",
        ),
        (
            posterior.rhat,
            crit.get("rhat_max", 1.01),
            "split R-hat (1)",
            "split R-hat across ensembles (maximum {:.4g})",
            "above",
        ),
    ]
    for ax, (val, lim, xlabel, title, bad_when) in zip(axs, panels, strict=True):
        val = np.asarray(val, dtype=float)
        bad = val > lim if bad_when == "above" else val < lim
        ax.barh(y, val, color=np.where(bad, "C3", "C0"), height=0.7)
        ax.axvline(lim, color="k", ls="--", lw=1)
        ax.set_xlabel(xlabel)
        ax.set_title(title.format(lim), fontsize=8.5)
        ax.grid(axis="y", visible=False)
        if xlabel.startswith("split"):
            lo = min(1.0, float(np.min(val)))
            hi = max(lim, float(np.max(val)))
            ax.set_xlim(lo - 0.1 * (hi - lo) - 1e-4, hi + 0.15 * (hi - lo) + 1e-4)
    axs[0].set_yticks(y, names, fontsize=7.5)
    axs[0].invert_yaxis()
    state = "converged" if posterior.converged else "NOT converged (red bars fail)"
    fig.suptitle(
        f"Convergence diagnostics: {state}; {posterior.nsteps} steps, burn-in {posterior.burn}"
    )
    return fig


def corner_feature(res) -> str | None:
    """The feature the corner plot shows: the measured feature with the most
    parameters (an arc when there is one), first in profile order."""
    if res.bayes is None:
        return None
    names = res.bayes.posterior.names
    best, n_best = None, 0
    for f in res.study.profile.features:
        n = sum(1 for p in f.param_names if f"{f.id}.{p}" in names)
        if n > n_best:
            best, n_best = f.id, n
    return best


def _ellipse(ax, mean, cov, k, **kw):
    vals, vecs = np.linalg.eigh(cov)
    vals = np.maximum(vals, 0.0)
    a = np.linspace(0, 2 * np.pi, 100)
    pts = mean[:, None] + k * vecs @ (np.sqrt(vals)[:, None] * np.vstack([np.cos(a), np.sin(a)]))
    ax.plot(pts[0], pts[1], **kw)


def _corner_data(post, f, ff, max_draws: int, seed: int):
    """Parameter names, display units, draws (display units) and the linearised normal
    `(mean, cov)` of feature `f` from its fit `ff` (None without a covariance)."""
    cols = [post.names.index(f"{f.id}.{p}") for p in f.param_names if f"{f.id}.{p}" in post.names]
    labels = [post.names[c] for c in cols]
    facs = [param_unit(n) for n in labels]
    draws = np.asarray(post.samples)[:, cols]
    if len(draws) > max_draws:
        draws = draws[np.random.default_rng(seed).choice(len(draws), max_draws, replace=False)]
    scale = np.array([fu[0] for fu in facs])
    x = draws * scale
    lin = None
    if ff is not None and ff.covariance is not None:
        names = list(f.param_names)
        sel = [names.index(n.rsplit(".", 1)[-1]) for n in labels]
        lin_mean = np.asarray(ff.values)[sel] * scale
        lin_cov = np.asarray(ff.covariance)[np.ix_(sel, sel)] * np.outer(scale, scale)
        lin = (lin_mean, lin_cov)
    return labels, facs, x, lin


def _corner_diagonal(ax, x, i, lin, labels, facs):
    """Histogram of parameter `i` with its mean and the linearised normal density."""
    from scipy import stats

    ax.hist(x[:, i], bins=50, density=True, color="C0", alpha=0.55)
    if lin is not None:
        lin_mean, lin_cov = lin
        sd = math.sqrt(max(lin_cov[i, i], 0.0))
        if sd > 0:
            g = np.linspace(x[:, i].min(), x[:, i].max(), 200)
            ax.plot(g, stats.norm.pdf(g, lin_mean[i], sd), "k--", lw=1)
    ax.axvline(x[:, i].mean(), color="C0", lw=1.2)
    ax.set_yticks([])
    ax.set_ylabel(f"density (1/{facs[i][1]})", fontsize=8)
    ax.set_xlabel(f"{labels[i].split('.')[-1]} ({facs[i][1]})", fontsize=8)


def _corner_pair(ax, x, i, j, lin, labels, facs):
    """Parameters `j` (horizontal) and `i`: draws, highest-density contours and the
    linearised normal's 86 % ellipse."""
    from scipy import stats

    h, xe, ye = np.histogram2d(x[:, j], x[:, i], bins=40)
    hs = np.sort(h.ravel())[::-1]
    cum = np.cumsum(hs) / hs.sum()
    levels = sorted({hs[np.searchsorted(cum, p)] for p in (0.86, 0.39)})
    ax.plot(x[:3000, j], x[:3000, i], ".", ms=1, color="C0", alpha=0.15)
    if len(levels) >= 1 and levels[-1] > 0:
        ax.contour(
            0.5 * (xe[1:] + xe[:-1]),
            0.5 * (ye[1:] + ye[:-1]),
            h.T,
            levels=levels + [hs[0] + 1],
            colors="C0",
            linewidths=1,
        )
    if lin is not None:
        lin_mean, lin_cov = lin
        sub = np.ix_([j, i], [j, i])
        _ellipse(
            ax,
            lin_mean[[j, i]],
            lin_cov[sub],
            math.sqrt(stats.chi2.ppf(0.86, 2)),
            color="k",
            ls="--",
            lw=1,
        )
    ax.set_ylabel(f"{labels[i].split('.')[-1]} ({facs[i][1]})", fontsize=8)


def corner_figure(res, feature: str | None = None, *, max_draws: int = 20000, seed: int = 0):
    """Corner plot of one feature's posterior (histograms; 39 % and 86 % highest-density
    contours, i.e. 1 and 2 sigma in 2-D) with the robust fit's linearised normal
    approximation overlaid (dashed; the 2-sigma ellipse)."""
    feature = feature or corner_feature(res)
    post = res.bayes.posterior
    f = res.study.profile[feature]
    labels, facs, x, lin = _corner_data(post, f, res.fit.fits.get(f.id), max_draws, seed)
    k = len(labels)
    fig = new_figure((2.5 * k + 1.2, 2.5 * k + 0.8))
    axs = fig.subplots(k, k, squeeze=False)
    for i in range(k):
        for j in range(k):
            ax = axs[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                _corner_diagonal(ax, x, i, lin, labels, facs)
            else:
                _corner_pair(ax, x, i, j, lin, labels, facs)
            if i == k - 1:
                ax.set_xlabel(f"{labels[j].split('.')[-1]} ({facs[j][1]})", fontsize=8)
            if j > 0 and i != j:
                ax.set_ylabel("")
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [
        Patch(color="C0", alpha=0.55, label="posterior (MCMC draws)"),
        Line2D([], [], color="C0", lw=1, label="posterior 39 % / 86 % contours, mean"),
        Line2D([], [], color="k", ls="--", lw=1, label="linearised normal (robust fit), 86 %"),
    ]
    fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(0.98, 0.9), frameon=False)
    fig.suptitle(
        f"Posterior of {feature!r}: MCMC draws (blue; contours 39 % and 86 %) and the "
        "robust fit's linearised normal (dashed)",
        fontsize=10,
    )
    return fig
