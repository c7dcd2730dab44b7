"""Bayesian least squares of a whole profile with the study's error sources.

[`fit_profile_bayes`][] (one part) and [`fit_profiles_bayes`][] (many parts, in
lockstep) sample every feature's deviation (flat priors) together with one nuisance
parameter per declared uncertainty source (`sources`: ball radius, pretravel, work
offsets, axis scales, rotation, thermal, the probe sigma itself), each with its prior.
The likelihood of the ball-centre residuals is Gaussian, or Student-t (`nu`) as the
robust option; the log posterior ([`profile_log_posterior`][]) is one JAX function,
sampled by independent ensembles started around the robust least-squares optimum, with
the lockstep JAX sampler by default or with emcee; same moves, diagnostics and
verdict. The result is a [`BayesProfileFit`][] (draws, diagnostics, `to_arviz`).

The model: docs/models/bayes_fit.md.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..geometry import Profile
from ._inference_data import BayesData, inference_data, pointwise_over_draws, write_netcdf
from ._measurement import SOURCE_EFFECTS, is_calibration_source, probe_residuals, source_unit
from ._options import BAYES_SAMPLING, BayesOptions
from .mcmc import (
    Posterior,
    SamplerOptions,
    check_moves,
    frozen,
    gaussian_loglik,
    prior_from_spec,
    sample_posterior,
    sample_posteriors,
    student_t_loglik,
)

#: Sources that enter the model as a nuisance parameter (``repeatability`` is sigma).
NUISANCE_SOURCES = SOURCE_EFFECTS


@dataclass(frozen=True)
class _Layout:
    """Where each block sits in the flat parameter vector."""

    features: tuple  # ((feature, slice into theta), ...)
    nuisance: tuple  # ((name, index), ...)
    sigma_index: int | None
    names: tuple


def _layout(profile: Profile, measured: tuple[str, ...], sources: dict) -> _Layout:
    names, feats, i = [], [], 0
    for f in profile.features:
        if f.id not in measured:
            continue
        feats.append((f, slice(i, i + f.nparams)))
        names += [f"{f.id}.{p}" for p in f.param_names]
        i += f.nparams
    nuis = []
    cal = sorted((n for n in sources if is_calibration_source(n)), key=lambda n: int(n[10:]))
    for name in (*NUISANCE_SOURCES, *cal):
        if name in sources:
            nuis.append((name, i))
            names.append(name)
            i += 1
    sigma_index = None
    if "repeatability" in sources:
        sigma_index = i
        names.append("sigma")
        i += 1
    return _Layout(tuple(feats), tuple(nuis), sigma_index, tuple(names))


def _freeze(sources: dict) -> tuple:
    return tuple(sorted((k, tuple(sorted(dict(v).items()))) for k, v in sources.items()))


def profile_log_posterior(
    profile: Profile,
    feature_ids,
    *,
    options: BayesOptions,
    with_approach: bool = False,
    weighted: bool = False,
):
    """Build ``(log_prob(theta, args), layout, priors)`` for a profile.

    ``args`` is ``(machine_points, approach)``: the ball centres in machine
    coordinates (radius X) in the order of ``feature_ids`` and, when
    ``with_approach``, the unit approach directions (else ``None``). With
    ``weighted``, ``(machine_points, approach, weights)``: each point's log likelihood
    counts ``weights`` times (0 leaves a point out, so that parts whose points differ
    only in which are left out share one compiled function).
    `options` is the model ([`BayesOptions`][]: the sources' prior specs, the ball
    radius, transform, probe sigma, likelihood and a probe calibration's
    components). The function is cached per structure, so many parts of one study
    share one compiled log posterior.
    """
    m = _model(*_model_key(profile, feature_ids, options, with_approach), weighted)
    return m.log_prob, m.layout, m.priors


def _model_key(profile, feature_ids, options: BayesOptions, with_approach) -> tuple:
    """`_model`'s hashable arguments."""
    return (
        profile,
        tuple(np.asarray(feature_ids).astype(str).tolist()),
        _freeze(options.sources),
        float(options.ball_radius),
        options.transform,
        float(options.sigma),
        options.likelihood,
        float(options.nu),
        bool(with_approach),
        options.file,
        options.radius,
    )


