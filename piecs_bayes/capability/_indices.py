"""Capability indices from a mean and a sigma, and their confidence intervals.

The chi-square interval of Cp, Pp (and Cpm with moment-matched degrees of freedom) and
Bissell's normal approximation for Cpk, Ppk, Cpl, Cpu; formulas and conventions in
docs/models/capability.md.
"""

from __future__ import annotations

import math

import numpy as np

from .. import _config
from ..errors import InputError
from ..intervals import Interval as Interval

stats = _config.LazyModule("scipy.stats")  # on first use: a fast start


NAN_INTERVAL = (math.nan, math.nan)


def spec_limits(lsl, usl, target):
    lsl = None if lsl is None else float(lsl)
    usl = None if usl is None else float(usl)
    if lsl is None and usl is None:
        raise InputError("capability needs at least one specification limit (lsl or usl)")
    for name, v in (("lsl", lsl), ("usl", usl)):
        if v is not None and not math.isfinite(v):
            raise InputError(f"{name} must be a finite number, got {v!r}", value=v)
    if lsl is not None and usl is not None and not lsl < usl:
        raise InputError(f"lsl must be below usl, got lsl={lsl}, usl={usl}", value=(lsl, usl))
    if target is None and lsl is not None and usl is not None:
        target = (lsl + usl) / 2.0
    return lsl, usl, None if target is None else float(target)


def capability_indices(mu, sigma, lsl, usl, target):
    nan = math.nan
    cp = (usl - lsl) / (6 * sigma) if lsl is not None and usl is not None else nan
    cpl = (mu - lsl) / (3 * sigma) if lsl is not None else nan
    cpu = (usl - mu) / (3 * sigma) if usl is not None else nan
    cpk = float(np.nanmin([cpl, cpu]))
    if lsl is not None and usl is not None and target is not None:
        cpm = (usl - lsl) / (6 * math.sqrt(sigma**2 + (mu - target) ** 2))
    else:
        cpm = nan
    return cp, cpl, cpu, cpk, cpm


def _chi2_interval(c, nu, alpha, level) -> Interval:
    if not math.isfinite(c) or nu <= 0:
        return Interval(*NAN_INTERVAL, level)
    lo, hi = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], nu)
    return Interval(c * math.sqrt(lo / nu), c * math.sqrt(hi / nu), level)


def bissell(c, n, nu, z, level) -> Interval:
    if not math.isfinite(c) or c == 0.0:
        return Interval(*NAN_INTERVAL, level)
    half = z * math.sqrt(1.0 / (9.0 * n * c**2) + 1.0 / (2.0 * nu))
    return Interval(c * (1 - half), c * (1 + half), level)


def _cpm_interval(cpm, mu, target, sigma, nu, n, alpha, level, convention) -> Interval:
    """Boyles' interval of Cpm; qcc uses the degrees of freedom $n(1+r^2)/(1+2r^2)$."""
    if not math.isfinite(cpm):
        return Interval(*NAN_INTERVAL, level)
    r = (mu - target) / sigma
    if convention == "qcc":
        nu_m = n * (1 + r**2) / (1 + 2 * r**2)
    else:
        nu_m = (1 + r**2) ** 2 / (1 / nu + 2 * r**2 / n)
    return _chi2_interval(cpm, nu_m, alpha, level)


def confidence_intervals(
    within, overall, n, mu, target, sigma_within, df_within, df_overall, level, convention
) -> dict[str, Interval]:
    """The `*_ci` fields of a capability result.

    `within` is `(cp, cpl, cpu, cpk, cpm)` from the within sigma, `overall`
    `(pp, ppl, ppu, ppk, _)` from the overall sigma (see `capability_indices`).
    """
    cp, cpl, cpu, cpk, cpm = within
    pp, _, _, ppk, _ = overall
    alpha = 1.0 - level
    z2 = float(stats.norm.ppf(1 - alpha / 2))
    z1 = float(stats.norm.ppf(level)) if convention == "qcc" else z2
    nu_w, nu_o = df_within, df_overall
    return {
        "cp_ci": _chi2_interval(cp, nu_w, alpha, level),
        "cpl_ci": bissell(cpl, n, nu_w, z1, level),
        "cpu_ci": bissell(cpu, n, nu_w, z1, level),
        "cpk_ci": bissell(cpk, n, nu_w, z2, level),
        "cpm_ci": _cpm_interval(cpm, mu, target, sigma_within, nu_w, n, alpha, level, convention),
        "pp_ci": _chi2_interval(pp, nu_o, alpha, level),
        "ppk_ci": bissell(ppk, n, nu_o, z2, level),
    }
