"""Figures of a job's results (matplotlib), for reports and notebooks.

Every function takes a [`JobResults`][piecs_bayes.workflow.JobResults] (or the
part of it it draws) and returns a `matplotlib.figure.Figure` made without
`pyplot`: nothing here selects a backend or keeps figures alive, so the
functions are safe in scripts, servers and notebooks (a notebook displays a
returned figure). matplotlib is imported inside the functions.

Conventions: Z (along the spindle axis) is horizontal and X (radius) vertical,
as on the drawing; lengths of the part in mm, deviations in µm, rotations in
µrad, axis scale errors in ppm. Deviations on the profile drawing are
exaggerated by a factor stated in its title.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "RC",
    "auto_exaggeration",
    "profile_figure",
    "offset_figure",
    "residuals_figure",
    "trace_figure",
    "diagnostics_figure",
    "corner_figure",
    "corner_feature",
    "budget_figure",
    "capability_chart_figure",
    "capability_index_figure",
    "text_pages",
    "param_unit",
]

#: rcParams the report is drawn with (readable at A4 landscape and on screen)
RC = {
    "font.size": 9,
    "axes.titlesize": 9.5,
    "axes.labelsize": 9,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 8,
    "figure.titlesize": 12,
    "figure.dpi": 100,
    "savefig.dpi": 110,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "pdf.fonttype": 42,  # TrueType: the PDF's text can be searched and extracted
    "svg.fonttype": "none",
}

_SOURCE_COLOURS = {
    "repeatability": "#4C72B0",
    "ball_radius": "#DD8452",
    "pretravel": "#937860",
    "x_centre": "#55A868",
    "z_offset": "#8C8C8C",
    "scale_x": "#C44E52",
    "scale_z": "#8172B3",
    "rotation": "#DA8BC3",
    "thermal": "#CCB974",
}


def param_unit(name: str) -> tuple[float, str]:
    """Display factor and unit of a parameter (`"dia_24.offset"`, `"scale_x"`, ...)."""
    base = name.rsplit(".", 1)[-1]
    if base == "rotation":
        return 1e6, "µrad"
    if base in ("scale_x", "scale_z", "thermal"):
        return 1e6, "ppm"
    return 1e3, "µm"


def _figure(figsize, **kw):
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained", **kw)


def _nice(x: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above `x` (at least 1)."""
    if not math.isfinite(x) or x <= 1:
        return 1.0
    k = math.floor(math.log10(x))
    for m in (5, 2, 1):
        if m * 10**k <= x:
            return float(m * 10**k)
    return float(10**k)


def _normal_deviation(feature, dev, q):
    """Normal deviation (mm, + outward) of the deviated feature at nominal points `q`."""
    import jax.numpy as jnp

    return -np.asarray(feature.signed_distance(jnp.asarray(q), jnp.asarray(dev, dtype=float)))


def auto_exaggeration(res) -> float:
    """A round factor (1, 2 or 5 x 10^k) that draws the largest deviation (fitted
    features, inlier probe points, the adjusted path's band) at about 1/6 of the
    part's radial extent. Outliers are left out: a chip would shrink everything else."""
    prof = res.study.profile
    pts = np.vstack([np.asarray(f.point_at(np.linspace(0, 1, 5))) for f in prof.features])
    extent = max(float(np.ptp(pts[:, 0])), 1e-3)
    big = 0.0
    for f in res.fit:
        keep = np.ones(f.n, dtype=bool)
        keep[np.asarray(f.outliers, dtype=int)] = False
        if keep.any():
            big = max(big, float(np.max(np.abs(np.asarray(f.error_vectors)[keep]))))
    if res.uncertainty is not None:
        b = res.uncertainty["linearised"].bands
        big = max(big, float(np.max(np.abs(b.simultaneous_lower))))
        big = max(big, float(np.max(np.abs(b.simultaneous_upper))))
    if big <= 0:
        return 1.0
    return _nice(extent / 6 / big)


