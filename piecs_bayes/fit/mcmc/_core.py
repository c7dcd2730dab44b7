"""What both samplers share (emcee's `sample_posterior` and the lockstep ensembles of
`sample_posteriors`): the convergence warning and error, the likelihoods, the start
ball and the diagnostics of the kept draws (thinning, tau, ESS, split R-hat)."""

from __future__ import annotations

import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np

from ...errors import AnalysisError, InputError
from ._diagnostics import arviz_layout, ess_and_rhat

_LOG_2PI = math.log(2.0 * math.pi)


class ConvergenceWarning(UserWarning):
    """An MCMC run whose diagnostics do not support trusting its numbers."""


class ConvergenceError(AnalysisError):
    """Raised instead of `ConvergenceWarning` when `on_fail="raise"`. Like emcee's
    `AutocorrError`, which carries `tau`, it carries what was computed:
    `posterior`, the [`Posterior`][] that failed the criteria (from
    `sample_posteriors`, the list of every part's), also as `result`."""

    def __init__(self, *args: object, posterior: Any = None):
        super().__init__(*args, result=posterior)
        self.posterior = posterior


# --------------------------------------------------------------------------- likelihoods


def gaussian_loglik(residuals, sigma):
    """Gaussian log likelihood $\\sum_i \\log \\varphi(r_i/\\sigma_i) - \\log\\sigma_i$.

    **Arguments:**

    - `residuals`: array of residuals $r_i$ (data minus model).
    - `sigma`: standard deviation, a scalar or an array broadcast to `residuals`.

    **Returns:** the scalar $-\\tfrac12\\sum_i (r_i/\\sigma_i)^2 - \\sum_i \\log\\sigma_i
    - \\tfrac n2 \\log 2\\pi$ (JAX, differentiable).
    """
    r = jnp.asarray(residuals)
    s = jnp.broadcast_to(jnp.asarray(sigma, dtype=r.dtype), r.shape)
    u = r / s
    return -0.5 * jnp.sum(u * u) - jnp.sum(jnp.log(s)) - 0.5 * r.size * _LOG_2PI


def student_t_loglik(residuals, scale, nu):
    """Student-t log likelihood: the robust option, heavy tails absorb outliers.

    $\\log L = \\sum_i \\log\\Gamma(\\tfrac{\\nu+1}2) - \\log\\Gamma(\\tfrac\\nu2)
    - \\tfrac12\\log(\\nu\\pi) - \\log s_i - \\tfrac{\\nu+1}2\\log(1 + r_i^2/(\\nu s_i^2))$.

    **Arguments:**

    - `residuals`: array of residuals.
    - `scale`: scale $s$ (not the standard deviation, which is
      $s\\sqrt{\\nu/(\\nu-2)}$), scalar or broadcast.
    - `nu`: degrees of freedom $\\nu > 0$ (4 to 5 is a common robust choice);
      may itself be a sampled parameter.

    **Returns:** the scalar log likelihood (JAX, differentiable).
    """
    r = jnp.asarray(residuals)
    s = jnp.broadcast_to(jnp.asarray(scale, dtype=r.dtype), r.shape)
    nu = jnp.asarray(nu, dtype=r.dtype)
    u = r / s
    const = jsp.gammaln(0.5 * (nu + 1.0)) - jsp.gammaln(0.5 * nu) - 0.5 * jnp.log(nu * jnp.pi)
    return r.size * const - jnp.sum(jnp.log(s)) - 0.5 * (nu + 1.0) * jnp.sum(jnp.log1p(u * u / nu))


# --------------------------------------------------------------------------- diagnostics


def _taus(kept: np.ndarray) -> np.ndarray:
    """emcee's integrated autocorrelation time per ensemble and parameter, `(K, d)`,
    in kept steps (walker-averaged autocorrelation, Sokal's window `c=5`).

    The numbers of `emcee.autocorr.integrated_time(kept[k], c=5, tol=0, quiet=True)`
    (to rounding: the same linear autocorrelation, zero-padded to a fast FFT length
    instead of a power of two), with batched real FFTs of a few walkers' series at
    a time, made contiguous block by block, instead of one complex FFT per strided
    walker and parameter in Python: ~3x faster on the demo's 4 x 80 walkers x 20
    parameters x 6,000 steps."""
    from scipy.fft import irfft, next_fast_len, rfft

    k, s, w, d = kept.shape
    nfft = next_fast_len(2 * s - 1, real=True)
    acf = np.zeros((k, d, s))  # walker-averaged normalised autocorrelation
    x = np.empty((d * w, s))
    for i in range(k):
        for lo in range(0, s, 256):  # (s, w, d) -> (d * w, s) in cache-sized blocks
            x[:, lo : lo + 256] = kept[i, lo : lo + 256].transpose(2, 1, 0).reshape(d * w, -1)
        x -= x.mean(axis=-1, keepdims=True)
        for j in range(d):
            for lo in range(j * w, (j + 1) * w, 32):  # 32 series at a time: in cache
                f = rfft(x[lo : min(lo + 32, (j + 1) * w)], n=nfft)
                a = irfft(f * np.conjugate(f), n=nfft)[:, :s]
                acf[i, j] += (a / a[:, :1]).sum(axis=0)
    acf /= w
    cum = 2.0 * np.cumsum(acf, axis=-1) - 1.0
    m = np.arange(s) < 5.0 * cum  # Sokal's window, c = 5
    win = np.where(m.any(axis=-1), np.argmin(m, axis=-1), s - 1)
    taus = np.take_along_axis(cum, win[..., None], axis=-1)[..., 0]
    return np.maximum(taus, 1e-12)