@dataclass(frozen=True)
class _Model:
    """One profile model: its log posterior, its pointwise log likelihood (one value
    per probe point, in the order of `feature_ids`), where each parameter sits and
    the priors of the sources."""

    log_prob: Callable
    pointwise: Callable
    layout: _Layout
    priors: dict


@functools.lru_cache(maxsize=32)
def _model(
    profile,
    feature_ids,
    frozen_sources,
    ball_radius,
    transform,
    sigma,
    likelihood,
    nu,
    with_approach,
    file,
    radius=None,
    weighted=False,
) -> _Model:
    sources = {k: dict(v) for k, v in frozen_sources}  # checked by BayesOptions
    feature_ids = np.asarray(feature_ids).astype(str)
    measured = tuple(f.id for f in profile.features if np.any(feature_ids == f.id))
    priors = {name: prior_from_spec(name, dict(spec), file=file) for name, spec in sources.items()}
    lay = _layout(profile, measured, sources)
    # indices as NumPy: constants of the traces (no program to convert them)
    groups = [(f, sl, np.flatnonzero(feature_ids == f.id)) for f, sl in lay.features]
    base = transform.as_array()
    pairs = [(f, idx) for f, _, idx in groups]
    order = np.concatenate([idx for _, _, idx in groups])

    def log_prior(theta):
        lp = 0.0
        for name, k in lay.nuisance:
            lp = lp + priors[name].log_pdf(theta[k])
        if lay.sigma_index is not None:
            lp = lp + priors["repeatability"].log_pdf(theta[lay.sigma_index])
        return lp

    def residuals(theta, args):
        """The residuals (in `groups` order) and the noise scale of `theta`."""
        points, appr = args[:2]
        r = probe_residuals(
            pairs,
            [theta[sl] for _, sl, _ in groups],
            points,
            {name: theta[k] for name, k in lay.nuisance},
            transform=base,
            ball_radius=ball_radius,
            approach=appr if with_approach else None,
            radius=radius,
        )
        return r, (theta[lay.sigma_index] if lay.sigma_index is not None else sigma)

    def loglik(r, s):
        return gaussian_loglik(r, s) if likelihood == "gaussian" else student_t_loglik(r, s, nu)

    def per_point(r, s):
        return jax.vmap(lambda ri: loglik(ri[None], s))(r)  # the fit's likelihood, per point

    def log_prob(theta, args):
        lp = log_prior(theta)
        if weighted:
            r, s = residuals(theta, args)
            ll = jnp.sum(jnp.asarray(args[2])[order] * per_point(r, s))
        else:
            ll = loglik(*residuals(theta, args))
        return jnp.where(jnp.isfinite(lp), lp + ll, -jnp.inf)

    # what log_prob computes, all of it (the arguments of this cached function): traces
    # of it are kept across processes under this name (`mcmc._core._kept`)
    log_prob.trace_key = ("profile_log_posterior", profile, tuple(feature_ids.tolist()),
                          frozen_sources, ball_radius, transform, sigma, likelihood, nu,
                          with_approach, file, radius, weighted)  # fmt: skip

    def pointwise(theta, args):
        ll = per_point(*residuals(theta, args))
        return jnp.full(feature_ids.size, jnp.nan, dtype=ll.dtype).at[order].set(ll)

    return _Model(log_prob, pointwise, lay, priors)


