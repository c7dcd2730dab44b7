"""Capability predicted after a compensation that removes (part of) a mean offset.

The spread is unchanged and only the mean moves: the indices are recomputed at the
shifted mean; Bissell's Cpk interval takes the offset's uncertainty into the mean's,
and the Bayesian summaries come from the posterior draws of the capability study
(see the Bayesian capability module) plus a normal error of the realised shift.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .. import _config
from ..errors import InputError
from ._bayes import draw_indices, posterior_draws, summarise_draws
from ._capability import CapabilityResult
from ._indices import Interval, bissell, capability_indices
from ._options import CapabilityOptions

stats = _config.LazyModule("scipy.stats")  # on first use: a fast start


@dataclass(frozen=True)
class PredictedCapability:
    """Capability predicted after shifting the process mean by `-gain * offset`.

    `mean_after` is the predicted mean; `cpk_ci` is Bissell's interval with the
    offset's uncertainty added to the mean's ($n_\\text{eff} = 1/(1/n + u^2/\\sigma^2)$);
    the Bayesian summaries come from posterior draws of $(\\mu, \\sigma)$ plus a
    $N(0, u^2)$ error of the realised shift.
    """

    offset: float
    u_offset: float
    gain: float
    mean_after: float
    sigma: float
    sigma_kind: str
    cp: float
    cpk: float
    cpk_ci: Interval
    cpm: float
    cpk_bayes: float
    cpk_bayes_interval: Interval
    p_cpk_above: float
    threshold: float
    cpk_before: float

    def __repr__(self) -> str:
        return (
            f"PredictedCapability(shift={-self.gain * self.offset:+.4g} ± "
            f"{self.gain * self.u_offset:.2g}, mean_after={self.mean_after:.6g}, "
            f"Cpk {self.cpk_before:.3f} -> {self.cpk:.3f} {self.cpk_ci!r}, "
            f"Bayes {self.cpk_bayes:.3f} {self.cpk_bayes_interval!r}, "
            f"P(Cpk > {self.threshold:g}) = {self.p_cpk_above:.3f})"
        )


def predict_capability(
    result: CapabilityResult,
    *,
    offset: float | None = None,
    u_offset: float = 0.0,
    sigma: Literal["overall", "within"] = "overall",
    options: CapabilityOptions = CapabilityOptions(),
) -> PredictedCapability:
    """Capability after a compensation that shifts the process mean by `-gain * offset`.

    **Arguments:**

    - `result`: the capability study of the process before compensation.
    - `offset`: the mean error to remove (mm); default $\\bar y - T$ (centre the process).
    - `u_offset`: standard uncertainty of the realised shift (mm): how far the mean may
      land from where it is aimed (adjustment resolution/repeatability, and the
      uncertainty of `offset` when it was estimated from other data than `result`).
    - `sigma`: `"overall"` (default; long-term spread stays) or `"within"` (assume the
      compensation also removes the between-part drift).
    - `options`: a [`CapabilityOptions`][]: `gain` (fraction of the offset applied, 1 =
      full compensation), `threshold`, and `n_draws` posterior draws seeded by `seed`.

    **Returns:** a [`PredictedCapability`][]; the spread is unchanged, only the mean moves.
    """
    if sigma not in ("overall", "within"):
        raise InputError(f"sigma must be 'overall' or 'within', got {sigma!r}", value=sigma)
    if not (math.isfinite(u_offset) and u_offset >= 0.0):
        raise InputError(f"u_offset must be a finite number >= 0, got {u_offset!r}", value=u_offset)
    gain, threshold = options.gain, options.threshold
    if offset is None:
        if result.target is None:
            raise InputError("offset is required when the specification has no target")
        offset = result.mean - result.target
    offset = float(offset)
    if not math.isfinite(offset):
        raise InputError(f"offset must be finite, got {offset!r}", value=offset)
    lsl, usl, target, n = result.lsl, result.usl, result.target, result.n
    if sigma == "overall":
        sd, nu, s_obs = result.sigma_overall, result.df_overall, result.sd_overall_observed
    else:
        sd, nu, s_obs = result.sigma_within, result.df_within, result.sd_within_observed
    mean_after = result.mean - gain * offset
    cp, _, _, cpk, cpm = capability_indices(mean_after, sd, lsl, usl, target)
    n_eff = 1.0 / (1.0 / n + (gain * u_offset) ** 2 / sd**2)
    z = float(stats.norm.ppf(1 - (1 - result.confidence) / 2))
    cpk_ci = bissell(cpk, n_eff, nu, z, result.confidence)

    nu_obs = nu / ((sd**2 / s_obs**2) ** 2) if result.gauge_sd > 0 else nu
    rng, mu, var = posterior_draws(n, result.mean, s_obs, nu_obs, options.n_draws, options.seed)
    var_p = var - result.gauge_sd**2
    keep = var_p > 0.0
    mu = mu[keep] - gain * offset + gain * u_offset * rng.standard_normal(int(keep.sum()))
    _, cpk_draws, _ = draw_indices(mu, np.sqrt(var_p[keep]), lsl, usl, target)
    med, interval = summarise_draws(cpk_draws, result.confidence)
    return PredictedCapability(
        offset=offset,
        u_offset=float(u_offset),
        gain=float(gain),
        mean_after=mean_after,
        sigma=sd,
        sigma_kind=sigma,
        cp=cp,
        cpk=cpk,
        cpk_ci=cpk_ci,
        cpm=cpm,
        cpk_bayes=med,
        cpk_bayes_interval=interval,
        p_cpk_above=float(np.mean(cpk_draws > threshold)),
        threshold=float(threshold),
        cpk_before=result.ppk if sigma == "overall" else result.cpk,
    )
