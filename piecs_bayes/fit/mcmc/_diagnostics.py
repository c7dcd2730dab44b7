r"""MCMC diagnostics of ensemble samplers, computed the way ArviZ computes them.

The walkers of one emcee ensemble are coupled, so they are never ArviZ *chains*. The
package stores and diagnoses draws in one layout ([`arviz_layout`][]): **chain = one
independent ensemble**, **draw = the ensemble's walker trajectories one after the
other**. On that layout [`ess_bulk`][] and [`split_rhat`][] reproduce
`arviz.ess(..., method="bulk")` and `arviz.rhat(..., method="rank")` (arviz 0.2x) to
rounding ([`ess_and_rhat`][] shares the ranks between the two); with a single ensemble
`split_rhat` still compares the two halves of its walkers, where ArviZ gives NaN.
`problems` says which diagnostics failed and what to change.

The layout and the parity with ArviZ: docs/models/sampling.md, "Diagnostics".
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import InputError


def arviz_layout(kept: np.ndarray) -> np.ndarray:
    """Ensemble draws `(K, S, W, ...)` -> ArviZ chains `(K, W * S, ...)`, walker-major."""
    k, s, w = kept.shape[:3]
    return np.swapaxes(kept, 1, 2).reshape(k, w * s, *kept.shape[3:])


def rank_normalise(x: np.ndarray) -> np.ndarray:
    """Normal scores of the pooled ranks (average ties), Blom's offset 3/8:
    `scipy.stats.norm.ppf` of them is `special.ndtri` (times 1, plus 0), without its
    argument checks (~0.3 ms a call, two per parameter and part)."""
    from scipy import special, stats  # lazily: scipy.stats costs ~0.5 s of import time

    r = stats.rankdata(x, axis=None).reshape(x.shape)
    return special.ndtri((r - 0.375) / (x.size + 0.25))


def _split(x: np.ndarray) -> np.ndarray:
    half = x.shape[1] // 2
    return np.concatenate([x[:, :half], x[:, -half:]], axis=0)


def _rhat_basic(x: np.ndarray) -> float:
    _, n = x.shape
    w = np.mean(np.var(x, axis=1, ddof=1))
    b = n * np.var(np.mean(x, axis=1), ddof=1)
    return float(np.sqrt((b / w + n - 1) / n)) if w > 0 else math.nan


def _check(chains, what: str) -> np.ndarray:
    x = np.asarray(chains, dtype=float)
    if x.ndim != 2 or x.shape[1] < 4:
        raise InputError(f"{what}: got shape {x.shape}, expected (chains, draws >= 4)")
    return x


def split_rhat(chains) -> float:
    """Rank-normalised split $\\hat R$ (Vehtari et al. 2021) of `chains`, shape `(m, n)`.

    Each of the `m` chains is split into its first and last `n // 2` draws; the
    result is the larger of the bulk $\\hat R$ (on normal scores of the pooled
    ranks) and the tail $\\hat R$ (on normal scores of $|x - \\mathrm{median}|$).
    The chains must be independent of each other: for emcee, pass one row per
    *ensemble* (`arviz_layout`), never one per walker. Same value as
    `arviz.rhat(..., method="rank")`.
    """
    x = _split(_check(chains, "split_rhat"))
    return _rhat_from_split(x, rank_normalise(x))


def _rhat_from_split(x: np.ndarray, z: np.ndarray) -> float:
    if x.shape[0] < 2:
        return math.nan
    bulk = _rhat_basic(z)
    tail = _rhat_basic(rank_normalise(np.abs(x - np.median(x))))
    return max(bulk, tail)


def _autocov(x: np.ndarray) -> np.ndarray:
    from scipy.fft import next_fast_len

    n = x.shape[1]
    m = next_fast_len(2 * n)
    y = x - x.mean(axis=1, keepdims=True)
    f = np.fft.rfft(y, n=m, axis=1)
    f *= np.conjugate(f)
    return np.fft.irfft(f, n=m, axis=1)[:, :n] / n


def _ess(z: np.ndarray) -> float:
    """Geyer's initial monotone sequence estimator on `(m, n)` chains (ArviZ's `_ess`)."""
    if not np.all(np.isfinite(z)):
        return math.nan
    if np.max(z) - np.min(z) < np.finfo(float).resolution:
        return float(z.size)
    m, n = z.shape
    acov = _autocov(z)
    mean_var = np.mean(acov[:, 0]) * n / (n - 1.0)
    var_plus = mean_var * (n - 1.0) / n
    if m > 1:
        var_plus += np.var(z.mean(axis=1), ddof=1)
    rho = 1.0 - (mean_var - acov.mean(axis=0)) / var_plus  # rho_hat at every lag
    rho_t = np.zeros(n)
    even, odd = 1.0, rho[1]
    rho_t[0], rho_t[1] = even, odd
    t = 1
    while t < n - 3 and even + odd > 0.0:
        even, odd = rho[t + 1], rho[t + 2]
        if even + odd >= 0:
            rho_t[t + 1], rho_t[t + 2] = even, odd
        t += 2
    max_t = t - 2
    if even > 0:
        rho_t[max_t + 1] = even
    t = 1
    while t <= max_t - 2:
        if rho_t[t + 1] + rho_t[t + 2] > rho_t[t - 1] + rho_t[t]:
            rho_t[t + 1] = rho_t[t + 2] = (rho_t[t - 1] + rho_t[t]) / 2.0
        t += 2
    total = m * n
    tau = -1.0 + 2.0 * np.sum(rho_t[: max_t + 1]) + np.sum(rho_t[max_t + 1 : max_t + 2])
    tau = max(tau, 1.0 / math.log10(total))
    return math.nan if np.isnan(rho_t).any() else total / tau


def ess_bulk(chains) -> float:
    """Rank-normalised bulk effective sample size of `(m, n)` chains, as
    `arviz.ess(..., method="bulk")`."""
    x = _split(_check(chains, "ess_bulk"))
    return _ess(rank_normalise(x))


def ess_and_rhat(chains) -> tuple[float, float]:
    """`ess_bulk` and `split_rhat` of the same chains, ranking once."""
    x = _split(_check(chains, "ess_and_rhat"))
    z = rank_normalise(x)
    return _ess(z), _rhat_from_split(x, z)


def problems(names, diag, s, options, *, thin):
    """Human-readable reasons (with numbers and advice) why a run is not trusted:
    `diag` = `(tau_max, reliable, ess, rhat)` per parameter of `s` kept steps, thinned
    by `thin`, of a run of `options` (`SamplerOptions.for_dim`: the criteria, steps,
    burn, walkers and ensembles)."""
    tau_max, reliable, ess, rhat = diag
    nsteps, burn, nwalkers, n_ensembles = (
        options.nsteps, options.burn, options.nwalkers, options.n_ensembles)  # fmt: skip
    rhat_max, min_ess, tau_factor = options.rhat_max, options.min_ess, options.tau_factor
    out = []
    worst = float(np.max(tau_max))
    kept_steps = s * thin
    if not np.all(reliable):
        bad = ", ".join(
            f"{n} {t:.0f}" for n, t, r in zip(names, tau_max, reliable, strict=True) if not r
        )
        need_burn = max(burn, int(math.ceil(5 * worst / 10.0)) * 10)
        need = int(math.ceil((need_burn + 1.2 * tau_factor * worst) / 100.0) * 100)
        out.append(
            f"autocorrelation time not trusted: the kept chain of {kept_steps} steps is shorter "
            f"than {tau_factor:g} tau (tau in steps: {bad}); increase nsteps to >= {need} "
            f"(burn >= {need_burn})"
        )
    if np.any(rhat > rhat_max):
        bad = ", ".join(f"{n} ({r:.3f})" for n, r in zip(names, rhat, strict=True) if r > rhat_max)
        hint = "" if n_ensembles > 1 else "; use n_ensembles >= 2 for a between-ensemble check"
        out.append(
            f"split R-hat across {n_ensembles} independent ensembles > {rhat_max}: {bad}; "
            f"increase nsteps and burn (now {nsteps}, {burn}), or check x0 / multiple modes{hint}"
        )
    if np.any(ess < min_ess):
        lo = float(np.min(ess))
        bad = ", ".join(f"{n} ({e:.0f})" for n, e in zip(names, ess, strict=True) if e < min_ess)
        factor = min_ess / max(lo, 1.0)
        out.append(
            f"effective sample size < {min_ess:g}: {bad}; multiply nsteps - burn or nwalkers "
            f"(now {nwalkers} per ensemble) by about {factor:.1f}, or add ensembles"
        )
    return out