@dataclass(frozen=True, eq=False)
class BayesProfileFit:
    """Posterior of a profile's deviations and nuisance parameters.

    ``posterior`` is the sampler's :class:`Posterior` (flat samples over
    ``names``); per feature, :meth:`samples` gives its deviation draws and
    ``deviations``/``covariances`` the posterior means and covariances.
    """

    profile: Profile
    posterior: Posterior
    layout: _Layout
    likelihood: str
    part: str | None = None
    data: BayesData | None = None

    @property
    def names(self) -> tuple[str, ...]:
        return self.layout.names

    @property
    def units(self) -> tuple[str, ...]:
        """The unit of each of `names`: mm, rad or 1 (a ratio; `fit.SOURCE_UNITS`)."""
        out = [u for f, _ in self.layout.features for u in f.param_units]
        out += [source_unit(n) for n, _ in self.layout.nuisance]
        return tuple(out + (["mm"] if self.layout.sigma_index is not None else []))

    def samples(self, feature_id: str) -> np.ndarray:
        for f, sl in self.layout.features:
            if f.id == feature_id:
                return np.asarray(self.posterior.samples)[:, sl]
        raise KeyError(f"feature {feature_id!r} was not measured")

    @property
    def deviation_samples(self) -> dict[str, np.ndarray]:
        return {f.id: self.samples(f.id) for f, _ in self.layout.features}

    @property
    def deviations(self) -> dict[str, np.ndarray]:
        return {k: v.mean(axis=0) for k, v in self.deviation_samples.items()}

    @property
    def covariances(self) -> dict[str, np.ndarray]:
        return {
            k: np.atleast_2d(np.cov(v, rowvar=False)) for k, v in self.deviation_samples.items()
        }

    @property
    def nuisance(self) -> dict[str, dict]:
        out = {}
        s = np.asarray(self.posterior.samples)
        idx = [(n, k) for n, k in self.layout.nuisance]
        if self.layout.sigma_index is not None:
            idx.append(("sigma", self.layout.sigma_index))
        for name, k in idx:
            lo, hi = np.quantile(s[:, k], [0.025, 0.975])
            out[name] = {
                "mean": float(s[:, k].mean()),
                "sd": float(s[:, k].std(ddof=1)),
                "q2.5": float(lo),
                "q97.5": float(hi),
            }
        return out

    def rows(self) -> list[dict]:
        """One row per parameter (posterior.csv): posterior mean, sd and 95 % interval
        in the row's `unit`."""
        s = np.asarray(self.posterior.samples)
        lo, hi = np.quantile(s, [0.025, 0.975], axis=0)
        return [
            {
                "part": self.part or "",
                "parameter": n,
                "unit": unit,
                "mean": float(s[:, i].mean()),
                "sd": float(s[:, i].std(ddof=1)),
                "q2.5": float(lo[i]),
                "q97.5": float(hi[i]),
            }
            for i, (n, unit) in enumerate(zip(self.names, self.units, strict=True))
        ]

    def log_likelihood(self) -> np.ndarray:
        """Log likelihood of each probe point (in the order of `data`) at every kept
        draw, `(chain, draw, point)` in the layout of `posterior.arviz_chains`: the
        fit's own likelihood (Gaussian or Student-t) point by point, `jax.vmap`-ed
        over draws; summed over points, the log likelihood the sampler saw. NaN for
        a point of a feature outside the profile."""
        m, d = self._model(), self._data()
        chains = self.posterior.arviz_chains
        k, n, dim = chains.shape
        args = (
            jnp.asarray(d.machine_points),
            None if d.approach is None else jnp.asarray(d.approach),
        )
        ll = pointwise_over_draws(m.pointwise, chains.reshape(k * n, dim), args)
        return ll.reshape(k, n, -1)

    def to_arviz(self):
        """ArviZ `InferenceData`: posterior (variables with feature dims and units),
        sample_stats, observed_data, log_likelihood (for `az.loo`) and prior, with
        the run's settings in attrs; the layout is `piecs_bayes.fit._inference_data`'s
        (docs/formats.md, posterior.nc). `posterior.to_arviz()` is the plain form
        (one scalar variable per parameter name)."""
        return inference_data(self, self._data(), self.log_likelihood(), self._model().priors)

    def to_netcdf(self, path) -> str:
        """Write `to_arviz()` to a netCDF file (`arviz.from_netcdf` reads it). For a
        file that appears whole or not at all, write through
        `piecs_bayes.io.write_file_atomic(path, fit.to_netcdf)` (the CLI does)."""
        return write_netcdf(self.to_arviz(), path)

    def _data(self) -> BayesData:
        if self.data is None:
            raise InputError(
                "this BayesProfileFit holds no data (made without fit_profile_bayes or "
                "fit_profiles_bayes); use fit.posterior.to_arviz() for the draws alone"
            )
        return self.data

    def _model(self) -> _Model:
        d = self._data()
        options = BayesOptions(
            sources=d.sources, ball_radius=d.ball_radius, sigma=d.sigma, transform=d.transform,
            likelihood=self.likelihood, nu=d.nu, radius=d.radius, file=d.file,
        )  # fmt: skip
        return _model(*_model_key(self.profile, d.feature_ids, options, d.approach is not None))

    def __repr__(self) -> str:
        head = (
            f"BayesProfileFit({self.likelihood}, {len(self.names)} parameters, part={self.part!r})"
        )
        return f"{head}\n{self.posterior!r}"


