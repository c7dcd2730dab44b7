r"""Conformity risk of a verdict, JCGM 106:2012: specific and global, with guard bands.

A part is *accepted* when its measured value lies in the acceptance interval
$[T_L + w, T_U - w]$ (guard band $w$), else *rejected*. [`p_nonconforming`][] is the
probability that the measurand lies outside the tolerance given the measurement (normal,
Student-t or posterior draws): the *specific* consumer's risk of an accepted part, one
minus the specific producer's risk of a rejected one (JCGM 106 9.3). [`global_risks`][]
integrates over a process prior $N(\mu_p, \sigma_p^2)$ and the measurement error
$u\,Z$: $R_C = P(\text{out of tolerance and accepted})$ and
$R_P = P(\text{in tolerance and rejected})$, joint probabilities (JCGM 106 9.5), one 1-D
integral each, accurate to about 1e-12. [`guard_band_width`][] picks $w$ by a
[`GuardBand`][] rule: none, fixed, a target $R_C$ (root found to 1e-12 of the tolerance)
or a TUR rule (RSS, Dobbert, RP-10, test95, 4:1). [`conformity_risk`][] returns it all
as a [`ConformityRisk`][]. Lengths in mm; the model and the conventions: docs/risk.md.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np

from .. import _config
from ..errors import AnalysisError, InputError

special = _config.LazyModule("scipy.special")
integrate = _config.LazyModule("scipy.integrate")
optimize = _config.LazyModule("scipy.optimize")

#: process tails beyond this many sd hold less than 2.3e-23 of the parts: not integrated
_Z = 10.0
#: the coverage factor of U in the test uncertainty ratio TUR = (T_U - T_L) / 2 / (2 u)
TUR_COVERAGE = 2.0
#: the rules of `GuardBand`
RULES = ("none", "fixed", "target", "rss", "dobbert", "rp10", "test95", "4:1")
Rule = Literal["none", "fixed", "target", "rss", "dobbert", "rp10", "test95", "4:1"]


# ----------------------------------------------------------------------- inputs


def _number(name: str, v, *, positive: bool = False, finite: bool = True) -> float:
    """`v` as a float, checked: a real number (finite unless `finite` is False), > 0 when
    `positive`; else an InputError naming `name` and the value."""
    ok = not isinstance(v, bool) and isinstance(v, numbers.Real) and not math.isnan(v)
    ok = ok and (math.isfinite(v) or not finite) and (v > 0 or not positive)
    if not ok:
        expected = "a number > 0" if positive else "a finite number"
        if positive and not finite:
            expected = "a number > 0 (or inf)"
        raise InputError(f"{name} must be {expected}, got {v!r}", value=v)
    return float(v)


def _tolerance(tolerance) -> tuple[float, float]:
    """`(T_L, T_U)` with `lower < upper`; `None` or an infinity is a one-sided limit."""
    try:
        lo, hi = (-math.inf if t is None and i == 0 else math.inf if t is None else float(t)
                  for i, t in enumerate(tolerance))  # fmt: skip
    except (TypeError, ValueError):
        raise InputError(
            f"tolerance must be (lower, upper) numbers, got {tolerance!r}", value=tolerance
        ) from None
    if math.isnan(lo) or math.isnan(hi) or not lo < hi or lo == math.inf or hi == -math.inf:
        raise InputError(
            f"tolerance must be (lower, upper) with lower < upper, got ({lo}, {hi})",
            value=tolerance,
        )
    if math.isinf(lo) and math.isinf(hi):
        raise InputError("tolerance needs at least one finite limit, got (-inf, inf)")
    return lo, hi


def _probability(name: str, p) -> float:
    ok = not isinstance(p, bool) and isinstance(p, numbers.Real) and 0.0 < p < 1.0
    if not ok:
        raise InputError(f"{name} must be a probability in (0, 1), got {p!r}", value=p)
    return float(p)


@dataclass(frozen=True)
class ProcessPrior:
    """The process distribution $N(\\mu_p, \\sigma_p^2)$ of the characteristic over parts
    (mm): the prior of the global risks. E.g. a capability study's mean and overall sd."""

    mean: float
    sd: float

    def __post_init__(self):
        object.__setattr__(self, "mean", _number("process mean", self.mean))
        object.__setattr__(self, "sd", _number("process sd", self.sd, positive=True))


