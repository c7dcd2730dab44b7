"""Confidence intervals of a measuring-system analysis, vectorised over studies.

[`Interval`][] (`piecs_bayes.intervals`) holds one; the functions take arrays (one
value per simulated study) and return the bounds: Student-t for a mean, chi-square
for a standard deviation and for a ratio to it (Cg), Bissell's normal approximation
for Cgk, and the modified large-sample (MLS) method of Ting, Burdick & Graybill for a
linear combination of mean squares (the variance components of a gauge R&R).
Derivations and measured coverage: docs/msa.md.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from ..intervals import Interval as Interval


def t_bounds(estimate, std_error, df, level: float):
    """`estimate -/+ t_{1-a/2, df} std_error` (a mean, a bias)."""
    t = stats.t.ppf(0.5 + level / 2.0, df)
    return estimate - t * std_error, estimate + t * std_error


def sd_bounds(s, df, level: float):
    """Exact bounds of a normal sd from its estimate `s` on `df` degrees of freedom:
    `s sqrt(df / chi2_{1-a/2})` to `s sqrt(df / chi2_{a/2})`."""
    lo, hi = stats.chi2.ppf([0.5 + level / 2.0, 0.5 - level / 2.0], df)
    return s * np.sqrt(df / lo), s * np.sqrt(df / hi)


def bissell_bounds(c, n, level: float):
    """Bissell (1990): `c -/+ z sqrt(1/(9n) + c^2/(2(n-1)))`, for a Cpk-type index
    `(d - |mean - m|) / (3 s)` of `n` values."""
    z = stats.norm.ppf(0.5 + level / 2.0)
    half = z * np.sqrt(1.0 / (9.0 * n) + np.asarray(c) ** 2 / (2.0 * (n - 1)))
    return c - half, c + half


def mls_bounds(coef, ms, df, level: float):
    """Modified large-sample bounds of `gamma = sum_q coef_q E[MS_q]`.

    **Arguments:** `coef` (Q,) signed coefficients (at most one negative), `ms`
    (..., Q) the mean squares, `df` (Q,) their degrees of freedom.

    **Returns:** `(estimate, lower, upper)`, each of shape `ms.shape[:-1]`; nothing is
    truncated (a variance's caller clips at 0). Ting, Burdick & Graybill (1990);
    Burdick, Borror & Montgomery (2005), eqs. (A.1)-(A.4) (docs/msa.md).
    """
    coef, df = np.asarray(coef, float), np.asarray(df, float)
    ms = np.asarray(ms, float)
    pos, neg = np.flatnonzero(coef > 0), np.flatnonzero(coef < 0)
    if len(neg) > 1:
        raise ValueError("mls_bounds: at most one negative coefficient")
    g, h = _g_h(df, level)
    a = np.abs(coef) * ms  # (..., Q)
    var_lo = (g[pos] ** 2 * a[..., pos] ** 2).sum(-1) + (h[neg] ** 2 * a[..., neg] ** 2).sum(-1)
    var_hi = (h[pos] ** 2 * a[..., pos] ** 2).sum(-1) + (g[neg] ** 2 * a[..., neg] ** 2).sum(-1)
    for r in neg:
        for q in pos:
            g_qr, h_qr = _cross(df[q], df[r], g[q], h[q], g[r], h[r], level)
            var_lo = var_lo + g_qr * a[..., q] * a[..., r]
            var_hi = var_hi + h_qr * a[..., q] * a[..., r]
    estimate = (coef * ms).sum(-1)
    return (
        estimate,
        estimate - np.sqrt(np.maximum(var_lo, 0.0)),
        estimate + np.sqrt(np.maximum(var_hi, 0.0)),
    )


def _g_h(df, level: float):
    """`G = 1 - 1/F_{1-a/2; df, inf}`, `H = 1/F_{a/2; df, inf} - 1` (lower quantiles)."""
    upper = stats.chi2.ppf(0.5 + level / 2.0, df) / df
    lower = stats.chi2.ppf(0.5 - level / 2.0, df) / df
    return 1.0 - 1.0 / upper, 1.0 / lower - 1.0


def _cross(n_q, n_r, g_q, h_q, g_r, h_r, level: float):
    """The cross terms `G_qr`, `H_qr` of a positive mean square q and a negative r."""
    f1 = stats.f.ppf(0.5 + level / 2.0, n_q, n_r)
    f2 = stats.f.ppf(0.5 - level / 2.0, n_q, n_r)
    g_qr = ((f1 - 1.0) ** 2 - g_q**2 * f1**2 - h_r**2) / f1
    h_qr = ((1.0 - f2) ** 2 - h_q**2 * f2**2 - g_r**2) / f2
    return g_qr, h_qr