def fit_profile_bayes(
    profile: Profile,
    feature_ids,
    machine_points,
    *,
    start: dict,
    start_cov: dict | None = None,
    options: BayesOptions,
    sampling: SamplerOptions = BAYES_SAMPLING,
    approach=None,
    part: str | None = None,
    lines=None,
) -> BayesProfileFit:
    """Sample the posterior of a profile's deviations and nuisance parameters.

    **Arguments:**

    - `feature_ids`, `machine_points`: per trigger, feature and ball centre
      (machine frame, radius X, mm); outliers need not be removed when
      ``likelihood="student_t"``.
    - `start`, `start_cov`: least-squares deviations and covariances per
      feature id: the walkers start in a ball around them.
    - `options`: the model ([`BayesOptions`][]): the study's uncertainty sources
      (prior specs), the ball radius and transform, the known probe repeatability
      `sigma` (used unless ``repeatability`` is a source, in which case it is
      estimated with that prior), the likelihood, and the probe calibration's
      `RadiusComponents` (`radius`) when the sources hold its components
      (``probe_cal_<j>``, nuisance parameters with normal priors).
    - `sampling`: the sampler's [`SamplerOptions`][] (see :func:`sample_posterior`);
      by default `BAYES_SAMPLING`: the lockstep JAX sampler (``"lockstep"``; emcee
      with ``sampler="emcee"``), 3,000 steps, differential-evolution moves (the
      nuisance parameters make the posterior correlated).
    - `lines`: the file line of each trigger (kept for the fit's `to_arviz()`).

    **Returns:** a :class:`BayesProfileFit`.
    """
    o = options
    log_prob, lay, priors = profile_log_posterior(
        profile, feature_ids, options=o, with_approach=approach is not None
    )
    x0, _ = _start(lay, priors, start, start_cov, o.sigma)
    post = sample_posterior(
        log_prob,
        x0,
        names=lay.names,
        cov0=None,
        args=(jnp.asarray(machine_points), None if approach is None else jnp.asarray(approach)),
        options=sampling,
    )
    data = BayesData(
        feature_ids=frozen(np.asarray(feature_ids).astype(str)),
        machine_points=frozen(np.asarray(machine_points, dtype=float)),
        approach=None if approach is None else frozen(np.asarray(approach, dtype=float)),
        lines=None if lines is None else frozen(np.asarray(lines)),
        sources={k: dict(v) for k, v in o.sources.items()}, ball_radius=float(o.ball_radius),
        transform=o.transform, sigma=float(o.sigma), nu=float(o.nu), file=o.file,
        sampler=post.sampler, moves=check_moves(sampling.moves), radius=o.radius,
    )  # fmt: skip
    return BayesProfileFit(profile, post, lay, o.likelihood, part, data)


def _start(lay: _Layout, priors: dict, start: dict, start_cov: dict | None, sigma: float):
    """The walkers' start `x0` (least-squares deviations, prior means, `sigma`) and
    per-parameter variances around it (not used: the sampler takes the inverse
    Hessian at `x0`)."""
    dim = len(lay.names)
    x0 = np.zeros(dim)
    var0 = np.zeros(dim)
    for f, sl in lay.features:
        x0[sl] = np.asarray(start[f.id])
        c = None if start_cov is None else start_cov.get(f.id)
        var0[sl] = np.diag(c) if c is not None else 1e-6
    for name, k in lay.nuisance:
        x0[k] = priors[name].mean
        var0[k] = priors[name].sd ** 2
    if lay.sigma_index is not None:
        x0[lay.sigma_index] = sigma
        var0[lay.sigma_index] = (0.1 * sigma) ** 2
    return x0, np.where(var0 > 0, var0, 1e-12)


