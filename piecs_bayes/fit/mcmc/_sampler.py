r"""Bayesian least squares with emcee: sampling, likelihoods and convergence checks.

[`sample_posterior`][] samples a JAX log posterior `log_prob(theta, args)` (log prior
plus log likelihood, `-inf` outside the support) with `n_ensembles` independent
ensembles started around `x0`: with emcee (`vectorize=True`, the log posterior jitted
and vmapped over walkers) or, with `sampler="lockstep"`, the same ensembles and moves in
one jitted JAX loop (`_lockstep`). It returns a [`Posterior`][] with its diagnostics:
split $\hat R$ with one chain per ensemble, emcee's $\tau$, the effective sample size.
Convergence is checked, not assumed: a run is `converged` when every parameter has a
trusted $\tau$ ($S \ge 50\,\tau$ kept steps), $\hat R \le 1.01$ and ESS $\ge 400$;
otherwise a [`ConvergenceWarning`][] (or, with `on_fail="raise"`, a
[`ConvergenceError`][]) says which numbers failed. [`gaussian_loglik`][] and
[`student_t_loglik`][] are the likelihoods.

Why several ensembles, and the diagnostics: docs/models/sampling.md.
"""

from __future__ import annotations

import functools
import sys
import time
import warnings
from dataclasses import replace
from typing import Any

import jax
import numpy as np

from ...errors import AnalysisError, InputError
from ._core import (
    ConvergenceError,
    ConvergenceWarning,
    diagnose,
    sqrt_psd,
    start_cov,
)
from ._diagnostics import problems as _problems
from ._lockstep import sample_posteriors
from ._moves import emcee_moves
from ._options import SamplerOptions
from ._posterior import Posterior, emcee_module, make_posterior


@functools.lru_cache(maxsize=64)
def _vectorised(log_prob):
    """``log_prob`` jitted and vmapped over walkers, cached per function so that
    repeated runs (many parts of one model) compile once."""
    return jax.jit(jax.vmap(log_prob, in_axes=(0, None)))


def sample_posterior(
    log_prob,
    x0,
    *,
    names,
    cov0=None,
    args: Any = None,
    options: SamplerOptions = SamplerOptions(),
) -> Posterior:
    """Sample a posterior from independent ensembles started around `x0`, with emcee
    or the lockstep JAX sampler.

    **Arguments:**

    - `log_prob`: `log_prob(theta, args) -> scalar`, a JAX-traceable log posterior
      (up to a constant), `-inf` outside the support. NaN is treated as `-inf`.
    - `x0`: start, shape `(dim,)`: the least-squares (or MAP) optimum.
    - `names`: `dim` parameter names.
    - `cov0`: covariance of the start ball, `(dim, dim)` or variances `(dim,)`,
      e.g. the least-squares covariance; default: the inverse Hessian of
      `-log_prob` at `x0`. Walkers start at draws of $N(x_0,$ `init_scale`$^2 C_0)$,
      redrawn where `log_prob` is not finite.
    - `args`: pytree passed to `log_prob` (data, known constants).
    - `options`: the run's [`SamplerOptions`][] (walkers, steps, burn, thinning,
      seed, progress, ensembles, moves, the convergence criteria and `on_fail`).
      Its `sampler`: ``"emcee"`` (the default: emcee's `EnsembleSampler`, one
      ensemble after the other) or ``"lockstep"``: the same ensembles and moves
      stepped together in one jitted JAX loop ([`sample_posteriors`][] with one
      part, backend ``"jax"``; no Python per step, several times emcee's effective
      samples per second). Same diagnostics, verdict and `Posterior`; other random
      numbers; `nwalkers` must be even.

    **Returns:** a `Posterior`.
    """
    x0, names, opts = _checked_run(x0, names, options)
    if opts.sampler == "lockstep":
        post = sample_posteriors(
            log_prob, x0[None], names=names, cov0=None if cov0 is None else np.asarray(cov0)[None],
            args=jax.tree_util.tree_map(lambda a: np.asarray(a)[None], args),  # no eager op
            options=replace(opts, on_fail="ignore"), backend="jax",
        )[0]  # fmt: skip
    else:
        post = _sample_emcee(log_prob, x0, names, cov0, args, opts)
    if post.problems and opts.on_fail != "ignore":
        msg = "MCMC run has not converged:\n  " + "\n  ".join(post.problems)
        if opts.on_fail == "raise":
            raise ConvergenceError(msg, posterior=post)
        warnings.warn(msg, ConvergenceWarning, stacklevel=2)
    return post