def _contour_s(profile, grid):
    """Arc length (mm) along the nominal contour of each grid point, and feature starts."""
    lengths = np.array([f.length for f in profile.features])
    starts = np.concatenate([[0.0], np.cumsum(lengths)])
    return starts[grid.feature] + grid.t * lengths[grid.feature], starts


def _label_features(ax, profile, starts):
    """Feature boundaries as dotted lines and the ids above the axes (staggered
    where neighbours are short)."""
    from matplotlib.transforms import blended_transform_factory

    tr = blended_transform_factory(ax.transData, ax.transAxes)
    total = max(starts[-1] - starts[0], 1e-9)
    raised = False
    for k, f in enumerate(profile.features):
        ax.axvline(starts[k], color="0.5", lw=0.6, ls=":")
        short = (starts[k + 1] - starts[k]) / total < 0.1
        raised = short and not raised
        ax.text(
            (starts[k] + starts[k + 1]) / 2,
            1.055 if raised else 1.01,
            f.id,
            transform=tr,
            ha="center",
            va="bottom",
            fontsize=7.5,
            clip_on=False,
        )
    ax.axvline(starts[-1], color="0.5", lw=0.6, ls=":")


# --------------------------------------------------------------------------- profile


def profile_figure(res, exaggeration: float | None = None):
    """The profile as drawn, the measured points and fitted features, and the
    adjusted tool path with its simultaneous 95 % band, deviations exaggerated."""
    fig = _figure((10.5, 5.0))
    ax = fig.add_subplot()
    prof = res.study.profile
    fac = exaggeration or auto_exaggeration(res)
    t = np.linspace(0.0, 1.0, 80)
    fits = res.fit.fits
    all_x = np.concatenate([np.asarray(f.point_at(t))[:, 0] for f in prof.features])
    label_gap = 0.22 * max(float(np.ptp(all_x)), 1.0)
    unc = None if res.uncertainty is None else res.uncertainty["linearised"]
    first = {"nominal": True, "fit": True, "meas": True, "out": True, "band": True, "path": True}

    def once(key, label):
        if first[key]:
            first[key] = False
            return label
        return None

    for i, f in enumerate(prof.features):
        q = np.asarray(f.point_at(t))
        n = np.asarray(f.outward_normal(q))
        ax.plot(q[:, 1], q[:, 0], color="k", lw=1.4, label=once("nominal", "nominal profile"))
        mid = q[len(q) // 2] + n[len(q) // 2] * label_gap
        ax.annotate(
            f.id, (mid[1], mid[0]), fontsize=8, ha="center", va="center", color="0.25", zorder=5
        )
        ff = fits.get(f.id)
        if ff is not None:
            d = _normal_deviation(f, ff.values, q)
            p = q + fac * d[:, None] * n
            ax.plot(
                p[:, 1], p[:, 0], color="C0", lw=1.0, label=once("fit", "fitted feature (exagg.)")
            )
            meas = np.asarray(ff.nominal_points) + fac * np.asarray(ff.error_vectors)
            keep = np.ones(ff.n, dtype=bool)
            keep[np.asarray(ff.outliers, dtype=int)] = False
            ax.plot(
                meas[keep, 1],
                meas[keep, 0],
                "o",
                ms=3,
                color="C0",
                alpha=0.8,
                label=once("meas", "probe points (exagg.)"),
            )
            if (~keep).any():
                ax.plot(
                    meas[~keep, 1],
                    meas[~keep, 0],
                    "x",
                    ms=7,
                    mew=1.8,
                    color="C3",
                    label=once("out", "outliers (exagg.)"),
                )
        if unc is not None:
            sel = unc.grid.feature == i
            g, nn = unc.grid.points[sel], unc.grid.normals[sel]
            lo = g + fac * unc.bands.simultaneous_lower[sel, None] * nn
            hi = g + fac * unc.bands.simultaneous_upper[sel, None] * nn
            poly = np.vstack([lo, hi[::-1]])
            ax.fill(
                poly[:, 1],
                poly[:, 0],
                color="C2",
                alpha=0.3,
                lw=0,
                label=once("band", "simultaneous 95 % band (exagg.)"),
            )
            c = g + fac * unc.offset[sel, None] * nn
            ax.plot(
                c[:, 1],
                c[:, 0],
                color="C2",
                lw=1.6,
                label=once("path", "adjusted tool path (exagg.)"),
            )
    if unc is None and res.path is not None:
        v = prof.vertices + fac * (np.asarray(res.path.vertices) - prof.vertices)
        ax.plot(v[:, 1], v[:, 0], "-", color="C2", lw=1.6, label="adjusted tool path (exagg.)")
    z_all = np.concatenate([np.asarray(f.point_at(t))[:, 1] for f in prof.features])
    ax.plot(
        [z_all.min(), z_all.max()], [0.0, 0.0], color="0.4", lw=0.8, ls="-.", label="spindle axis"
    )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("Z (mm, along the spindle axis)")
    ax.set_ylabel("X (mm, radius)")
    ax.set_title(
        f"Profile, measured part and adjusted tool path (part frame); deviations exaggerated "
        f"× {fac:g}"
    )
    ax.legend(loc="lower left", framealpha=0.9)
    return fig


def offset_figure(res):
    """Normal offset of the adjusted tool path from nominal along the contour, with
    its pointwise and simultaneous 95 % bands (linearised and Monte Carlo)."""
    fig = _figure((10.5, 4.6))
    ax = fig.add_subplot()
    prof = res.study.profile
    lin = res.uncertainty["linearised"]
    mc = res.uncertainty.get("monte_carlo")
    s, starts = _contour_s(prof, lin.grid)
    um = 1e3
    b = lin.bands
    for i, f in enumerate(prof.features):
        sel = lin.grid.feature == i
        lab = i == 0
        ax.fill_between(
            s[sel],
            um * b.simultaneous_lower[sel],
            um * b.simultaneous_upper[sel],
            color="C2",
            alpha=0.2,
            lw=0,
            label="simultaneous 95 % (GUM)" if lab else None,
        )
        ax.fill_between(
            s[sel],
            um * b.pointwise_lower[sel],
            um * b.pointwise_upper[sel],
            color="C2",
            alpha=0.35,
            lw=0,
            label="pointwise 95 % (GUM)" if lab else None,
        )
        ax.plot(
            s[sel], um * lin.offset[sel], color="C2", lw=1.5, label="adjusted path" if lab else None
        )
        ff = res.fit.fits.get(f.id)
        if ff is not None:
            d = _normal_deviation(f, ff.values, lin.grid.points[sel])
            ax.plot(
                s[sel],
                um * d,
                color="0.35",
                lw=1.0,
                ls="--",
                label="fitted deviation of the part" if lab else None,
            )
        if mc is not None:
            mb = mc.bands
            ax.plot(
                s[sel],
                um * mb.simultaneous_lower[sel],
                color="C4",
                lw=0.9,
                ls=":",
                label="simultaneous 95 % (Monte Carlo)" if lab else None,
            )
            ax.plot(s[sel], um * mb.simultaneous_upper[sel], color="C4", lw=0.9, ls=":")
    _label_features(ax, prof, starts)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlim(starts[0], starts[-1])
    ax.set_xlabel("position along the nominal contour from its start (mm)")
    ax.set_ylabel("normal offset from nominal (µm, + outward)")
    title = (
        f"Adjusted tool path: offset with 95 % bands (pointwise k = "
        f"{float(np.median(b.crit_pointwise)):.2f}, simultaneous k = {b.crit_simultaneous:.2f})"
    )
    ax.set_title(title, pad=26)
    fig.legend(loc="outside lower center", ncol=5)
    return fig


# --------------------------------------------------------------------------- residuals


def _along(feature, q):
    """Distance (mm) along the nominal feature from its start of nominal points `q`."""
    q = np.asarray(q, dtype=float)
    if feature.kind == "line":
        p0, p1 = np.array(feature.p0), np.array(feature.p1)
        d = (p1 - p0) / np.linalg.norm(p1 - p0)
        return (q - p0) @ d
    c = np.array(feature.center)
    a0 = math.atan2(feature.p0[0] - c[0], feature.p0[1] - c[1])
    a = np.arctan2(q[:, 0] - c[0], q[:, 1] - c[1])
    da = np.angle(np.exp(1j * (a - a0)))
    return np.abs(da) * feature.radius


def _grid(n, ncols):
    return max(1, math.ceil(n / ncols)), min(n, ncols)


def residuals_figure(res):
    """Residuals of every fitted feature along it, outliers marked with their file line."""
    fits = list(res.fit)
    nrows, ncols = _grid(len(fits), 4)
    fig = _figure((11.0, 2.35 * nrows + 0.7))
    axs = fig.subplots(nrows, ncols, squeeze=False)
    sigma = res.study.probe.repeatability * 1e3
    for k, ax in enumerate(axs.flat):
        if k >= len(fits):
            ax.set_visible(False)
            continue
        ff = fits[k]
        x = _along(ff.feature, ff.nominal_points)
        r = np.asarray(ff.residuals) * 1e3
        keep = np.ones(ff.n, dtype=bool)
        keep[np.asarray(ff.outliers, dtype=int)] = False
        ax.axhline(0.0, color="k", lw=0.7)
        ax.axhspan(-2 * sigma, 2 * sigma, color="C0", alpha=0.08, lw=0)
        ax.plot(x[keep], r[keep], "o", ms=3.5, color="C0")
        inl = np.abs(r[keep]) if keep.any() else np.zeros(1)
        lim = max(3 * sigma, float(np.max(inl)) * 1.3)
        for j in np.flatnonzero(~keep):
            clipped = abs(r[j]) > 0.9 * lim
            yj = math.copysign(0.85 * lim, r[j]) if clipped else r[j]
            marker = ("^" if r[j] > 0 else "v") if clipped else "x"
            ax.plot(x[j], yj, marker, ms=8, mew=2, color="C3")
            ax.annotate(
                f"line {int(ff.lines[j])}: {r[j]:+.1f} µm" + (" (off scale)" if clipped else ""),
                (x[j], yj),
                xytext=(0, -12 if r[j] > 0 else 6),
                textcoords="offset points",
                ha="right" if x[j] > 0.6 * ff.feature.length else "left",
                fontsize=7.5,
                color="C3",
            )
        ax.set_ylim(-lim, lim)
        s_txt = (
            f"s = {ff.residual_sd * 1e3:.2f} µm ({ff.residual_dof} dof)"
            if np.isfinite(ff.residual_sd)
            else "no residual dof"
        )
        ax.set_title(f"{ff.id}: {ff.n} points, {s_txt}", fontsize=8.5)
        ax.set_xlabel("along feature (mm)", fontsize=8)
        ax.set_ylabel("residual (µm)", fontsize=8)
    fig.suptitle(
        f"Residuals per feature ({res.fit.method} fit); shaded: ±2σ of the probe "
        f"(σ = {sigma:.2f} µm); red: outliers (probe-file line; triangles: off scale)"
    )
    return fig


# --------------------------------------------------------------------------- posterior


def trace_figure(posterior, *, max_points: int = 600, walkers_per_ensemble: int = 2):
    """Trace of every parameter after burn-in: the walker mean of each ensemble
    (thick) and a few single walkers (thin)."""
    names = posterior.names
    ens = posterior.ensemble_chains  # (E, S, W, D)
    n_e, n_s = ens.shape[0], ens.shape[1]
    idx = np.unique(np.linspace(0, n_s - 1, min(max_points, n_s)).astype(int))
    step = posterior.burn + idx * posterior.thin
    nrows, ncols = _grid(len(names), 4)
    fig = _figure((11.0, 1.75 * nrows + 0.9))
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
    fig.legend(loc="outside lower center", ncol=n_e)
    fig.suptitle(
        f"Posterior traces after burn-in ({posterior.burn} steps): walker mean per ensemble "
        f"(thick) and {walkers_per_ensemble} walkers each (thin); {n_e} ensembles × "
        f"{posterior.nwalkers} walkers"
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
    fig = _figure((11.0, 0.22 * len(names) + 1.9))
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


def corner_figure(res, feature: str | None = None, *, max_draws: int = 20000, seed: int = 0):
    """Corner plot of one feature's posterior (histograms; 39 % and 86 % highest-density
    contours, i.e. 1 and 2 sigma in 2-D) with the robust fit's linearised normal
    approximation overlaid (dashed; the 2-sigma ellipse)."""
    from scipy import stats

    feature = feature or corner_feature(res)
    post = res.bayes.posterior
    f = res.study.profile[feature]
    cols = [post.names.index(f"{f.id}.{p}") for p in f.param_names if f"{f.id}.{p}" in post.names]
    labels = [post.names[c] for c in cols]
    facs = [param_unit(n) for n in labels]
    draws = np.asarray(post.samples)[:, cols]
    if len(draws) > max_draws:
        draws = draws[np.random.default_rng(seed).choice(len(draws), max_draws, replace=False)]
    scale = np.array([fu[0] for fu in facs])
    x = draws * scale
    ff = res.fit.fits.get(f.id)
    lin_mean = lin_cov = None
    if ff is not None and ff.covariance is not None:
        names = list(f.param_names)
        sel = [names.index(n.rsplit(".", 1)[-1]) for n in labels]
        lin_mean = np.asarray(ff.values)[sel] * scale
        lin_cov = np.asarray(ff.covariance)[np.ix_(sel, sel)] * np.outer(scale, scale)
    k = len(cols)
    fig = _figure((2.5 * k + 1.2, 2.5 * k + 0.8))
    axs = fig.subplots(k, k, squeeze=False)
    for i in range(k):
        for j in range(k):
            ax = axs[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(x[:, i], bins=50, density=True, color="C0", alpha=0.55)
                if lin_mean is not None:
                    sd = math.sqrt(max(lin_cov[i, i], 0.0))
                    if sd > 0:
                        g = np.linspace(x[:, i].min(), x[:, i].max(), 200)
                        ax.plot(g, stats.norm.pdf(g, lin_mean[i], sd), "k--", lw=1)
                ax.axvline(x[:, i].mean(), color="C0", lw=1.2)
                ax.set_yticks([])
                ax.set_ylabel(f"density (1/{facs[i][1]})", fontsize=8)
                ax.set_xlabel(f"{labels[i].split('.')[-1]} ({facs[i][1]})", fontsize=8)
            else:
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
                if lin_mean is not None:
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
            if i == k - 1:
                ax.set_xlabel(f"{labels[j].split('.')[-1]} ({facs[j][1]})", fontsize=8)
            if j > 0 and i != j:
                ax.set_ylabel("")
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [
        Patch(color="C0", alpha=0.55, label="posterior (emcee draws)"),
        Line2D([], [], color="C0", lw=1, label="posterior 39 % / 86 % contours, mean"),
        Line2D([], [], color="k", ls="--", lw=1, label="linearised normal (robust fit), 86 %"),
    ]
    fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(0.98, 0.9), frameon=False)
    fig.suptitle(
        f"Posterior of {feature!r}: emcee draws (blue; contours 39 % and 86 %) and the "
        "robust fit's linearised normal (dashed)",
        fontsize=10,
    )
    return fig


# --------------------------------------------------------------------------- budget


def budget_figure(tpu, profile):
    """Uncertainty budget (linearised): share of each source in the variance of every
    feature parameter, and the variance of the path offset along the contour by source."""
    budget = tpu.deviation_budget
    sources = [s for s in budget if s != "total"]
    rows, totals = [], []
    for f in profile.features:
        for p in f.param_names:
            rows.append(f"{f.id}.{p}")
    tot = np.asarray(budget["total"], dtype=float)
    n = min(len(rows), len(tot))
    rows = rows[:n]
    for i, r in enumerate(rows):
        fac, unit = param_unit(r)
        totals.append(f"{r}  (u = {math.sqrt(max(tot[i], 0.0)) * fac:.3g} {unit})")
    fig = _figure((10.5, 0.23 * n + 5.3))
    gs = fig.add_gridspec(2, 1, height_ratios=[0.23 * n + 1.0, 3.4])
    ax = fig.add_subplot(gs[0])
    left = np.zeros(n)
    y = np.arange(n)
    for s in sources:
        share = np.where(tot[:n] > 0, np.asarray(budget[s], dtype=float)[:n] / tot[:n], 0.0) * 100
        ax.barh(y, share, left=left, color=_SOURCE_COLOURS.get(s), label=s, height=0.75)
        left += share
    ax.set_yticks(y, totals, fontsize=7.5)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("share of the variance (%)")
    ax.set_title("Feature parameters: variance share by source (linearised, GUM)")
    ax.grid(axis="y", visible=False)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), title="source")
    ax2 = fig.add_subplot(gs[1])
    s_along, starts = _contour_s(profile, tpu.grid)
    ob = tpu.offset_budget or {}
    base = np.zeros(len(s_along))
    for s in sources:
        if s not in ob:
            continue
        v = np.asarray(ob[s], dtype=float) * 1e6
        for i in range(len(profile)):
            sel = tpu.grid.feature == i
            ax2.fill_between(
                s_along[sel],
                base[sel],
                base[sel] + v[sel],
                color=_SOURCE_COLOURS.get(s),
                lw=0,
                label=s if i == 0 else None,
            )
        base = base + v
    _label_features(ax2, profile, starts)
    ax2.set_xlim(starts[0], starts[-1])
    ax2.set_ylim(bottom=0)
    ax2.set_xlabel("position along the nominal contour from its start (mm)")
    ax2.set_ylabel("variance of the path offset (µm²)")
    ax2.set_title("Adjusted tool path: variance of the normal offset by source", pad=26)
    return fig