def fit_profiles_bayes(
    profile,
    part_ids,
    feature_ids,
    machine_points,
    *,
    starts,
    options: BayesOptions,
    sampling: SamplerOptions = BAYES_SAMPLING,
    approach=None,
    lines=None,
    inlier=None,
):
    """[`fit_profile_bayes`][] for many parts: parts with the same pattern of
    triggers (feature of each point, in order) share one compiled log posterior
    and are sampled together by [`sample_posteriors`][] (the lockstep sampler:
    `sampling.sampler` is not read).

    **Arguments:** `part_ids`, `feature_ids`, `machine_points` (and `approach`)
    (and `lines`) per trigger, as in `fit_profile_bayes`; `starts`: `{part: {feature: deviation}}`
    (e.g. `BatchFit.values`); `inlier`: a boolean per trigger, the points to fit (e.g.
    not `BatchFit.outlier_mask`; default all): the others weigh 0 in the likelihood,
    so parts that differ only in which points they leave out still share one compiled
    log posterior (a part that would leave every point of a feature out is fitted on
    its inliers alone, that feature unmeasured); `options`, `sampling`: as
    `fit_profile_bayes` (each group of parts gets the seed `sampling.seed` plus its
    number).

    **Returns:** `{part: BayesProfileFit}` in the order of first appearance.
    """
    o = options
    part_ids = np.asarray(part_ids).astype(str)
    feature_ids = np.asarray(feature_ids).astype(str)
    machine_points = np.asarray(machine_points, dtype=float)
    keep = np.ones(part_ids.size, bool) if inlier is None else np.asarray(inlier, bool)
    order = list(dict.fromkeys(part_ids.tolist()))
    patterns: dict[tuple, list[str]] = {}
    rows_of = {}  # the rows sampled (inliers and, weighted, the points weighing 0)
    for p in order:
        rows = np.flatnonzero(part_ids == p)
        ids, w = feature_ids[rows], keep[rows]
        weighted = inlier is not None and set(ids[w]) == set(ids)
        rows_of[p] = rows if weighted else rows[w]
        patterns.setdefault((tuple(feature_ids[rows_of[p]].tolist()), weighted), []).append(p)
    out = {}
    for g, ((pattern, weighted), parts) in enumerate(patterns.items()):
        log_prob, lay, priors = profile_log_posterior(
            profile, pattern, options=o, with_approach=approach is not None, weighted=weighted
        )
        x0 = np.zeros((len(parts), len(lay.names)))
        for i, p in enumerate(parts):
            for f, sl in lay.features:
                x0[i, sl] = np.asarray(starts[p][f.id])
            for name, k in lay.nuisance:
                x0[i, k] = priors[name].mean
            if lay.sigma_index is not None:
                x0[i, lay.sigma_index] = o.sigma
        pts = np.stack([machine_points[rows_of[p]] for p in parts])
        appr = None if approach is None else np.stack([approach[rows_of[p]] for p in parts])
        args = (pts, appr) + ((np.stack([keep[rows_of[p]] * 1.0 for p in parts]),) * weighted)
        posts = sample_posteriors(
            log_prob, x0, names=lay.names, args=args,
            options=replace(sampling, seed=sampling.seed + g),
        )  # fmt: skip
        for p, post in zip(parts, posts, strict=True):
            r = rows_of[p][keep[rows_of[p]]]  # the points fitted
            data = BayesData(
                feature_ids=feature_ids[r], machine_points=machine_points[r],
                approach=None if approach is None else np.asarray(approach)[r],
                lines=None if lines is None else np.asarray(lines)[r], sources=dict(o.sources),
                ball_radius=float(o.ball_radius), transform=o.transform, sigma=float(o.sigma),
                nu=float(o.nu), file=o.file, sampler=post.sampler,
                moves=check_moves(sampling.moves), radius=o.radius,
            )  # fmt: skip
            out[p] = BayesProfileFit(profile, post, lay, o.likelihood, p, data)
    return {p: out[p] for p in order}