@dataclass(frozen=True)
class GuardBand:
    """How the acceptance interval $[T_L + w, T_U - w]$ is chosen.

    - `rule`: `"none"` ($w = 0$, simple acceptance), `"fixed"` ($w$ = `width`, mm; < 0
      relaxes acceptance), `"target"` (the $w \\ge 0$ at which the global consumer's risk
      is `target`; 0 when the tolerance already meets it), or a rule of the test
      uncertainty ratio $\\mathrm{TUR} = (T_U - T_L)/2/(2u)$ on a two-sided tolerance:
      `"rss"` ($A = \\sqrt{T^2 - U^2}$), `"dobbert"` (Dobbert 2008: $w = MU$,
      $M = 1.04 - e^{0.38 \\ln \\mathrm{TUR} - 0.54}$, never below 0), `"rp10"` (NCSLI
      RP-10: $w = U - T/4$) and `"test95"` ($w = U$), both 0 above TUR 4, `"4:1"` (the
      $R_C$ the process would have at TUR 4 without a guard band, as a target).
    - `target`: the global consumer's risk of `"target"`, in (0, 1); default 2 %.
    - `width`: $w$ of `"fixed"` (mm).
    - `max_width`: the largest $w$ allowed (mm); a rule that needs more raises
      InputError. Default: the half-width of the tolerance (no acceptance zone left).
    """

    rule: Rule = "none"
    target: float = 0.02
    width: float | None = None
    max_width: float | None = None

    def __post_init__(self):
        if self.rule not in RULES:
            raise InputError(
                f"unknown guard band rule {self.rule!r}; expected one of {list(RULES)}",
                value=self.rule,
            )
        object.__setattr__(self, "target", _probability("target consumer's risk", self.target))
        if (self.rule == "fixed") != (self.width is not None):
            raise InputError(
                "guard band width: give it with the rule 'fixed' (only), got rule "
                f"{self.rule!r} and width {self.width!r}",
                value=self.width,
            )
        if self.width is not None:
            object.__setattr__(self, "width", _number("guard band width", self.width))
        if self.max_width is not None:
            m = _number("max guard band width", self.max_width)
            if m < 0:
                raise InputError(f"max guard band width must be >= 0, got {m!r}", value=m)
            object.__setattr__(self, "max_width", m)


# ----------------------------------------------------------------- specific risk


def _cdf(dof: float):
    """The standard cdf of the measurement error: normal, or Student-t with `dof`."""
    if math.isfinite(dof):
        return lambda t: special.stdtr(dof, t)
    return special.ndtr


def _p_outside(lo, hi, y, u, cdf):
    """P(X outside [lo, hi]) for X = y + u E, E with cdf `cdf`: the two tails, summed."""
    return cdf((lo - y) / u) + cdf((y - hi) / u)


def _p_inside(lo, hi, y, u, cdf):
    """P(lo < X < hi) for X = y + u E: upper-tail differences on the side away from the
    interval's centre, so that a small probability keeps its relative precision."""
    if math.isinf(lo) or math.isinf(hi):  # one-sided: the finite limit's tail only
        mid = -math.inf if math.isinf(lo) else math.inf
    else:
        mid = (lo + hi) / 2
    above = np.asarray(y) >= mid
    right = cdf((hi - y) / u) - cdf((lo - y) / u)
    left = cdf((y - lo) / u) - cdf((y - hi) / u)
    return np.where(above, right, left)


def p_nonconforming(
    tolerance, *, value: float | None = None, u: float | None = None, dof: float = math.inf,
    samples=None,
) -> float:  # fmt: skip
    """The probability that the measurand lies outside the tolerance, given the
    measurement: $\\Phi((T_L - y)/u) + \\Phi((y - T_U)/u)$, the Student-t cdf with
    finite `dof`, or the fraction of posterior `samples` outside.

    **Arguments:** `tolerance` `(lower, upper)` (mm; `None` or an infinity: one-sided);
    `value`, `u`: the measured value (or posterior mean) and its standard uncertainty
    (mm), with `dof` (effective) degrees of freedom; or `samples`: draws of the
    characteristic (mm).

    **Returns:** the specific consumer's risk if the part is accepted; one minus it is
    the specific producer's risk if it is rejected (JCGM 106 9.3).
    """
    lo, hi = _tolerance(tolerance)
    y, s, smp, dof = _measurement(value, u, dof, samples)
    if smp is not None:
        return float(np.mean((smp < lo) | (smp > hi)))
    return float(_p_outside(lo, hi, y, s, _cdf(dof)))


