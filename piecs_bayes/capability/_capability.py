"""Process capability: Cp, Cpk, Pp, Ppk, Cpm with confidence and credible intervals.

[`capability`][] takes plain numbers (the values of one characteristic, one per part, in
mm; individuals or subgroups) and specification limits, and returns a
[`CapabilityResult`][]: Cp, Cpk, Cpm from the within (short-term) sigma, Pp, Ppk from the
overall sigma, each with its two-sided confidence interval at `confidence`, and with
`bayes=True` posterior medians, credible intervals and P(Cpk > `threshold`). A gauge
(measurement) standard deviation `gauge_sd` is subtracted from every variance.
`convention="piecs"` (default) uses exact constants and the effective degrees of freedom
of the sigma estimate; `convention="qcc"` reproduces R's `qcc::process.capability`. Bad
data or limits raise `InputError`; a gauge variance that swallows the process variance
raises `AnalysisError`. Reading probe files and fitting parts is done elsewhere.

The model (indices, intervals, conventions, gauge variance): docs/models/capability.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import AnalysisError, InputError
from ._bayes import BayesCapability, bayes_capability
from ._indices import Interval, capability_indices, confidence_intervals, spec_limits
from ._options import CapabilityOptions
from ._sigma import SigmaEstimate, as_groups, sigma_within


@dataclass(frozen=True)
class CapabilityResult:
    """Capability indices of one characteristic with intervals; see the module docstring.

    Indices a one-sided specification cannot define are NaN. `sigma_*` are the
    process standard deviations after any gauge-variance subtraction.
    """

    n: int
    mean: float
    sigma_within: float
    sigma_overall: float
    sigma_method: str
    df_within: float
    df_overall: float
    gauge_sd: float
    lsl: float | None
    usl: float | None
    target: float | None
    cp: float
    cpl: float
    cpu: float
    cpk: float
    cpm: float
    pp: float
    ppl: float
    ppu: float
    ppk: float
    cp_ci: Interval
    cpl_ci: Interval
    cpu_ci: Interval
    cpk_ci: Interval
    cpm_ci: Interval
    pp_ci: Interval
    ppk_ci: Interval
    confidence: float
    convention: str
    n_subgroups: int | None = None
    subgroup_size: int | None = None
    bayes: BayesCapability | None = None
    # raw statistics kept for predictions (before gauge subtraction)
    sd_overall_observed: float = math.nan
    sd_within_observed: float = math.nan

    def table(self) -> list[dict]:
        """One row per index: `index, value, lower, upper` (and Bayesian columns)."""
        rows = []
        for name in ("cp", "cpl", "cpu", "cpk", "cpm", "pp", "ppk"):
            ci = getattr(self, f"{name}_ci")
            row = {
                "index": name,
                "value": getattr(self, name),
                "lower": ci.lower,
                "upper": ci.upper,
            }
            if self.bayes is not None and name in ("cp", "cpk", "cpm"):
                b = self.bayes
                row["bayes_median"] = getattr(b, name)
                bi = getattr(b, f"{name}_interval")
                row["bayes_lower"], row["bayes_upper"] = bi.lower, bi.upper
            rows.append(row)
        return rows

    def __repr__(self) -> str:
        lines = [
            f"CapabilityResult(n={self.n}, mean={self.mean:.6g}, "
            f"sigma_within={self.sigma_within:.4g}"
            f" [{self.sigma_method}, df={self.df_within:.1f}], sigma_overall="
            f"{self.sigma_overall:.4g}, spec=[{self.lsl}, {self.usl}], target={self.target},"
            f" {self.confidence:.0%} intervals, convention={self.convention!r})"
        ]
        for name in ("cp", "cpk", "cpm", "pp", "ppk"):
            v = getattr(self, name)
            if not math.isnan(v):
                lines.append(f"  {name.capitalize():4s} {v:8.4f} {getattr(self, name + '_ci')!r}")
        if self.bayes is not None:
            lines.append(f"  {self.bayes!r}")
        return "\n".join(lines)


def _gauge_adjust(sigma: float, df: float, gauge_sd: float, what: str) -> tuple[float, float]:
    if gauge_sd == 0.0:
        return sigma, df
    var_p = sigma**2 - gauge_sd**2
    if var_p <= 0.0:
        raise AnalysisError(
            f"gauge variance ({gauge_sd:.3g}^2) is not smaller than the observed {what} variance "
            f"({sigma:.3g}^2): the measurement system cannot resolve this process"
        )
    return math.sqrt(var_p), df * (var_p / sigma**2) ** 2


def capability(
    data,
    lsl: float | None = None,
    usl: float | None = None,
    *,
    target: float | None = None,
    subgroups=None,
    gauge_sd: float = 0.0,
    options: CapabilityOptions = CapabilityOptions(),
) -> CapabilityResult:
    """Capability indices Cp, Cpk, Cpm (within sigma) and Pp, Ppk (overall sigma).

    **Arguments:**

    - `data`: values of one characteristic (mm), see [`sigma_within`][] for layouts.
    - `lsl`, `usl`: specification limits (one may be `None`); `target` defaults to
      their mid-point (Cpm needs both limits).
    - `gauge_sd`: standard deviation of the measurement (repeatability) to subtract.
    - `options`: a [`CapabilityOptions`][]: `sigma_method` and `convention` (see
      [`sigma_within`][] and the module docstring), `confidence` (level of the
      two-sided confidence and credible intervals), `bayes` (also posterior
      medians/intervals and $P(C_{pk} >$ `threshold`$)$ from `n_draws` draws seeded
      by `seed`).

    **Returns:** a [`CapabilityResult`][].

    Raises `InputError` for bad data or limits and `AnalysisError` when the gauge
    variance swallows the process variance.
    """
    _check_gauge(gauge_sd)
    confidence, convention = options.confidence, options.convention
    lsl, usl, target = spec_limits(lsl, usl, target)
    y, groups = as_groups(data, subgroups)
    n = int(y.size)
    mu = float(np.mean(y))
    est, s_all = _observed_sigmas(y, groups, options.sigma_method, convention)
    sig_w, nu_w = _gauge_adjust(est.value, est.df, gauge_sd, "within")
    sig_o, nu_o = _gauge_adjust(s_all, float(n - 1), gauge_sd, "overall")
    within = capability_indices(mu, sig_w, lsl, usl, target)  # cp, cpl, cpu, cpk, cpm
    overall = capability_indices(mu, sig_o, lsl, usl, target)  # pp, ppl, ppu, ppk, (cpm)
    intervals = confidence_intervals(
        within, overall, n, mu, target, sig_w, nu_w, nu_o, confidence, convention
    )
    bayes_res = bayes_capability(y, lsl, usl, target, gauge_sd, options) if options.bayes else None
    return CapabilityResult(
        n=n,
        mean=mu,
        sigma_within=sig_w,
        sigma_overall=sig_o,
        sigma_method=est.method,
        df_within=nu_w,
        df_overall=nu_o,
        gauge_sd=float(gauge_sd),
        lsl=lsl,
        usl=usl,
        target=target,
        **dict(zip(("cp", "cpl", "cpu", "cpk", "cpm"), within, strict=True)),
        **dict(zip(("pp", "ppl", "ppu", "ppk"), overall[:4], strict=True)),
        **intervals,
        confidence=confidence,
        convention=convention,
        n_subgroups=None if groups is None else len(groups),
        subgroup_size=_common_size(groups),
        bayes=bayes_res,
        sd_overall_observed=s_all,
        sd_within_observed=est.value,
    )


def _check_gauge(gauge_sd: float) -> None:
    if not (math.isfinite(gauge_sd) and gauge_sd >= 0.0):
        raise InputError(f"gauge_sd must be a finite number >= 0, got {gauge_sd!r}", value=gauge_sd)


def _observed_sigmas(y, groups, method, convention) -> tuple[SigmaEstimate, float]:
    """The within-sigma estimate and the overall sample sd, before any gauge subtraction."""
    est = sigma_within(y if groups is None else groups, method=method, convention=convention)
    s_all = float(np.std(y, ddof=1))
    if est.value <= 0.0 or s_all <= 0.0:
        raise AnalysisError("all values are equal: the process standard deviation is zero")
    return est, s_all


def _common_size(groups) -> int | None:
    """The subgroup size when all subgroups have one, else None (also for individuals)."""
    if groups is None or len({g.size for g in groups}) != 1:
        return None
    return int(groups[0].size)