def check_thin(thin) -> int | str:
    """`thin`: a positive int, or ``"auto"`` (about half the smallest tau)."""
    if thin == "auto":
        return thin
    if isinstance(thin, bool) or not isinstance(thin, int | np.integer) or thin < 1:
        raise InputError(f"thin: got {thin!r}, expected an integer >= 1 or 'auto'", value=thin)
    return int(thin)


def diagnose(kept: np.ndarray, lps: np.ndarray, run_thin: int, thin, tau_factor: float):
    """Thin and diagnose the kept draws of one run.

    `kept`: `(K, S, W, d)` draws (every `run_thin`-th step after burn-in), `lps`:
    `(K, S, W)`; `thin`: ``"auto"`` thins them further to about half the smallest
    autocorrelation time (nearly no effective samples lost, a tenth to a
    fiftieth of the draws to store), an int keeps them. Returns the thinned
    draws and log posteriors, the total thinning, tau (original steps; mean and
    max over ensembles, estimated before thinning), reliable, ESS and R-hat per
    parameter, the last two as ArviZ computes them on the stored draws
    (`_diagnostics.arviz_layout`).
    """
    k, s, w, d = kept.shape
    taus = _taus(kept)
    reliable = s >= tau_factor * taus.max(axis=0)
    extra = 1
    if thin == "auto" and np.all(np.isfinite(taus)):
        extra = max(1, min(int(np.min(taus) // 2), s // 8))
    kept, lps = kept[:, extra - 1 :: extra], lps[:, extra - 1 :: extra]
    chains = arviz_layout(kept)  # (K, W*S', d)
    ess, rhat = np.empty(d), np.empty(d)
    for j in range(d):
        ess[j], rhat[j] = ess_and_rhat(chains[:, :, j])
    total = run_thin * extra
    tau = taus.mean(axis=0) * run_thin
    return kept, lps, total, tau, taus.max(axis=0) * run_thin, reliable, ess, rhat


# --------------------------------------------------------------------------- sampling


def kept_trace(name: str, log_prob, fn, *structure, compiler_options=None):
    """`fn`, through a kept trace when `log_prob` says what it computes (a
    `trace_key` attribute: the profile model's does), else None. `structure`: the
    rest of what the trace depends on (sizes, settings: hashable, with a full repr);
    `compiler_options`: those of its `compiled` programs."""
    from ... import _config

    key = getattr(log_prob, "trace_key", None)
    if key is None:
        return None
    return _config.KeptTrace(name, (key, *structure), fn, compiler_options)


def _kept(name: str, log_prob, fn):
    """`fn` through a kept trace where `log_prob` has a `trace_key`, else `fn`."""
    return kept_trace(name, log_prob, fn) or fn


@functools.lru_cache(maxsize=64)
def _neg_hessian(log_prob):
    """Jitted Hessian of ``-log_prob``, cached per function (and its trace kept
    across processes where `log_prob` has a `trace_key`: tracing it takes ~1 s)."""
    return _kept("neg_hessian", log_prob, jax.jit(jax.hessian(lambda t, a: -log_prob(t, a))))


@functools.lru_cache(maxsize=64)
def neg_hessians(log_prob):
    """`_neg_hessian` of many parts at once (`vmap` over the leading axis of the start
    and of every leaf of the arguments), cached per function."""
    fn = jax.jit(jax.vmap(jax.hessian(lambda t, a: -log_prob(t, a))))
    return _kept("neg_hessians", log_prob, fn)


def cov_from_hessian(h: np.ndarray) -> np.ndarray:
    """The start ball's covariance from the Hessian of -log_prob at the start."""
    w, v = np.linalg.eigh(0.5 * (h + h.T)) if np.all(np.isfinite(h)) else (None, None)
    # a start off the mode (e.g. a sigma at its declared value, not at the data's)
    # can have negative curvature along a few directions: the ball only needs a
    # scale per direction, so those take |curvature| (a saddle-free Newton ball)
    if w is None or np.min(np.abs(w)) <= 1e-12 * np.max(np.abs(w)):
        raise AnalysisError(
            "cannot build the walkers' start ball: the Hessian of -log_prob at x0 is "
            "singular (a parameter is not identified by the data and its prior); "
            f"eigenvalues {w}; pass cov0, e.g. the least-squares covariance"
        )
    return (v / np.abs(w)) @ v.T


def start_cov(log_prob, x0, args, cov0, ndim):
    if cov0 is None:
        return cov_from_hessian(np.asarray(_neg_hessian(log_prob)(jnp.asarray(x0), args)))
    c = np.asarray(cov0, dtype=float)
    if c.ndim == 1:
        c = np.diag(c)
    if c.shape != (ndim, ndim):
        raise InputError(f"cov0: got shape {c.shape}, expected ({ndim}, {ndim}) or ({ndim},)")
    if not np.all(np.isfinite(c)) or np.any(np.diag(c) <= 0.0):
        raise InputError(f"cov0: expected a finite covariance with a positive diagonal, got {c}")
    return 0.5 * (c + c.T)


def sqrt_psd(c: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh(c)
    return v * np.sqrt(np.clip(w, 0.0, None))