def _measurement(value, u, dof, samples):
    """`(estimate, u, samples or None, dof)` of the measurement handed in, checked."""
    dof = _number("dof", dof, positive=True, finite=False)
    if samples is not None:
        if value is not None or u is not None or math.isfinite(dof):
            raise InputError("give either value and u (and dof) or samples, not both")
        smp = np.asarray(samples, dtype=float).ravel()
        if smp.size < 2 or not np.all(np.isfinite(smp)):
            raise InputError("samples must be at least 2 finite numbers", value=smp.size)
        return float(smp.mean()), float(smp.std(ddof=1)), smp, math.inf
    if value is None or u is None:
        raise InputError("give the measured value and its standard uncertainty u (or samples)")
    return _number("value", value), _number("u", u, positive=True), None, dof


# ------------------------------------------------------------------- global risk


class GlobalRisks(NamedTuple):
    """JCGM 106 9.5 global risks, joint probabilities over the process:
    `consumer` = P(out of tolerance and accepted), `producer` = P(in tolerance and
    rejected)."""

    consumer: float
    producer: float


def _acceptance(tol, w) -> tuple[float, float]:
    return tol[0] + w, tol[1] - w


def _integral(fn, a, b, process, marks) -> float:
    """$\\int_a^b \\phi_p(x)\\,fn(x)\\,dx$ over the process density, in its standard
    units, with breakpoints at `marks` (limits; steps of width u around them)."""
    m, s = process.mean, process.sd
    za, zb = max((a - m) / s, -_Z), min((b - m) / s, _Z)
    if not za < zb:
        return 0.0
    pts = sorted({(p - m) / s for p in marks if math.isfinite(p) and za < (p - m) / s < zb})
    val, err, *_ = integrate.quad(
        lambda z: math.exp(-0.5 * z * z) * float(fn(m + s * z)),
        za, zb, points=pts or None, epsabs=1e-15, epsrel=1e-12, limit=500, full_output=1,
    )  # fmt: skip
    if not err <= 1e-11:
        raise AnalysisError(
            f"the risk integral did not converge (estimate {val / math.sqrt(2 * math.pi):.3g},"
            f" error {err:.2g})",
            result=val / math.sqrt(2 * math.pi),
        )
    return val / math.sqrt(2 * math.pi)


def _marks(tol, acc, u) -> list[float]:
    """Breakpoints: the limits, and a few u either side of each acceptance limit."""
    out = [*tol, *acc]
    for a in acc:
        out += [a + k * u for k in (-8.0, -3.0, -1.0, 1.0, 3.0, 8.0)]
    return out


def _global(tol, acc, u, process, dof) -> GlobalRisks:
    """$R_C$, $R_P$ for checked inputs (see `global_risks`)."""
    cdf = _cdf(dof)
    lo, hi = tol
    marks = _marks(tol, acc, u)

    def accept(x):
        return _p_inside(acc[0], acc[1], x, u, cdf)

    def reject(x):
        return _p_outside(acc[0], acc[1], x, u, cdf)

    consumer = _integral(accept, -math.inf, lo, process, marks) + _integral(
        accept, hi, math.inf, process, marks
    )
    producer = _integral(reject, lo, hi, process, marks)
    return GlobalRisks(consumer, producer)


def global_risks(
    tolerance, acceptance, *, u: float, process: ProcessPrior, dof: float = math.inf
) -> GlobalRisks:
    """Global consumer's and producer's risks of accepting measured values inside
    `acceptance` for a process `process`, measured with standard uncertainty `u`.

    **Arguments:** `tolerance`, `acceptance`: `(lower, upper)` limits (mm; `None` or an
    infinity: one-sided); `u` (mm) with `dof` degrees of freedom (finite: Student-t
    measurement errors); `process`: the process prior.

    **Returns:** [`GlobalRisks`][] `(consumer, producer)`, each
    $\\int \\phi_p(x)\\,P(\\text{accept}|x)\\,dx$ over the values out of tolerance, or
    $\\int \\phi_p(x)\\,P(\\text{reject}|x)\\,dx$ over those in tolerance.
    """
    tol = _tolerance(tolerance)
    try:
        acc = tuple(-math.inf if a is None and i == 0 else math.inf if a is None else float(a)
                    for i, a in enumerate(acceptance))  # fmt: skip
    except (TypeError, ValueError):
        raise InputError(f"acceptance must be (lower, upper), got {acceptance!r}") from None
    if len(acc) != 2 or math.isnan(acc[0]) or math.isnan(acc[1]) or acc[0] > acc[1]:
        raise InputError(f"acceptance must be (lower, upper), got {acceptance!r}", value=acc)
    u = _number("u", u, positive=True)
    dof = _number("dof", dof, positive=True, finite=False)
    return _global(tol, acc, u, _prior(process), dof)


