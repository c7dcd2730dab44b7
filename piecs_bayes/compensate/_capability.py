"""Process capability: Cp, Cpk, Pp, Ppk, Cpm with confidence and credible intervals,
a stability check (individuals and moving-range chart), and the capability predicted
after a compensation that removes a mean offset.

Everything here works on plain numbers (one value per part and feature, in mm);
reading probe files and fitting parts is done elsewhere.

**Indices.** With specification limits $L$, $U$, target $T$ (default the mid-point),
mean $\\bar y$ and a process standard deviation $\\sigma$:

- $C_p = (U-L)/(6\\sigma)$, $C_{pl} = (\\bar y - L)/(3\\sigma)$,
  $C_{pu} = (U-\\bar y)/(3\\sigma)$, $C_{pk} = \\min(C_{pl}, C_{pu})$,
  $C_{pm} = (U-L)/(6\\sqrt{\\sigma^2 + (\\bar y - T)^2})$;
- Cp, Cpk, Cpm use the **within** (short-term) sigma: $\\bar R/d_2$ or
  $\\bar S/c_4$ for subgroups, $\\overline{MR}/d_2(2)$ for individuals;
  Pp, Ppk use the **overall** sample standard deviation $s$ of all values.

**Confidence intervals** (level $1-\\alpha$, $z = \\Phi^{-1}(1-\\alpha/2)$, $n$ values,
$\\nu$ degrees of freedom of the sigma estimate):

- Cp, Pp (chi-square): $\\hat C_p\\sqrt{\\chi^2_{\\alpha/2,\\nu}/\\nu}$ to
  $\\hat C_p\\sqrt{\\chi^2_{1-\\alpha/2,\\nu}/\\nu}$;
- Cpk, Ppk, Cpl, Cpu (Bissell 1990, normal approximation):
  $\\hat C\\,(1 \\mp z\\sqrt{1/(9n\\hat C^2) + 1/(2\\nu)})$;
- Cpm (Boyles 1991, moment-matched chi-square):
  $\\hat C_{pm}\\sqrt{\\chi^2_{q,\\nu_m}/\\nu_m}$ with
  $\\nu_m = (1+r^2)^2/(1/\\nu + 2r^2/n)$, $r = (\\bar y - T)/\\hat\\sigma$
  (equal to Boyles' $n(1+r^2)^2/(1+2r^2)$ when $\\nu = n$).

`convention="piecs"` (default) uses exact $d_2, c_4$, the *effective* degrees
of freedom of the sigma estimate (Patnaik: $\\nu = 1/(2\\,\\mathrm{Var}(\\hat\\sigma/\\sigma))$;
$\\bar R$: $m d_2^2/(2 d_3^2)$; $\\bar S$: $m c_4^2/(2(1-c_4^2))$; $\\overline{MR}$:
about $0.6(n-1)$ from the correlation of neighbouring ranges; overall $s$: $n-1$),
and the formulas above. `convention="qcc"` reproduces R's `qcc::process.capability`
(and Montgomery's worked examples): 3-decimal table constants, $\\nu = n-1$ whatever the
sigma estimator, Cpl/Cpu limits with the one-sided $z_{1-\\alpha}$, and the Cpm degrees
of freedom $n(1+r^2)/(1+2r^2)$. With $\\bar R$ or $\\overline{MR}$ sigmas the qcc intervals
are too narrow (the estimate has fewer than $n-1$ degrees of freedom).

**Bayesian credible intervals** treat the values as i.i.d. normal with the prior
$p(\\mu,\\sigma)\\propto 1/\\sigma$: $\\sigma^2\\mid y \\sim (n-1)s^2/\\chi^2_{n-1}$,
$\\mu\\mid\\sigma,y \\sim N(\\bar y, \\sigma^2/n)$; indices are computed draw by draw
(Cp's interval is closed form and equals the chi-square interval of Pp).

**Gauge variance** $u_g^2$ (measurement repeatability) is subtracted from every
variance: $\\sigma_p^2 = \\sigma^2 - u_g^2$; the intervals then use
$\\nu_p = \\nu(\\sigma_p^2/\\sigma^2)^2$ (delta method), and Bayesian draws with
$\\sigma^2 \\le u_g^2$ are discarded.

**Stability**: individuals chart $\\bar y \\pm 3\\overline{MR}/d_2(2)$, moving-range
chart upper limit $D_4\\overline{MR}$ ($D_4 = 1 + 3d_3/d_2 = 3.267$); rule 1 (a point
beyond 3 sigma), a run of `run_length` (8) points on one side of the centre line, a
trend of `trend_length` (7) points steadily rising or falling; moving ranges above
their limit (reported); and the most likely step position (two-sample t over all split
points).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal

import numpy as np
from scipy import integrate, special, stats

from ..errors import AnalysisError, InputError

__all__ = [
    "BayesCapability",
    "CapabilityResult",
    "Interval",
    "PredictedCapability",
    "SigmaEstimate",
    "StabilityResult",
    "c4_constant",
    "capability",
    "d2_constant",
    "predict_capability",
    "sigma_within",
    "stability_check",
]

Convention = Literal["piecs", "qcc"]
_CONVENTIONS = ("piecs", "qcc")
_METHODS = ("auto", "rbar", "sbar", "pooled", "mr", "overall")


# --------------------------------------------------------------------------- constants


@lru_cache(maxsize=64)
def _range_moments(n: int) -> tuple[float, float]:
    """$E[W]$ and $E[W^2]$ of the range $W$ of $n$ standard normal values.

    $E[W] = \\int 1 - \\Phi^n - (1-\\Phi)^n\\,dx$;
    $E[W^2] = \\int_0^\\infty 2w(1 - F_W(w))\\,dw$ with
    $F_W(w) = n\\int \\phi(x)[\\Phi(x+w) - \\Phi(x)]^{n-1}dx$ (Simpson, ~1e-11).
    """
    x = np.linspace(-8.5, 8.5, 681)
    cdf = special.ndtr(x)
    ew = integrate.simpson(1.0 - cdf**n - (1.0 - cdf) ** n, x=x)
    w = np.linspace(0.0, 12.0, 481)
    pdf = np.exp(-0.5 * x**2) / math.sqrt(2 * math.pi)
    inner = (special.ndtr(x[None, :] + w[:, None]) - cdf[None, :]) ** (n - 1)
    fw = n * integrate.simpson(pdf[None, :] * inner, x=x, axis=1)
    ew2 = integrate.simpson(2.0 * w * (1.0 - fw), x=w)
    return float(ew), float(ew2)


def d2_constant(n: int, *, convention: Convention = "piecs") -> float:
    """Control-chart constant $d_2(n) = E[R]/\\sigma$ for subgroups of size `n` (2..50).

    `convention="qcc"` returns the 3-decimal table value (Montgomery, Appendix VI).
    """
    if not 2 <= int(n) <= 50:
        raise InputError(f"subgroup size must be 2..50 for d2, got {n}", value=n)
    if n == 2:
        exact = 2.0 / math.sqrt(math.pi)
    else:
        exact = _range_moments(int(n))[0]
    return round(exact, 3) if convention == "qcc" else exact


def _d3_constant(n: int) -> float:
    if n == 2:
        return math.sqrt(2.0 - 4.0 / math.pi)
    ew, ew2 = _range_moments(int(n))
    return math.sqrt(ew2 - ew**2)


def c4_constant(n: int, *, convention: Convention = "piecs") -> float:
    """$c_4(n) = E[S]/\\sigma = \\sqrt{2/(n-1)}\\,\\Gamma(n/2)/\\Gamma((n-1)/2)$.

    `convention="qcc"` rounds to the 4-decimal table value.
    """
    if n < 2:
        raise InputError(f"c4 needs n >= 2, got {n}", value=n)
    v = math.sqrt(2.0 / (n - 1)) * math.exp(special.gammaln(n / 2) - special.gammaln((n - 1) / 2))
    return round(v, 4) if convention == "qcc" else v


def _mr_sigma_df(k: int) -> float:
    """Effective degrees of freedom of $\\overline{MR}/d_2(2)$ from `k` moving ranges.

    $\\mathrm{Var}(\\overline{MR}) = \\sigma^2[k v + 2(k-1)c]/k^2$ with $v = 2-4/\\pi$ and
    $c = (4/\\pi)(\\sqrt3/2 + \\pi/12 - 1)$ (neighbouring ranges share a value).
    """
    v = 2.0 - 4.0 / math.pi
    c = (4.0 / math.pi) * (math.sqrt(3.0) / 2.0 + math.pi / 12.0 - 1.0)
    var_mr = (k * v + 2.0 * (k - 1) * c) / k**2
    var_sigma = var_mr / (4.0 / math.pi)
    return 1.0 / (2.0 * var_sigma)


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class Interval:
    """A two-sided interval `[lower, upper]` at probability/confidence `level`."""

    lower: float
    upper: float
    level: float

    def __iter__(self):
        return iter((self.lower, self.upper))

    def __contains__(self, value: float) -> bool:
        return self.lower <= value <= self.upper

    def __repr__(self) -> str:
        return f"[{self.lower:.4g}, {self.upper:.4g}] ({self.level:.0%})"


_NAN_INTERVAL = (math.nan, math.nan)


@dataclass(frozen=True)
class SigmaEstimate:
    """A standard-deviation estimate with its method and effective degrees of freedom."""

    value: float
    method: str
    df: float

    def __repr__(self) -> str:
        return f"SigmaEstimate({self.value:.6g}, method={self.method!r}, df={self.df:.1f})"


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


@dataclass(frozen=True)
class StabilityResult:
    """Individuals / moving-range chart of values in time order, with rule violations.

    Index tuples refer to positions in the input. `step_index` is the first index
    of the most likely second segment, `step_t` its two-sample t statistic
    (using the moving-range sigma); a value above ~4 is a clear step.
    """

    n: int
    center: float
    sigma: float
    lcl: float
    ucl: float
    mr_center: float
    mr_ucl: float
    beyond_limits: tuple[int, ...]
    run_points: tuple[int, ...]
    trend_points: tuple[int, ...]
    mr_beyond: tuple[int, ...]
    runs: tuple[tuple[int, int], ...]
    trends: tuple[tuple[int, int], ...]
    step_index: int | None
    step_size: float
    step_t: float
    run_length: int
    trend_length: int

    @property
    def out_of_control(self) -> tuple[int, ...]:
        """Indices flagged by any rule (sorted)."""
        return tuple(
            sorted(set(self.beyond_limits) | set(self.run_points) | set(self.trend_points))
        )

    @property
    def in_control(self) -> bool:
        """True when no individuals-chart rule fires (moving ranges are only reported)."""
        return not self.out_of_control

    def reasons(self) -> list[str]:
        """Human-readable list of violations."""
        out = []
        if self.beyond_limits:
            out.append(
                f"{len(self.beyond_limits)} point(s) beyond 3 sigma: {list(self.beyond_limits)}"
            )
        for a, b in self.runs:
            out.append(f"run of {b - a + 1} points on one side of the centre line: {a}..{b}")
        for a, b in self.trends:
            out.append(f"trend of {b - a + 1} points steadily rising or falling: {a}..{b}")
        if self.mr_beyond:
            out.append(f"moving range above its limit at {list(self.mr_beyond)}")
        if self.step_index is not None and abs(self.step_t) > 4.0:
            out.append(
                f"likely step of {self.step_size:+.4g} before index {self.step_index}"
                f" (t = {self.step_t:.1f})"
            )
        return out

    def __repr__(self) -> str:
        state = "in control" if self.in_control else "OUT OF CONTROL"
        head = (
            f"StabilityResult(n={self.n}, {state}, centre={self.center:.6g}, "
            f"limits=[{self.lcl:.6g}, {self.ucl:.6g}], MR UCL={self.mr_ucl:.4g})"
        )
        return "\n".join([head, *(f"  - {r}" for r in self.reasons())])


# --------------------------------------------------------------------------- input


def _check_convention(convention: str) -> None:
    if convention not in _CONVENTIONS:
        raise InputError(f"unknown convention {convention!r}; expected one of {_CONVENTIONS}")


def _as_groups(data, subgroups) -> tuple[np.ndarray, list[np.ndarray] | None]:
    """Flatten the input; return (all values, subgroups or None for individuals)."""
    if subgroups is not None:
        y = np.asarray(data, dtype=float)
        labels = np.asarray(subgroups)
        if y.ndim != 1 or labels.shape != y.shape:
            raise InputError(
                f"subgroups must be one label per value: got {labels.shape} labels for "
                f"{y.shape} values"
            )
        _, first = np.unique(labels, return_index=True)
        order = np.argsort(first)  # subgroups in order of first appearance
        keys = np.unique(labels)[order]
        groups = [y[labels == k] for k in keys]
    elif isinstance(data, np.ndarray) or not _is_ragged(data):
        arr = np.asarray(data, dtype=float)
        if arr.ndim == 1:
            groups = None
        elif arr.ndim == 2:
            groups = [row for row in arr]
        else:
            raise InputError(f"data must be 1-D (individuals) or 2-D (subgroups), got {arr.ndim}-D")
    else:
        groups = [np.asarray(g, dtype=float).ravel() for g in data]
    y = np.concatenate(groups) if groups is not None else np.asarray(data, dtype=float).ravel()
    bad = np.flatnonzero(~np.isfinite(y))
    if bad.size:
        raise InputError(
            f"capability data must be finite numbers; value {int(bad[0])} is {float(y[bad[0]])!r}",
            value=float(y[bad[0]]),
        )
    if y.size < 2:
        raise InputError(f"capability needs at least 2 values, got {y.size}")
    return y, groups


def _is_ragged(data) -> bool:
    if not isinstance(data, Sequence) or isinstance(data, str | bytes) or len(data) == 0:
        return False
    first = data[0]
    if not isinstance(first, Sequence | np.ndarray):
        return False
    sizes = {len(g) for g in data}
    return len(sizes) > 1


def sigma_within(
    data,
    *,
    subgroups=None,
    method: str = "auto",
    convention: Convention = "piecs",
) -> SigmaEstimate:
    """Within-subgroup (short-term) standard deviation.

    **Arguments:**

    - `data`: 1-D values in time order (individuals), a 2-D array (one row per
      subgroup), a list of 1-D subgroups, or 1-D values with `subgroups` labels.
    - `method`: `"auto"` (`"rbar"` for subgroups, `"mr"` for individuals), `"rbar"`
      ($\\bar R/d_2$), `"sbar"` ($\\bar S/c_4$), `"pooled"` ($s_p/c_4(\\nu+1)$, any sizes),
      `"mr"` ($\\overline{MR}/d_2(2)$), `"overall"` (sample sd, $n-1$).
    - `convention`: `"piecs"` or `"qcc"` (table constants, $\\nu = n - 1$).

    **Returns:** a [`SigmaEstimate`][] with its effective degrees of freedom.
    """
    _check_convention(convention)
    if method not in _METHODS:
        raise InputError(f"unknown sigma method {method!r}; expected one of {_METHODS}")
    y, groups = _as_groups(data, subgroups)
    n = y.size
    if method == "auto":
        method = "mr" if groups is None or all(g.size == 1 for g in groups) else "rbar"
    if method == "overall":
        return SigmaEstimate(float(np.std(y, ddof=1)), "overall", float(n - 1))
    if method == "mr":
        if n < 3:
            raise InputError(f"moving-range sigma needs at least 3 values, got {n}")
        mr = np.abs(np.diff(y))
        sigma = float(mr.mean() / d2_constant(2, convention=convention))
        df = float(n - 1) if convention == "qcc" else _mr_sigma_df(n - 1)
        return SigmaEstimate(sigma, "mr", df)
    if groups is None:
        raise InputError(f"sigma method {method!r} needs subgroups; got individual values")
    sizes = np.array([g.size for g in groups])
    if np.any(sizes < 2):
        raise InputError(
            f"every subgroup needs at least 2 values for method {method!r}; "
            f"subgroup {int(np.argmin(sizes))} has {int(sizes.min())}"
        )
    m = len(groups)
    if method == "pooled":
        dof = int(np.sum(sizes - 1))
        sp = math.sqrt(sum(float(np.var(g, ddof=1)) * (g.size - 1) for g in groups) / dof)
        sigma = sp / c4_constant(dof + 1, convention=convention)
        return SigmaEstimate(sigma, "pooled", float(n - 1 if convention == "qcc" else dof))
    if np.unique(sizes).size != 1:
        raise InputError(
            f"method {method!r} needs subgroups of equal size; got sizes "
            f"{sorted(set(sizes.tolist()))}; use method='pooled'"
        )
    k = int(sizes[0])
    if method == "rbar":
        rbar = float(np.mean([np.ptp(g) for g in groups]))
        d2 = d2_constant(k, convention=convention)
        sigma = rbar / d2
        df = float(n - 1) if convention == "qcc" else m * d2**2 / (2.0 * _d3_constant(k) ** 2)
        return SigmaEstimate(sigma, "rbar", df)
    # sbar
    sbar = float(np.mean([np.std(g, ddof=1) for g in groups]))
    c4 = c4_constant(k, convention=convention)
    df = float(n - 1) if convention == "qcc" else m * c4**2 / (2.0 * (1.0 - c4**2))
    return SigmaEstimate(sbar / c4, "sbar", df)


# --------------------------------------------------------------------------- indices


def _limits(lsl, usl, target):
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


def _indices(mu, sigma, lsl, usl, target):
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
        return Interval(*_NAN_INTERVAL, level)
    lo, hi = stats.chi2.ppf([alpha / 2, 1 - alpha / 2], nu)
    return Interval(c * math.sqrt(lo / nu), c * math.sqrt(hi / nu), level)


def _bissell(c, n, nu, z, level) -> Interval:
    if not math.isfinite(c) or c == 0.0:
        return Interval(*_NAN_INTERVAL, level)
    half = z * math.sqrt(1.0 / (9.0 * n * c**2) + 1.0 / (2.0 * nu))
    return Interval(c * (1 - half), c * (1 + half), level)


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
    sigma_method: str = "auto",
    confidence: float = 0.95,
    gauge_sd: float = 0.0,
    convention: Convention = "piecs",
    bayes: bool = True,
    threshold: float = 1.33,
    n_draws: int = 200_000,
    seed: int = 0,
) -> CapabilityResult:
    """Capability indices Cp, Cpk, Cpm (within sigma) and Pp, Ppk (overall sigma).

    **Arguments:**

    - `data`: values of one characteristic (mm), see [`sigma_within`][] for layouts.
    - `lsl`, `usl`: specification limits (one may be `None`); `target` defaults to
      their mid-point (Cpm needs both limits).
    - `sigma_method`, `convention`: see [`sigma_within`][] and the module docstring.
    - `confidence`: level of the two-sided confidence and credible intervals.
    - `gauge_sd`: standard deviation of the measurement (repeatability) to subtract.
    - `bayes`: also compute posterior medians/intervals and $P(C_{pk} >$ `threshold`$)$
      from `n_draws` draws (seeded by `seed`).

    **Returns:** a [`CapabilityResult`][].

    Raises `InputError` for bad data or limits and `AnalysisError` when the gauge
    variance swallows the process variance.
    """
    _check_convention(convention)
    if not 0.0 < confidence < 1.0:
        raise InputError(f"confidence must be in (0, 1), got {confidence!r}", value=confidence)
    if not (math.isfinite(gauge_sd) and gauge_sd >= 0.0):
        raise InputError(f"gauge_sd must be a finite number >= 0, got {gauge_sd!r}", value=gauge_sd)
    lsl, usl, target = _limits(lsl, usl, target)
    y, groups = _as_groups(data, subgroups)
    n = int(y.size)
    mu = float(np.mean(y))
    est = sigma_within(y if groups is None else groups, method=sigma_method, convention=convention)
    s_all = float(np.std(y, ddof=1))
    if est.value <= 0.0 or s_all <= 0.0:
        raise AnalysisError("all values are equal: the process standard deviation is zero")
    sig_w, nu_w = _gauge_adjust(est.value, est.df, gauge_sd, "within")
    sig_o, nu_o = _gauge_adjust(s_all, float(n - 1), gauge_sd, "overall")

    alpha = 1.0 - confidence
    z2 = float(stats.norm.ppf(1 - alpha / 2))
    z1 = float(stats.norm.ppf(confidence)) if convention == "qcc" else z2

    cp, cpl, cpu, cpk, cpm = _indices(mu, sig_w, lsl, usl, target)
    pp, ppl, ppu, ppk, _ = _indices(mu, sig_o, lsl, usl, target)

    if math.isfinite(cpm):
        r = (mu - target) / sig_w
        if convention == "qcc":
            nu_m = n * (1 + r**2) / (1 + 2 * r**2)
        else:
            nu_m = (1 + r**2) ** 2 / (1 / nu_w + 2 * r**2 / n)
        cpm_ci = _chi2_interval(cpm, nu_m, alpha, confidence)
    else:
        cpm_ci = Interval(*_NAN_INTERVAL, confidence)

    bayes_res = None
    if bayes:
        bayes_res = _bayes_capability(
            y, lsl, usl, target, gauge_sd, confidence, threshold, n_draws, seed
        )
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
        cp=cp,
        cpl=cpl,
        cpu=cpu,
        cpk=cpk,
        cpm=cpm,
        pp=pp,
        ppl=ppl,
        ppu=ppu,
        ppk=ppk,
        cp_ci=_chi2_interval(cp, nu_w, alpha, confidence),
        cpl_ci=_bissell(cpl, n, nu_w, z1, confidence),
        cpu_ci=_bissell(cpu, n, nu_w, z1, confidence),
        cpk_ci=_bissell(cpk, n, nu_w, z2, confidence),
        cpm_ci=cpm_ci,
        pp_ci=_chi2_interval(pp, nu_o, alpha, confidence),
        ppk_ci=_bissell(ppk, n, nu_o, z2, confidence),
        confidence=confidence,
        convention=convention,
        n_subgroups=None if groups is None else len(groups),
        subgroup_size=(
            None if groups is None or len({g.size for g in groups}) != 1 else int(groups[0].size)
        ),
        bayes=bayes_res,
        sd_overall_observed=s_all,
        sd_within_observed=est.value,
    )


def _posterior_draws(n, ybar, s, nu, n_draws, seed):
    rng = np.random.default_rng(seed)
    var = nu * s**2 / rng.chisquare(nu, size=n_draws)
    mu = ybar + np.sqrt(var / n) * rng.standard_normal(n_draws)
    return rng, mu, var


def _draw_indices(mu, sd, lsl, usl, target):
    with np.errstate(invalid="ignore"):
        cpl = (mu - lsl) / (3 * sd) if lsl is not None else np.full_like(sd, np.inf)
        cpu = (usl - mu) / (3 * sd) if usl is not None else np.full_like(sd, np.inf)
    cpk = np.minimum(cpl, cpu)
    cp = (usl - lsl) / (6 * sd) if lsl is not None and usl is not None else None
    cpm = None
    if cp is not None and target is not None:
        cpm = (usl - lsl) / (6 * np.sqrt(sd**2 + (mu - target) ** 2))
    return cp, cpk, cpm


def _summary(x, level) -> tuple[float, Interval]:
    if x is None:
        return math.nan, Interval(*_NAN_INTERVAL, level)
    q = np.quantile(x, [0.5, (1 - level) / 2, (1 + level) / 2])
    return float(q[0]), Interval(float(q[1]), float(q[2]), level)


def _bayes_capability(y, lsl, usl, target, gauge_sd, level, threshold, n_draws, seed):
    n = y.size
    ybar, s = float(y.mean()), float(np.std(y, ddof=1))
    _, mu, var = _posterior_draws(n, ybar, s, n - 1, n_draws, seed)
    var_p = var - gauge_sd**2
    keep = var_p > 0.0
    discarded = 1.0 - float(keep.mean())
    if discarded > 0.5:
        raise AnalysisError(
            f"gauge variance exceeds the process variance in {discarded:.0%} of the posterior "
            "draws: the measurement system cannot resolve this process"
        )
    mu, sd = mu[keep], np.sqrt(var_p[keep])
    cp, cpk, cpm = _draw_indices(mu, sd, lsl, usl, target)
    cp_med, cp_int = _summary(cp, level)
    if gauge_sd == 0.0 and cp is not None:  # closed form: Cp = Cp_hat * sqrt(chi2_nu / nu)
        c = (usl - lsl) / (6 * s)
        q = stats.chi2.ppf([0.5, (1 - level) / 2, (1 + level) / 2], n - 1) / (n - 1)
        cp_med, cp_int = (
            float(c * math.sqrt(q[0])),
            Interval(float(c * math.sqrt(q[1])), float(c * math.sqrt(q[2])), level),
        )
    cpk_med, cpk_int = _summary(cpk, level)
    cpm_med, cpm_int = _summary(cpm, level)
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


# --------------------------------------------------------------------------- prediction


def predict_capability(
    result: CapabilityResult,
    *,
    offset: float | None = None,
    u_offset: float = 0.0,
    gain: float = 1.0,
    sigma: Literal["overall", "within"] = "overall",
    threshold: float = 1.33,
    n_draws: int = 200_000,
    seed: int = 0,
) -> PredictedCapability:
    """Capability after a compensation that shifts the process mean by `-gain * offset`.

    **Arguments:**

    - `result`: the capability study of the process before compensation.
    - `offset`: the mean error to remove (mm); default $\\bar y - T$ (centre the process).
    - `u_offset`: standard uncertainty of the realised shift (mm): how far the mean may
      land from where it is aimed (adjustment resolution/repeatability, and the
      uncertainty of `offset` when it was estimated from other data than `result`).
    - `gain`: fraction of the offset applied (1 = full compensation).
    - `sigma`: `"overall"` (default; long-term spread stays) or `"within"` (assume the
      compensation also removes the between-part drift).

    **Returns:** a [`PredictedCapability`][]; the spread is unchanged, only the mean moves.
    """
    if sigma not in ("overall", "within"):
        raise InputError(f"sigma must be 'overall' or 'within', got {sigma!r}", value=sigma)
    for name, v in (("u_offset", u_offset), ("gain", gain)):
        if not (math.isfinite(v) and v >= 0.0):
            raise InputError(f"{name} must be a finite number >= 0, got {v!r}", value=v)
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
    cp, _, _, cpk, cpm = _indices(mean_after, sd, lsl, usl, target)
    n_eff = 1.0 / (1.0 / n + (gain * u_offset) ** 2 / sd**2)
    z = float(stats.norm.ppf(1 - (1 - result.confidence) / 2))
    cpk_ci = _bissell(cpk, n_eff, nu, z, result.confidence)

    nu_obs = nu / ((sd**2 / s_obs**2) ** 2) if result.gauge_sd > 0 else nu
    rng, mu, var = _posterior_draws(n, result.mean, s_obs, nu_obs, n_draws, seed)
    var_p = var - result.gauge_sd**2
    keep = var_p > 0.0
    mu = mu[keep] - gain * offset + gain * u_offset * rng.standard_normal(int(keep.sum()))
    _, cpk_draws, _ = _draw_indices(mu, np.sqrt(var_p[keep]), lsl, usl, target)
    med, interval = _summary(cpk_draws, result.confidence)
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


# --------------------------------------------------------------------------- stability


def _runs(mask: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    """Maximal runs of True in `mask` with length >= `min_len` as (start, end) inclusive."""
    out = []
    start = None
    for i, v in enumerate(np.append(mask, False)):
        if v and start is None:
            start = i
        elif not v and start is not None:
            if i - start >= min_len:
                out.append((start, i - 1))
            start = None
    return out


def stability_check(
    values,
    *,
    center: float | None = None,
    sigma: float | None = None,
    run_length: int = 8,
    trend_length: int = 7,
) -> StabilityResult:
    """Individuals and moving-range chart with Western Electric / Nelson rules.

    **Arguments:**

    - `values`: one value per part, in production order.
    - `center`, `sigma`: known centre line and sigma (Phase II); by default the mean
      and $\\overline{MR}/d_2(2)$ of `values` (Phase I).
    - `run_length`: points in a row on one side of the centre line that signal a
      shift (8, Western Electric; Nelson uses 9); `trend_length`: points in a row
      steadily rising or falling (7, as AIAG; Nelson's 6 raises ~6 % false alarms in
      30 stable points).

    Moving ranges above $D_4\\overline{MR}$ are reported but do not make the process
    "out of control": about 1 % of the moving ranges of a stable process exceed the
    limit, so a long run almost always has one.

    **Returns:** a [`StabilityResult`][] with the limits, flagged indices and the
    most likely step position.
    """
    y = np.asarray(values, dtype=float).ravel()
    if y.size < 3:
        raise InputError(f"a stability check needs at least 3 values, got {y.size}")
    if not np.all(np.isfinite(y)):
        bad = int(np.flatnonzero(~np.isfinite(y))[0])
        raise InputError(
            f"value {bad} is not a finite number: {float(y[bad])!r}", value=float(y[bad])
        )
    if run_length < 2 or trend_length < 3:
        raise InputError(
            f"run_length must be >= 2 and trend_length >= 3, got {run_length}, {trend_length}"
        )
    mr = np.abs(np.diff(y))
    mr_bar = float(mr.mean())
    d2 = 2.0 / math.sqrt(math.pi)
    d4 = 1.0 + 3.0 * _d3_constant(2) / d2
    c = float(y.mean()) if center is None else float(center)
    s = mr_bar / d2 if sigma is None else float(sigma)
    if not s > 0.0:
        raise AnalysisError("the moving-range sigma is zero: all values are equal")
    lcl, ucl = c - 3 * s, c + 3 * s
    beyond = tuple(int(i) for i in np.flatnonzero((y > ucl) | (y < lcl)))
    runs = _runs(y > c, run_length) + _runs(y < c, run_length)
    runs.sort()
    run_pts = tuple(sorted({i for a, b in runs for i in range(a, b + 1)}))
    d = np.diff(y)
    trends = _runs(d > 0, trend_length - 1) + _runs(d < 0, trend_length - 1)
    trends = sorted((a, b + 1) for a, b in trends)  # diff index i links points i and i+1
    trend_pts = tuple(sorted({i for a, b in trends for i in range(a, b + 1)}))
    mr_ucl = d4 * (mr_bar if sigma is None else s * d2)
    mr_beyond = tuple(int(i) + 1 for i in np.flatnonzero(mr > mr_ucl))

    n = y.size
    step_index, step_size, step_t = None, 0.0, 0.0
    if n >= 4:
        k = np.arange(2, n - 1)
        csum = np.cumsum(y)
        m1 = csum[k - 1] / k
        m2 = (csum[-1] - csum[k - 1]) / (n - k)
        t = (m2 - m1) / (s * np.sqrt(1.0 / k + 1.0 / (n - k)))
        j = int(np.argmax(np.abs(t)))
        step_index, step_size, step_t = int(k[j]), float(m2[j] - m1[j]), float(t[j])
    return StabilityResult(
        n=int(n),
        center=c,
        sigma=s,
        lcl=lcl,
        ucl=ucl,
        mr_center=mr_bar,
        mr_ucl=mr_ucl,
        beyond_limits=beyond,
        run_points=run_pts,
        trend_points=trend_pts,
        mr_beyond=mr_beyond,
        runs=tuple(runs),
        trends=tuple(trends),
        step_index=step_index,
        step_size=step_size,
        step_t=step_t,
        run_length=int(run_length),
        trend_length=int(trend_length),
    )
