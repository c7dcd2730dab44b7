"""The type-1 study of a gauge (VDA 5, Bosch booklet 10, Minitab "Type 1 Gage Study").

[`type1_study`][] takes n >= 25 readings of one reference part (a ring, a master
diameter or face whose certified value and expanded uncertainty are a
[`Reference`][]), the tolerance T and the resolution, and returns a
[`Type1Result`][]: the bias with its t-test and interval, the repeatability s with
its chi-square interval, Cg = K T / (L s) and Cgk = (K T / 2 - |bias|) / (L s / 2) with
their intervals (exact chi-square; Bissell), the resolution check and the verdict.
[`type1_batch`][] computes the same statistics for many studies at once (arrays), for
simulations. Too few readings, a bad reference, zero variation: `InputError`.
The formulas and the measured coverage of the intervals: docs/msa.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from numbers import Real

import numpy as np
from scipy import stats

from ..errors import InputError
from ._intervals import Interval, bissell_bounds, sd_bounds, t_bounds
from ._settings import MsaSettings


@dataclass(frozen=True)
class Reference:
    """A reference part's certified value and its expanded uncertainty `U` at coverage
    factor `k` (from the calibration certificate); `u = U / k`."""

    value: float
    expanded_uncertainty: float
    coverage_factor: float

    def __post_init__(self):
        for name in ("value", "expanded_uncertainty", "coverage_factor"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v):
                raise InputError(f"reference {name}: expected a finite number, got {v!r}", value=v)
        for name in ("expanded_uncertainty", "coverage_factor"):
            if getattr(self, name) <= 0:
                raise InputError(
                    f"reference {name} must be > 0 (from the calibration certificate), got "
                    f"{getattr(self, name)!r}",
                    value=getattr(self, name),
                )

    @property
    def u(self) -> float:
        """The standard uncertainty of the certified value, U / k."""
        return self.expanded_uncertainty / self.coverage_factor


@dataclass(frozen=True, eq=False)
class Type1Batch:
    """The type-1 statistics of many studies of `n` readings: one array entry per study
    (`*_lo`, `*_hi`: the bounds at `level`)."""

    n: int
    level: float
    mean: np.ndarray
    bias: np.ndarray
    bias_t: np.ndarray
    bias_p: np.ndarray
    bias_lo: np.ndarray
    bias_hi: np.ndarray
    s: np.ndarray
    s_lo: np.ndarray
    s_hi: np.ndarray
    cg: np.ndarray
    cg_lo: np.ndarray
    cg_hi: np.ndarray
    cgk: np.ndarray
    cgk_lo: np.ndarray
    cgk_hi: np.ndarray


def type1_batch(
    readings, reference: float, tolerance: float, settings: MsaSettings = MsaSettings()
) -> Type1Batch:
    """The type-1 statistics of each row of `readings` (m, n) against the reference
    value `reference`, tolerance `tolerance`; no checks (see `type1_study`)."""
    x = np.asarray(readings, float)
    n, level = x.shape[-1], settings.confidence
    mean = x.mean(-1)
    s = x.std(-1, ddof=1)
    bias = mean - reference
    se = s / math.sqrt(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = bias / se
    spread, reach = settings.l_spread, settings.k_share * tolerance
    cg = reach / (spread * s)
    cgk = (reach / 2.0 - np.abs(bias)) / (spread / 2.0 * s)
    s_lo, s_hi = sd_bounds(s, n - 1, level)
    bias_lo, bias_hi = t_bounds(bias, se, n - 1, level)
    cgk_lo, cgk_hi = bissell_bounds(cgk, n, level)
    return Type1Batch(
        n=n, level=level, mean=mean, bias=bias, bias_t=t,
        bias_p=2.0 * stats.t.sf(np.abs(t), n - 1), bias_lo=bias_lo, bias_hi=bias_hi,
        s=s, s_lo=s_lo, s_hi=s_hi,
        cg=cg, cg_lo=reach / (spread * s_hi), cg_hi=reach / (spread * s_lo),
        cgk=cgk, cgk_lo=cgk_lo, cgk_hi=cgk_hi,
    )  # fmt: skip


@dataclass(frozen=True, eq=False)
class Type1Result:
    """A type-1 study; see the module docstring. Lengths in the readings' unit (mm).

    `bias = mean - reference.value`; `bias_p` the two-sided p-value of the t-test of
    bias = 0 (the reference value taken as exact: its `u` enters the budget, u_CAL);
    `resolution_share` = resolution / T; `capable`: Cg and Cgk at or above their
    limits and the resolution within its share; `reasons` say what failed.
    """

    readings: np.ndarray
    reference: Reference
    tolerance: float
    resolution: float
    mean: float
    bias: float
    bias_t: float
    bias_p: float
    bias_ci: Interval
    s: float
    s_ci: Interval
    cg: float
    cg_ci: Interval
    cgk: float
    cgk_ci: Interval
    settings: MsaSettings = field(repr=False)

    @property
    def n(self) -> int:
        return len(self.readings)

    @property
    def resolution_share(self) -> float:
        return self.resolution / self.tolerance

    @property
    def resolution_ok(self) -> bool:
        return self.resolution_share <= self.settings.resolution_share + 1e-12

    @property
    def bias_significant(self) -> bool:
        """Whether the t-test rejects bias = 0 at 1 - confidence."""
        return self.bias_p < 1.0 - self.settings.confidence

    @property
    def cg_ok(self) -> bool:
        return self.cg >= self.settings.cg_limit

    @property
    def cgk_ok(self) -> bool:
        return self.cgk >= self.settings.cgk_limit

    @property
    def capable(self) -> bool:
        return self.cg_ok and self.cgk_ok and self.resolution_ok

    @property
    def reasons(self) -> tuple[str, ...]:
        """What keeps the gauge from being capable (empty when it is)."""
        st, out = self.settings, []
        if not self.cg_ok:
            out.append(f"Cg {self.cg:.2f} < {st.cg_limit:g}: repeatability s too large")
        if not self.cgk_ok:
            out.append(f"Cgk {self.cgk:.2f} < {st.cgk_limit:g}: bias and repeatability too large")
        if not self.resolution_ok:
            out.append(f"resolution {self.resolution_share:.1%} of T > {st.resolution_share:.0%}")
        return tuple(out)

    @property
    def verdict(self) -> str:
        return "capable" if self.capable else "not capable"

    @property
    def limits(self) -> dict[str, float]:
        """The run chart's lines: reference -/+ K T / 2 and mean -/+ L s / 2."""
        st = self.settings
        half, spread = st.k_share * self.tolerance / 2.0, st.l_spread * self.s / 2.0
        ref = self.reference.value
        return {
            "reference": ref,
            "lower": ref - half,
            "upper": ref + half,
            "mean": self.mean,
            "mean_lower": self.mean - spread,
            "mean_upper": self.mean + spread,
        }

    def table(self) -> list[dict]:
        """One row per statistic: `quantity, value, lower, upper, limit, ok`."""
        st = self.settings
        rows = [
            ("bias", self.bias, self.bias_ci, None, None),
            ("s", self.s, self.s_ci, None, None),
            ("cg", self.cg, self.cg_ci, st.cg_limit, self.cg_ok),
            ("cgk", self.cgk, self.cgk_ci, st.cgk_limit, self.cgk_ok),
        ]
        out = [
            {
                "quantity": q,
                "value": v,
                "lower": ci.lower,
                "upper": ci.upper,
                "limit": lim,
                "ok": ok,
            }
            for q, v, ci, lim, ok in rows
        ]
        out.append(
            {
                "quantity": "resolution_share",
                "value": self.resolution_share,
                "lower": None,
                "upper": None,
                "limit": st.resolution_share,
                "ok": self.resolution_ok,
            }
        )
        return out

    def __repr__(self) -> str:
        return (
            f"Type1Result(n={self.n}, bias={self.bias:.4g} {self.bias_ci!r}, "
            f"p={self.bias_p:.3g}, s={self.s:.4g} {self.s_ci!r}, Cg={self.cg:.3f} {self.cg_ci!r}, "
            f"Cgk={self.cgk:.3f} {self.cgk_ci!r}, resolution {self.resolution_share:.1%} "
            f"of T: {self.verdict})"
        )