def _prior(process) -> ProcessPrior:
    if not isinstance(process, ProcessPrior):
        raise InputError(f"process must be a ProcessPrior, got {process!r}", value=process)
    return process


# -------------------------------------------------------------------- guard band


def tur(tolerance, u: float) -> float:
    """Test uncertainty ratio $(T_U - T_L)/2 / (2u)$: the half tolerance over the
    expanded uncertainty at $k = 2$ (suncal's and Z540.3's convention)."""
    lo, hi = _tolerance(tolerance)
    return (hi - lo) / 2.0 / (TUR_COVERAGE * _number("u", u, positive=True))


def _tur_width(rule: str, tol, u) -> float:
    """$w$ of a TUR rule on a two-sided tolerance (see `GuardBand`)."""
    half = (tol[1] - tol[0]) / 2.0
    ratio, big_u = half / (TUR_COVERAGE * u), TUR_COVERAGE * u
    if rule == "rss":
        if ratio <= 1.0:
            raise InputError(f"rule 'rss' needs TUR > 1, got TUR {ratio:.3g}", value=ratio)
        return half - math.sqrt(half**2 - big_u**2)
    if rule == "dobbert":
        return max(0.0, (1.04 - math.exp(0.38 * math.log(ratio) - 0.54)) * big_u)
    if ratio > 4.0:
        return 0.0
    return big_u - half / 4.0 if rule == "rp10" else big_u  # "rp10", "test95"


def guard_band_width(
    tolerance, guard_band: GuardBand, *, u: float, process: ProcessPrior | None = None,
    dof: float = math.inf,
) -> float:  # fmt: skip
    """The guard band $w$ (mm) that `guard_band`'s rule gives: acceptance limits
    $[T_L + w, T_U - w]$ (an infinite limit stays infinite).

    `u` (mm, `dof` degrees of freedom) is the measuring process's standard uncertainty;
    `process` is needed by `"target"` and `"4:1"`. A rule that needs more than
    `max_width` (default: half the tolerance), or a TUR rule on a one-sided tolerance,
    raises InputError.
    """
    tol = _tolerance(tolerance)
    u = _number("u", u, positive=True)
    dof = _number("dof", dof, positive=True, finite=False)
    gb = guard_band
    if not isinstance(gb, GuardBand):
        raise InputError(f"guard_band must be a GuardBand, got {gb!r}", value=gb)
    two_sided = math.isfinite(tol[0]) and math.isfinite(tol[1])
    limit = (tol[1] - tol[0]) / 2.0 if two_sided else math.inf
    if gb.max_width is not None:
        limit = min(limit, gb.max_width)
    if gb.rule == "none":
        return 0.0
    if gb.rule == "fixed":
        w = gb.width
    elif gb.rule in ("target", "4:1"):
        return _target_width(tol, gb, u, _needs_process(gb.rule, process), dof, limit)
    elif not two_sided:
        raise InputError(f"rule {gb.rule!r} needs a two-sided tolerance, got {tol}", value=tol)
    else:
        w = _tur_width(gb.rule, tol, u)
    if w > limit or (two_sided and w >= (tol[1] - tol[0]) / 2.0):
        raise InputError(
            f"guard band rule {gb.rule!r} needs w = {w * 1e3:.4g} µm, more than the "
            f"{limit * 1e3:.4g} µm allowed (TUR {tur(tol, u):.3g})",
            value=w,
        )
    return w


def _needs_process(rule, process) -> ProcessPrior:
    if process is None:
        raise InputError(f"guard band rule {rule!r} needs the process distribution (process)")
    return _prior(process)