# --------------------------------------------------------------------------- capability


def capability_chart_figure(cap):
    """Individuals charts of every feature's characteristic over the run, with
    the control limits, the tolerance, flagged parts and the most likely step."""
    feats = list(cap.features.values())
    nrows, ncols = _grid(len(feats), 2)
    fig = _figure((11.0, 2.3 * nrows + 0.8))
    axs = fig.subplots(nrows, ncols, squeeze=False)
    for k, ax in enumerate(axs.flat):
        if k >= len(feats):
            ax.set_visible(False)
            continue
        fc = feats[k]
        s = fc.stability
        x = np.arange(1, len(fc.values) + 1)
        v = np.asarray(fc.values) * 1e3
        ax.plot(x, v, "-o", ms=3, lw=0.8, color="C0")
        flagged = sorted(set(s.beyond_limits) | set(s.run_points) | set(s.trend_points))
        if flagged:
            ax.plot(x[flagged], v[flagged], "o", ms=5, mfc="none", mec="C3", mew=1.4)
        ax.axhline(s.center * 1e3, color="k", lw=0.8)
        ax.axhline(s.ucl * 1e3, color="C1", lw=0.9, ls="--")
        ax.axhline(s.lcl * 1e3, color="C1", lw=0.9, ls="--")
        lo, hi = fc.tolerance
        ax.axhline(lo * 1e3, color="C3", lw=1.0)
        ax.axhline(hi * 1e3, color="C3", lw=1.0)
        if fc.step_part:
            ax.axvline(s.step_index + 0.5, color="C4", lw=1.2, ls=":")
            ax.annotate(
                f"step before {fc.step_part}",
                (s.step_index + 0.5, 0.95),
                xycoords=("data", "axes fraction"),
                fontsize=7.5,
                color="C4",
                ha="left",
                va="top",
            )
        c = fc.capability
        ax.set_title(f"{fc.feature} ({fc.characteristic}): Cpk {c.cpk:.2f}, Ppk {c.ppk:.2f}")
        ax.set_ylabel("deviation (µm)", fontsize=8)
        ax.set_xlabel("part (production order)", fontsize=8)
    fig.suptitle(
        "Individuals charts: normal deviation per part; dashed: 3σ control limits "
        "(moving range); red: tolerance; circles: flagged parts"
    )
    return fig