def _sample_emcee(log_prob, x0, names, cov0, args, opts: SamplerOptions):
    """`sample_posterior` with emcee: the `Posterior` of the checked settings `opts`."""
    vec = _vectorised(log_prob)

    def f(p):  # the walkers as NumPy: jit takes them as they are, where an eager
        # jnp.asarray dispatched a transfer of its own (~50 us, 12 % of an emcee run)
        v = np.asarray(vec(np.asarray(p, dtype=float), args), dtype=float)
        return np.where(np.isnan(v), -np.inf, v)

    starts = _starts(f, log_prob, x0, args, cov0, opts.nwalkers, opts.n_ensembles, opts.seed,
                     opts.init_scale)  # fmt: skip
    kept, lps, acc, wall = _run_emcee(f, starts, x0.size, opts.nsteps, opts.burn, opts.run_thin,
                                      opts.moves, bool(opts.progress))  # fmt: skip
    if callable(opts.progress):
        opts.progress("posterior diagnostics: autocorrelation times, ESS and R-hat per parameter")
    kept, lps, thin, tau, tau_max, reliable, ess, rhat = diagnose(
        np.stack(kept), np.stack(lps), opts.run_thin, opts.thin, opts.tau_factor
    )  # kept: (K, S, W, d)
    problems = _problems(names, (tau_max, reliable, ess, rhat), kept.shape[1], opts, thin=thin)
    return make_posterior(
        names, (kept, lps, np.concatenate(acc)), (tau, reliable, ess, rhat), problems, opts,
        thin=thin, wall_time=wall, sampler=f"emcee {emcee_module().__version__}",
    )  # fmt: skip


def _checked_run(x0, names, options: SamplerOptions):
    """`sample_posterior`'s checked settings: `x0` as a vector, `names` as a tuple, and
    the options for its dimension (`SamplerOptions.for_dim`)."""
    x0 = np.atleast_1d(np.asarray(x0, dtype=float))
    if x0.ndim != 1 or not np.all(np.isfinite(x0)):
        raise InputError(f"x0: expected a finite vector, got {x0!r}")
    ndim = x0.size
    names = tuple(str(n) for n in names)
    if len(names) != ndim:
        raise InputError(f"names: got {len(names)} names for {ndim} parameters", value=names)
    opts = options.for_dim(ndim)
    if opts.nwalkers < 2 * ndim:
        raise InputError(f"nwalkers: got {opts.nwalkers}, expected >= 2 * dim = {2 * ndim}")
    return x0, names, opts


def _starts(f, log_prob, x0, args, cov0, nwalkers, n_ensembles, seed, init_scale):
    """Per ensemble: walkers drawn around `x0` (redrawn where `f`, the vectorised
    log posterior, is not finite), their log posteriors and a random seed."""
    ndim = x0.size
    root = sqrt_psd(start_cov(log_prob, x0, args, cov0, ndim)) * init_scale
    children = np.random.SeedSequence(seed).spawn(n_ensembles)
    starts = []
    for child in children:
        rng = np.random.default_rng(child)
        p0 = x0 + rng.standard_normal((nwalkers, ndim)) @ root.T
        lp0 = f(p0)
        for _ in range(100):
            bad = ~np.isfinite(lp0)
            if not bad.any():
                break
            p0[bad] = x0 + rng.standard_normal((int(bad.sum()), ndim)) @ root.T
            lp0[bad] = f(p0)[bad]
        if not np.all(np.isfinite(lp0)):
            raise AnalysisError(
                f"could not start {nwalkers} walkers with a finite log_prob around x0 = {x0} "
                "(after 100 redraws); check x0 and the prior supports, or lower init_scale"
            )
        starts.append((p0, lp0, int(child.generate_state(1)[0])))
    return starts


def _run_emcee(f, starts, ndim, nsteps, burn, thin, moves, progress):
    """One emcee run per start: the kept draws, log posteriors and acceptance
    fractions of each ensemble, and the wall time."""
    kept, lps, acc = [], [], []
    t0 = time.perf_counter()
    for k, (p0, lp0, rs) in enumerate(starts):
        emcee = emcee_module()
        nwalkers = p0.shape[0]
        sampler = emcee.EnsembleSampler(nwalkers, ndim, f, vectorize=True, moves=emcee_moves(moves))
        state = emcee.State(p0, log_prob=lp0, random_state=np.random.RandomState(rs).get_state())
        sampler.run_mcmc(
            state,
            nsteps,
            progress=progress,
            progress_kwargs={
                "desc": f"emcee ensemble {k + 1}/{len(starts)}",
                # a log file (CI, `make demo > log`) gets a line every 10 s, not 300
                "mininterval": 0.1 if sys.stderr.isatty() else 10.0,
            },
        )
        kept.append(sampler.get_chain(discard=burn, thin=thin))
        lps.append(sampler.get_log_prob(discard=burn, thin=thin))
        acc.append(sampler.acceptance_fraction)
    return kept, lps, acc, time.perf_counter() - t0
