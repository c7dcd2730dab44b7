"""Bayesian credible intervals of the capability indices.

The values are treated as i.i.d. normal with the prior $p(\\mu,\\sigma)\\propto 1/\\sigma$:
$\\sigma^2\\mid y \\sim (n-1)s^2/\\chi^2_{n-1}$, $\\mu\\mid\\sigma,y \\sim N(\\bar y, \\sigma^2/n)$;
indices are computed draw by draw (Cp's interval is closed form and equals the
chi-square interval of Pp). With a gauge variance $u_g^2$, draws with
$\\sigma^2 \\le u_g^2$ are discarded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _config
from ..errors import AnalysisError
from ._indices import NAN_INTERVAL, Interval

stats = _config.LazyModule("scipy.stats")  # on first use: a fast start


@dataclass(frozen=True)
class BayesCapability:
    """Posterior summaries of the indices under the prior $1/\\sigma$ (i.i.d. normal values).

    Medians and equal-tailed credible intervals; `p_cpk_above` is
    $P(C_{pk} > \\text{threshold}\\mid y)$.
    """

    cp: float
    cp_interval: Interval
    cpk: float
    cpk_interval: Interval
    cpm: float
    cpm_interval: Interval
    p_cpk_above: float
    threshold: float
    n_draws: int
    discarded: float = 0.0

    def __repr__(self) -> str:
        return (
            f"BayesCapability(Cp {self.cp:.4g} {self.cp_interval!r}, "
            f"Cpk {self.cpk:.4g} {self.cpk_interval!r}, "
            f"P(Cpk > {self.threshold:g}) = {self.p_cpk_above:.4f}, draws={self.n_draws})"
        )


def posterior_draws(n, ybar, s, nu, n_draws, seed):
    rng = np.random.default_rng(seed)
    var = nu * s**2 / rng.chisquare(nu, size=n_draws)
    mu = ybar + np.sqrt(var / n) * rng.standard_normal(n_draws)
    return rng, mu, var


def draw_indices(mu, sd, lsl, usl, target):
    with np.errstate(invalid="ignore"):
        cpl = (mu - lsl) / (3 * sd) if lsl is not None else np.full_like(sd, np.inf)
        cpu = (usl - mu) / (3 * sd) if usl is not None else np.full_like(sd, np.inf)
    cpk = np.minimum(cpl, cpu)
    cp = (usl - lsl) / (6 * sd) if lsl is not None and usl is not None else None
    cpm = None
    if cp is not None and target is not None:
        cpm = (usl - lsl) / (6 * np.sqrt(sd**2 + (mu - target) ** 2))
    return cp, cpk, cpm


def summarise_draws(x, level) -> tuple[float, Interval]:
    if x is None:
        return math.nan, Interval(*NAN_INTERVAL, level)
    q = np.quantile(x, [0.5, (1 - level) / 2, (1 + level) / 2])
    return float(q[0]), Interval(float(q[1]), float(q[2]), level)


def bayes_capability(y, lsl, usl, target, gauge_sd, options):
    """The posterior summaries of `capability` (`options`: a `CapabilityOptions`)."""
    level, threshold = options.confidence, options.threshold
    n = y.size
    ybar, s = float(y.mean()), float(np.std(y, ddof=1))
    _, mu, var = posterior_draws(n, ybar, s, n - 1, options.n_draws, options.seed)
    var_p = var - gauge_sd**2
    keep = var_p > 0.0
    discarded = 1.0 - float(keep.mean())
    if discarded > 0.5:
        raise AnalysisError(
            f"gauge variance exceeds the process variance in {discarded:.0%} of the posterior "
            "draws: the measurement system cannot resolve this process"
        )
    mu, sd = mu[keep], np.sqrt(var_p[keep])
    cp, cpk, cpm = draw_indices(mu, sd, lsl, usl, target)
    cp_med, cp_int = summarise_draws(cp, level)
    if gauge_sd == 0.0 and cp is not None:  # closed form: Cp = Cp_hat * sqrt(chi2_nu / nu)
        c = (usl - lsl) / (6 * s)
        q = stats.chi2.ppf([0.5, (1 - level) / 2, (1 + level) / 2], n - 1) / (n - 1)
        cp_med, cp_int = (
            float(c * math.sqrt(q[0])),
            Interval(float(c * math.sqrt(q[1])), float(c * math.sqrt(q[2])), level),
        )
    cpk_med, cpk_int = summarise_draws(cpk, level)
    cpm_med, cpm_int = summarise_draws(cpm, level)
    return BayesCapability(
        cp=cp_med,
        cp_interval=cp_int,
        cpk=cpk_med,
        cpk_interval=cpk_int,
        cpm=cpm_med,
        cpm_interval=cpm_int,
        p_cpk_above=float(np.mean(cpk > threshold)),
        threshold=float(threshold),
        n_draws=int(mu.size),
        discarded=discarded,
    )