def type1_study(
    readings,
    *,
    reference: Reference,
    tolerance: float,
    resolution: float,
    settings: MsaSettings = MsaSettings(),
) -> Type1Result:
    """The type-1 study of `readings` (n >= `settings.min_readings`) of `reference`.

    **Arguments:** `readings` (n,) in the unit of `tolerance` (T = USL - LSL, > 0) and
    `resolution` (> 0, the gauge's digit step); `reference` its certified value and U.

    **Returns:** a [`Type1Result`][].

    **Raises:** `InputError` for too few or non-finite readings, a bad T or
    resolution, or readings that do not vary (s = 0: no index from nothing).
    """
    x = _checked_readings(readings, settings.min_readings)
    for name, v in (("tolerance", tolerance), ("resolution", resolution)):
        if isinstance(v, bool) or not isinstance(v, Real) or not 0 < v < math.inf:
            raise InputError(f"{name} must be a finite number > 0, got {v!r}", value=v)
    b = type1_batch(x[None, :], reference.value, tolerance, settings)
    one = {k: float(v[0]) for k, v in vars(b).items() if isinstance(v, np.ndarray)}

    def ci(name):
        return Interval(one[f"{name}_lo"], one[f"{name}_hi"], settings.confidence)

    return Type1Result(
        readings=x, reference=reference, tolerance=float(tolerance),
        resolution=float(resolution), mean=one["mean"], bias=one["bias"],
        bias_t=one["bias_t"], bias_p=one["bias_p"], bias_ci=ci("bias"), s=one["s"],
        s_ci=ci("s"), cg=one["cg"], cg_ci=ci("cg"), cgk=one["cgk"], cgk_ci=ci("cgk"),
        settings=settings,
    )  # fmt: skip


def _checked_readings(readings, least: int) -> np.ndarray:
    x = np.asarray(readings, dtype=float).ravel()
    if len(x) < least:
        raise InputError(
            f"a type-1 study needs at least {least} readings of the reference, got {len(x)}",
            value=len(x),
        )
    bad = np.flatnonzero(~np.isfinite(x))
    if len(bad):
        raise InputError(f"reading {bad[0] + 1} is not a finite number: {float(x[bad[0]])!r}")
    if np.ptp(x) == 0.0:
        raise InputError(
            f"all {len(x)} readings are equal ({float(x[0])!r}): the repeatability is not measured "
            "(no variation; a finer resolution is needed), no Cg or Cgk can be computed",
            value=float(x[0]),
        )
    return x
