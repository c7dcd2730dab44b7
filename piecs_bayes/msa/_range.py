"""The average-and-range method of a gauge R&R (AIAG MSA 4th ed.), a cross-check of
the ANOVA: EV = R̿ K1, AV = sqrt((X̄_diff K2)^2 - EV^2 / (n r)), PV = R_p K3.

K1 = 1/d2(trials), K2 = 1/d2*(appraisers, 1), K3 = 1/d2*(parts, 1): AIAG's printed
4-decimal table where it has them (2-3 trials, 2-3 appraisers, 2-10 parts), computed
from the range distribution otherwise ([`range_constants`][]). The R chart's upper limit
D4 R̿ flags part x appraiser ranges to re-measure; AIAG wants at least half of the
part averages outside the X̄ chart's limits (the gauge discriminates the parts).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import integrate, special

#: AIAG MSA 4th ed., ch. III, the average-and-range method's constants
AIAG_K1 = {2: 0.8862, 3: 0.5908}
AIAG_K2 = {2: 0.7071, 3: 0.5231}
AIAG_K3 = {
    2: 0.7071,
    3: 0.5231,
    4: 0.4467,
    5: 0.4030,
    6: 0.3742,
    7: 0.3534,
    8: 0.3375,
    9: 0.3249,
    10: 0.3146,
}
#: AIAG's multiplier of ndc (its rounding of sqrt 2)
NDC_FACTOR = 1.41


@lru_cache(maxsize=64)
def range_moments(n: int) -> tuple[float, float]:
    """`(E[W], E[W^2])` of the range W of n standard normal values (Simpson, ~1e-10):
    E[W] = int 1 - Phi^n - (1-Phi)^n dx; E[W^2] = int_0^inf 2 w (1 - F_W(w)) dw with
    F_W(w) = n int phi(x) (Phi(x+w) - Phi(x))^(n-1) dx."""
    x = np.linspace(-8.5, 8.5, 681)
    cdf = special.ndtr(x)
    ew = integrate.simpson(1.0 - cdf**n - (1.0 - cdf) ** n, x=x)
    w = np.linspace(0.0, 12.0, 481)
    pdf = np.exp(-0.5 * x**2) / math.sqrt(2.0 * math.pi)
    inner = (special.ndtr(x[None, :] + w[:, None]) - cdf[None, :]) ** (n - 1)
    fw = n * integrate.simpson(pdf[None, :] * inner, x=x, axis=1)
    return float(ew), float(integrate.simpson(2.0 * w * (1.0 - fw), x=w))


def range_constants(parts: int, appraisers: int, trials: int) -> tuple[float, float, float, str]:
    """`(K1, K2, K3, source)`: AIAG's table (`source` "AIAG table") when it covers the
    design, else 1/d2 and 1/d2* computed (`"computed"`)."""
    if trials in AIAG_K1 and appraisers in AIAG_K2 and parts in AIAG_K3:
        return AIAG_K1[trials], AIAG_K2[appraisers], AIAG_K3[parts], "AIAG table"
    k1 = 1.0 / range_moments(trials)[0]
    k2, k3 = (1.0 / math.sqrt(range_moments(m)[1]) for m in (appraisers, parts))
    return k1, k2, k3, "computed"


@dataclass(frozen=True)
class RangeGrr:
    """The average-and-range gauge R&R: standard deviations `ev, av, grr, pv, tv`, their
    percentages of TV (`pct_*`), of the tolerance (`pct_grr_tolerance`, None without
    one), ndc, the constants and the chart findings (`ranges_above`: (part, appraiser)
    indices whose range is above the R chart's UCL; `outside_share`: the share of
    part x appraiser averages outside the X̄ chart's limits)."""

    k1: float
    k2: float
    k3: float
    constants: str
    rbar: float
    xdiff: float
    rp: float
    ev: float
    av: float
    grr: float
    pv: float
    tv: float
    pct_grr_tolerance: float | None
    r_ucl: float
    xbar_limits: tuple[float, float]
    ranges_above: tuple[tuple[int, int], ...]
    outside_share: float

    @property
    def ndc(self) -> int:
        return math.floor(NDC_FACTOR * self.pv / self.grr)

    def pct(self, name: str) -> float:
        """% of TV of `"ev"`, `"av"`, `"grr"` or `"pv"`."""
        return 100.0 * getattr(self, name) / self.tv

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in self.__dataclass_fields__}
        d["xbar_limits"] = list(self.xbar_limits)
        d["ranges_above"] = [list(c) for c in self.ranges_above]
        d["pct_of_tv"] = {k: self.pct(k) for k in ("ev", "av", "grr", "pv")}
        d["ndc"] = self.ndc
        return d


def range_method(y, *, tolerance: float | None = None, multiplier: float = 6.0) -> RangeGrr:
    """The average-and-range gauge R&R of `y` (parts, appraisers, trials), balanced."""
    y = np.asarray(y, float)
    p, o, r = y.shape
    k1, k2, k3, source = range_constants(p, o, r)
    ranges = np.ptp(y, axis=2)
    rbar = float(ranges.mean())
    appr, part = y.mean((0, 2)), y.mean((1, 2))
    xdiff, rp = float(np.ptp(appr)), float(np.ptp(part))
    ev = rbar * k1
    av = math.sqrt(max((xdiff * k2) ** 2 - ev**2 / (p * r), 0.0))
    grr, pv = math.hypot(ev, av), rp * k3
    ew, ew2 = range_moments(r)
    r_ucl = rbar * (1.0 + 3.0 * math.sqrt(ew2 - ew**2) / ew)
    centre, a2 = float(y.mean()), 3.0 / (ew * math.sqrt(r))
    lims = (centre - a2 * rbar, centre + a2 * rbar)
    cells = y.mean(2)
    above = tuple((int(i), int(j)) for i, j in zip(*np.nonzero(ranges > r_ucl), strict=True))
    outside = float(np.mean((cells < lims[0]) | (cells > lims[1])))
    pct_tol = None if tolerance is None else 100.0 * multiplier * grr / tolerance
    return RangeGrr(
        k1,
        k2,
        k3,
        source,
        rbar,
        xdiff,
        rp,
        ev,
        av,
        grr,
        pv,
        math.hypot(grr, pv),
        pct_tol,
        r_ucl,
        lims,
        above,
        outside,
    )