def _target_width(tol, gb: GuardBand, u, process, dof, limit) -> float:
    """The $w \\ge 0$ with $R_C(w)$ = target (`"4:1"`: $R_C$ at TUR 4, $w = 0$), by
    Brent's method to 1e-12 of the tolerance's scale; 0 when $R_C(0)$ meets it."""
    target = _rule_target(gb, tol, process)

    def excess(w):
        return _global(tol, _acceptance(tol, w), u, process, dof).consumer - target

    if excess(0.0) <= 0.0:
        return 0.0
    hi = _upper_bracket(excess, tol, u, process, limit)
    scale = min(tol[1] - tol[0], 20.0 * (process.sd + u))
    return float(optimize.brentq(excess, 0.0, hi, xtol=1e-12 * scale, rtol=1e-15))


def _rule_target(gb: GuardBand, tol, process) -> float | None:
    """The target $R_C$ of the rules `"target"` and `"4:1"` (the process's $R_C$ at
    TUR 4 without a guard band, normal errors); None for the other rules."""
    if gb.rule == "target":
        return gb.target
    if gb.rule != "4:1":
        return None
    if not (math.isfinite(tol[0]) and math.isfinite(tol[1])):
        raise InputError(f"rule '4:1' needs a two-sided tolerance, got {tol}", value=tol)
    u4 = (tol[1] - tol[0]) / 2.0 / (4.0 * TUR_COVERAGE)
    return _global(tol, tol, u4, _needs_process("4:1", process), math.inf).consumer


def _upper_bracket(excess, tol, u, process, limit) -> float:
    """A $w \\le$ `limit` with $R_C(w)$ below the target; InputError when there is none."""
    if math.isfinite(limit):
        if excess(limit) > 0.0:
            raise InputError(
                f"no guard band up to {limit * 1e3:.4g} µm reaches the target consumer's "
                f"risk: at that width it is still {excess(limit):+.3g} above the target",
                value=limit,
            )
        return limit
    edge = tol[1] if math.isfinite(tol[1]) else -tol[0]
    centre = process.mean if math.isfinite(tol[1]) else -process.mean
    w = max(edge - centre, 0.0) + 10.0 * (process.sd + u)
    for _ in range(60):
        if excess(w) <= 0.0:
            return w
        w *= 2.0
    raise InputError("no guard band reaches the target consumer's risk", value=w)


# ----------------------------------------------------------------------- result


@dataclass(frozen=True)
class ConformityRisk:
    """The conformity decision on one characteristic and its risks (JCGM 106).

    `acceptance` = `tolerance` narrowed by `guard_band` (mm) by `rule`; `decision` is
    `"accept"` when `estimate` lies in it (closed interval), else `"reject"`.
    `p_nonconforming` = P(out of tolerance | measurement); the specific consumer's risk
    is it when accepted (0 when rejected), the specific producer's risk is
    1 - it when rejected (0 when accepted). The global risks (joint probabilities) and
    `process` are None without a process prior; `tur` is None on a one-sided tolerance;
    `target_consumer_risk` is set by the rules `"target"` and `"4:1"`.
    """

    tolerance: tuple[float, float]
    acceptance: tuple[float, float]
    guard_band: float
    rule: str
    u_measurement: float
    tur: float | None
    estimate: float | None
    decision: Literal["accept", "reject"] | None
    p_nonconforming: float | None
    specific_consumer_risk: float | None
    specific_producer_risk: float | None
    process: ProcessPrior | None
    global_consumer_risk: float | None
    global_producer_risk: float | None
    target_consumer_risk: float | None = None

    def as_dict(self) -> dict:
        """A flat JSON-ready dict (lengths `*_mm`; infinite limits as None)."""

        def mm(x):
            return None if x is None or not math.isfinite(x) else float(x)

        p = self.process
        return {
            "rule": self.rule,
            "decision": self.decision,
            "estimate_mm": mm(self.estimate),
            "tolerance_lower_mm": mm(self.tolerance[0]),
            "tolerance_upper_mm": mm(self.tolerance[1]),
            "acceptance_lower_mm": mm(self.acceptance[0]),
            "acceptance_upper_mm": mm(self.acceptance[1]),
            "guard_band_mm": self.guard_band,
            "u_measurement_mm": self.u_measurement,
            "tur": self.tur,
            "p_nonconforming": self.p_nonconforming,
            "specific_consumer_risk": self.specific_consumer_risk,
            "specific_producer_risk": self.specific_producer_risk,
            "process_mean_mm": None if p is None else p.mean,
            "process_sd_mm": None if p is None else p.sd,
            "global_consumer_risk": self.global_consumer_risk,
            "global_producer_risk": self.global_producer_risk,
            "target_consumer_risk": self.target_consumer_risk,
        }

    def __repr__(self) -> str:
        lo, hi = (f"{a * 1e3:+.2f}" if math.isfinite(a) else f"{a:+}"[0] + "∞"
                  for a in self.acceptance)  # fmt: skip
        head = f"ConformityRisk({self.rule}: acceptance [{lo}, {hi}] µm"
        head += f", w {self.guard_band * 1e3:.2f} µm"
        if self.decision is not None:
            head += (
                f"; {self.decision} {self.estimate * 1e3:+.2f} µm, P(out) "
                f"{self.p_nonconforming:.3g}"
            )
        if self.global_consumer_risk is not None:
            head += (
                f"; global consumer's {self.global_consumer_risk:.3%}, producer's "
                f"{self.global_producer_risk:.3%}"
            )
        return head + ")"