def capability_index_figure(cap):
    """Cpk with its confidence interval, Ppk, the Bayesian Cpk with its credible
    interval and the Cpk predicted after compensation, per feature."""
    feats = list(cap.features.values())
    fig = _figure((10.5, 0.5 * len(feats) + 1.8))
    ax = fig.add_subplot()
    y = np.arange(len(feats))
    off = {"cpk": -0.27, "ppk": -0.09, "bayes": 0.09, "after": 0.27}
    thr = 1.33

    def bar(k, val, iv, dy, colour, marker, label):
        lo, hi = iv
        if math.isfinite(lo) and math.isfinite(hi):
            ax.plot([lo, hi], [k + dy] * 2, color=colour, lw=1.4)
        ax.plot(val, k + dy, marker, color=colour, ms=5, label=label if k == 0 else None)

    for k, fc in enumerate(feats):
        c, b, p = fc.capability, fc.capability.bayes, fc.predicted
        bar(k, c.cpk, c.cpk_ci, off["cpk"], "C0", "o", f"Cpk, {cap.confidence:.0%} CI")
        bar(k, c.ppk, c.ppk_ci, off["ppk"], "C1", "s", f"Ppk, {cap.confidence:.0%} CI")
        if b is not None:
            thr = b.threshold
            bar(k, b.cpk, b.cpk_interval, off["bayes"], "C2", "D", "Bayes Cpk, credible interval")
        bar(k, p.cpk, p.cpk_ci, off["after"], "C4", "^", "Cpk predicted after compensation")
    ax.axvline(thr, color="k", ls="--", lw=1)
    ax.axvline(1.0, color="0.5", ls=":", lw=1)
    ax.set_yticks(y, [fc.feature for fc in feats])
    ax.invert_yaxis()
    ax.set_xlabel("capability index (dimensionless)")
    ax.set_title(f"Capability indices per feature; dashed: {thr:g}, dotted: 1")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


