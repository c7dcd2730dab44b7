r"""The probe sigma behind every standard uncertainty of a part, and its degrees of freedom.

A feature's own few residuals say little about the probe's repeatability, so no
feature's covariance is scaled by them. The rule ([`probe_sigma`][] -> [`ProbeSigma`][];
[`sigma_arrays`][] for many parts at once):

1. **known** (`known=True`): the declared repeatability $\sigma_0$, $\nu = \infty$;
2. **default**: the residual variance pooled over every feature of the part (robust
   fits: the inliers), combined with $\sigma_0$ as a scaled-inverse-$\chi^2$ prior worth
   $\nu_0$ degrees of freedom (`DECLARED_DOF` = 8); $\nu = \nu_0 + \nu_p$ for Student-t
   intervals; with $\nu_0 = 0$ the pooled variance alone;
3. quantities that also carry Type B sources get the Welch-Satterthwaite effective
   degrees of freedom ([`effective_dof`][]) and the factor [`coverage_factor`][].

The rule and why: docs/uncertainty.md, sections 1 and 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

#: degrees of freedom a declared repeatability is worth by default (relative
#: standard uncertainty of the declared value ~25 %: nu = 1 / (2 * 0.25^2))
DECLARED_DOF = 8.0


@dataclass(frozen=True)
class ProbeSigma:
    """The probe sigma a part's uncertainties are scaled by.

    - `value`: sigma (mm); `dof`: its degrees of freedom (`inf` when declared known).
    - `source`: ``"declared"`` (known), ``"pooled"`` (the part's residuals, every
      feature together), ``"pooled+declared"`` (the pooled residuals with the
      declared repeatability as prior), ``"prior"`` (no residual dof: the declared
      value with its `declared_dof`) or ``"posterior"`` (a Bayesian fit's).
    - `pooled_sd`, `pooled_dof`: the residual sd pooled over the part's features
      and its degrees of freedom (`nan`, 0 when not computed).
    - `declared`, `declared_dof`: the declared repeatability and its weight.
    """

    value: float
    dof: float
    source: str
    pooled_sd: float = math.nan
    pooled_dof: int = 0
    declared: float = math.nan
    declared_dof: float = 0.0

    def k(self, p: float = 0.95) -> float:
        """Coverage factor of a two-sided `p` interval on this sigma alone."""
        return coverage_factor(self.dof, p)

    def as_dict(self) -> dict:
        def num(x):
            return None if not math.isfinite(x) else float(x)

        return {
            "value_mm": float(self.value),
            "dof": num(self.dof),
            "source": self.source,
            "pooled_sd_mm": num(self.pooled_sd),
            "pooled_dof": int(self.pooled_dof),
            "declared_mm": num(self.declared),
            "declared_dof": num(self.declared_dof),
        }

    def describe(self) -> str:
        dof = "inf" if math.isinf(self.dof) else f"{self.dof:.0f}"
        what = {
            "declared": "declared repeatability, taken as known",
            "pooled": "pooled residuals of every feature",
            "pooled+declared": "pooled residuals with the declared repeatability as prior",
            "prior": "declared repeatability as prior, no residual degrees of freedom",
            "posterior": "posterior of the Bayesian fit",
        }.get(self.source, self.source)
        return f"{self.value * 1e3:.3g} um ({what}, {dof} dof)"

    def __repr__(self) -> str:
        return f"ProbeSigma({self.describe()})"


def probe_sigma(
    ss: float,
    dof: int,
    *,
    declared: float | None = None,
    declared_dof: float = DECLARED_DOF,
    known: bool = False,
    what: str = "part",
) -> ProbeSigma:
    """The probe sigma of a part by the module's rule.

    **Arguments:**

    - `ss`, `dof`: residual sum of squares (mm^2) pooled over the part's features
      (inliers) and its degrees of freedom $\\sum_f (n_f - p_f)$.
    - `declared`: the declared repeatability (mm); `declared_dof` its weight
      ($\\nu_0 \\ge 0$; 0: no prior).
    - `known`: take `declared` as known ($\\nu = \\infty$).

    **Returns:** a [`ProbeSigma`][].
    """
    ss, dof = float(ss), int(dof)
    pooled = math.sqrt(ss / dof) if dof > 0 and ss >= 0 else math.nan
    if declared is not None and not (math.isfinite(declared) and declared > 0):
        raise InputError(f"declared repeatability: got {declared!r}, expected > 0", value=declared)
    if not (math.isfinite(declared_dof) and declared_dof >= 0):
        raise InputError(f"repeatability_dof: got {declared_dof!r}, expected >= 0")
    base = dict(
        pooled_sd=pooled,
        pooled_dof=max(dof, 0),
        declared=math.nan if declared is None else float(declared),
    )
    if known:
        if declared is None:
            raise InputError("known sigma: no declared repeatability to take as known")
        return ProbeSigma(float(declared), math.inf, "declared", declared_dof=math.inf, **base)
    nu0 = 0.0 if declared is None else float(declared_dof)
    nu = nu0 + max(dof, 0)
    if nu <= 0:
        raise InputError(
            f"no degrees of freedom to estimate the probe sigma of the {what}: every feature "
            "has as many points as parameters and no repeatability is declared; "
            "add points or declare [probe] repeatability"
        )
    value, _ = sigma_arrays(ss, dof, declared=declared, declared_dof=nu0)
    source = "pooled+declared" if nu0 > 0 and dof > 0 else ("pooled" if dof > 0 else "prior")
    if not math.isfinite(value):  # a perfect fit and no prior: nothing says how large
        raise InputError(
            f"the residuals of the {what} are all zero and no repeatability is declared: "
            "the probe sigma cannot be estimated; declare [probe] repeatability"
        )
    return ProbeSigma(float(value), nu, source, declared_dof=nu0, **base)


def sigma_arrays(ss, dof, *, declared=None, declared_dof=DECLARED_DOF, known=False):
    """`probe_sigma`'s value and degrees of freedom for many parts at once:
    `ss`, `dof` arrays -> `(sigma, nu)` arrays, NaN sigma where the rule has
    nothing to go on (no residual dof and no prior, or all-zero residuals)."""
    ss = np.asarray(ss, dtype=float)
    dof = np.maximum(np.asarray(dof, dtype=float), 0.0)
    if known:
        return np.full(ss.shape, float(declared)), np.full(ss.shape, np.inf)
    nu0 = 0.0 if declared is None else float(declared_dof)
    nu = nu0 + dof
    prior = nu0 * declared**2 if nu0 > 0 else 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        s2 = (prior + np.maximum(ss, 0.0)) / nu
    value = np.where((nu > 0) & (s2 > 0), np.sqrt(np.where(s2 > 0, s2, 1.0)), np.nan)
    return value, nu


def effective_dof(u_total, u_a, dof_a):
    """Welch-Satterthwaite $\\nu_\\mathrm{eff} = u_c^4 / (u_A^4 / \\nu_A)$ for a combined
    standard uncertainty `u_total` whose Type A part `u_a` has `dof_a` degrees of
    freedom and whose other parts are Type B ($\\nu = \\infty$). Arrays broadcast;
    `inf` where `dof_a` is infinite or `u_a` is zero."""
    u_total = np.asarray(u_total, dtype=float)
    u_a = np.asarray(u_a, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = np.where(u_a > 0, dof_a * (u_total / np.where(u_a > 0, u_a, 1.0)) ** 4, np.inf)
    nu = np.where(np.isfinite(dof_a), nu, np.inf)
    return nu if nu.ndim else float(nu)


def coverage_factor(dof, p: float = 0.95):
    """Two-sided coverage factor: $t_{(1+p)/2}(\\nu)$, the normal quantile at $\\nu = \\infty$."""
    from scipy import stats

    q = 0.5 + p / 2.0
    dof = np.asarray(dof, dtype=float)
    k = np.where(np.isfinite(dof), stats.t.ppf(q, np.where(np.isfinite(dof), dof, 1.0)), 0.0)
    k = np.where(np.isfinite(dof), k, stats.norm.ppf(q))
    return k if k.ndim else float(k)


def pooled_residuals(fits) -> tuple[float, int]:
    """Residual sum of squares and degrees of freedom pooled over `FeatureFit`s
    (inliers only: a robust fit's flagged points are left out)."""
    ss, dof = 0.0, 0
    for f in fits:
        keep = np.ones(f.n, dtype=bool)
        keep[np.asarray(f.outliers, dtype=int)] = False
        ss += float(np.sum(np.asarray(f.residuals)[keep] ** 2))
        dof += int(keep.sum()) - (len(f.values) - len(f.fixed))
    return ss, dof