def conformity_risk(
    tolerance, *, value: float | None = None, u: float | None = None, dof: float = math.inf,
    samples=None, process: ProcessPrior | None = None, guard_band: GuardBand | None = None,
    u_measurement: float | None = None,
) -> ConformityRisk:  # fmt: skip
    """The conformity decision on one characteristic with its specific and global risks.

    **Arguments:**

    - `tolerance`: `(lower, upper)` (mm; `None` or an infinity: one-sided).
    - `value`, `u`, `dof`: the measured value (posterior mean) and its standard
      uncertainty (mm) with its degrees of freedom; or `samples`: posterior draws
      (estimate: their mean). Both may be left out for the global risks alone.
    - `process`: the process prior (needed for the global risks, `"target"`, `"4:1"`).
    - `guard_band`: a [`GuardBand`][] (default: none, acceptance = tolerance).
    - `u_measurement`: the measuring process's u for the global risks and the guard
      band (mm); default `u` (or the samples' sd).

    **Returns:** a [`ConformityRisk`][].
    """
    tol = _tolerance(tolerance)
    gb = guard_band if guard_band is not None else GuardBand()
    measured = value is not None or u is not None or samples is not None
    y, s, smp, dof = _measurement(value, u, dof, samples) if measured else (None, None, None, dof)
    u_m = s if u_measurement is None else _number("u_measurement", u_measurement, positive=True)
    if u_m is None:
        raise InputError("give u_measurement (or a measurement) for the global risks")
    dof = _number("dof", dof, positive=True, finite=False)
    w = guard_band_width(tol, gb, u=u_m, process=process, dof=dof)
    acc = _acceptance(tol, w)
    spec = _specific(tol, acc, y, s, smp, dof) if measured else (None, None, None, None)
    glob = _global(tol, acc, u_m, _prior(process), dof) if process is not None else None
    two_sided = math.isfinite(tol[0]) and math.isfinite(tol[1])
    return ConformityRisk(
        tolerance=tol,
        acceptance=acc,
        guard_band=float(w),
        rule=gb.rule,
        u_measurement=float(u_m),
        tur=tur(tol, u_m) if two_sided else None,
        estimate=y,
        decision=spec[0],
        p_nonconforming=spec[1],
        specific_consumer_risk=spec[2],
        specific_producer_risk=spec[3],
        process=process,
        global_consumer_risk=None if glob is None else glob.consumer,
        global_producer_risk=None if glob is None else glob.producer,
        target_consumer_risk=_rule_target(gb, tol, process),
    )


def _specific(tol, acc, y, s, smp, dof):
    """`(decision, P(out), specific consumer's risk, specific producer's risk)`."""
    accepted = acc[0] <= y <= acc[1]
    if smp is not None:
        p_out = float(np.mean((smp < tol[0]) | (smp > tol[1])))
        p_in = 1.0 - p_out
    else:
        cdf = _cdf(dof)
        p_out = float(_p_outside(tol[0], tol[1], y, s, cdf))
        p_in = float(_p_inside(tol[0], tol[1], y, s, cdf))
    if accepted:
        return "accept", p_out, p_out, 0.0
    return "reject", p_out, 0.0, p_in