# --------------------------------------------------------------------------- text pages


def text_pages(
    title: str,
    lines,
    *,
    subtitle: str = "",
    footer: str = "",
    width: int = 165,
    lines_per_page: int = 50,
):
    """Monospaced text on A4 landscape pages (tables, diffs): a list of Figures.

    Lines longer than `width` characters wrap with an indent; `title` heads every
    page ("(continued)" after the first).
    """
    import textwrap

    wrapped: list[str] = []
    for line in lines:
        line = line.expandtabs(4).rstrip("\n")
        if len(line) <= width:
            wrapped.append(line)
        else:
            wrapped += textwrap.wrap(
                line, width, subsequent_indent="    ", break_long_words=True, drop_whitespace=False
            )
    pages = [wrapped[i : i + lines_per_page] for i in range(0, len(wrapped), lines_per_page)]
    pages = pages or [[]]
    figs = []
    for k, chunk in enumerate(pages):
        fig = _figure((11.69, 8.27))
        fig.set_layout_engine("none")
        fig.text(
            0.05,
            0.95,
            title + (" (continued)" if k else ""),
            fontsize=13,
            weight="bold",
            va="top",
        )
        if subtitle and not k:
            fig.text(0.05, 0.915, subtitle, fontsize=9, va="top", color="0.3")
        fig.text(
            0.05,
            0.885,
            "\n".join(chunk),
            family="monospace",
            fontsize=7.3,
            va="top",
            linespacing=1.3,
        )
        if footer:
            fig.text(0.05, 0.03, footer, fontsize=7.5, color="0.4")
        figs.append(fig)
    return figs
