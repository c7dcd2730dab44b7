"""Gauge R&R by ANOVA (AIAG MSA 4th ed.): parts x appraisers x trials, crossed, balanced.

[`gauge_rr`][] returns a [`GrrResult`][]: the ANOVA table with the interaction, its test
at `interaction_alpha` (0.25; not significant: pooled into repeatability), the variance
components (repeatability, appraiser, interaction, reproducibility, GRR, part, total)
from the expected mean squares, negative estimates set to 0, each with a confidence
interval by the modified large-sample method (Burdick & Larsen 1997), %GRR of the
tolerance (6 sigma_GRR / T) and of the study variation, ndc, the verdict bands and the
average-and-range method as a cross-check. On a machine an "appraiser" is a setup, a
probe qualification or a shift (`appraiser_is`). [`gauge_rr_batch`][]: the components
and intervals of many studies at once. A missing cell, fewer than 2 parts, appraisers
or trials, or no repeat variation: `InputError`. Formulas, coverage: docs/msa.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ._anova import AnovaTable, anova_sums, anova_table, interaction_p
from ._intervals import Interval, mls_bounds
from ._range import NDC_FACTOR, RangeGrr, range_method
from ._settings import MsaSettings

#: the variance components, in the order of every table
COMPONENTS = (
    "repeatability",
    "appraiser",
    "part x appraiser",
    "reproducibility",
    "gauge R&R",
    "part",
    "total",
)
#: the verdict bands of %GRR
VERDICTS = ("acceptable", "conditional", "not acceptable")


def _coefficients(p: int, o: int, r: int, pooled: bool) -> dict[str, list[float]]:
    """Each component as a combination of the mean squares (expected mean squares of the
    random model): `[P, O, PO, E]`, or `[P, O, E']` with the interaction pooled."""
    pr, orr = p * r, o * r
    if pooled:
        return {
            "repeatability": [0, 0, 1],
            "appraiser": [0, 1 / pr, -1 / pr],
            "reproducibility": [0, 1 / pr, -1 / pr],
            "gauge R&R": [0, 1 / pr, 1 - 1 / pr],
            "part": [1 / orr, 0, -1 / orr],
            "total": [1 / orr, 1 / pr, 1 - 1 / pr - 1 / orr],
        }
    return {
        "repeatability": [0, 0, 0, 1],
        "appraiser": [0, 1 / pr, -1 / pr, 0],
        "part x appraiser": [0, 0, 1 / r, -1 / r],
        "reproducibility": [0, 1 / pr, (p - 1) / pr, -1 / r],
        "gauge R&R": [0, 1 / pr, (p - 1) / pr, (r - 1) / r],
        "part": [1 / orr, 0, -1 / orr, 0],
        "total": [1 / orr, 1 / pr, (p - 1) / pr - 1 / orr, (r - 1) / r],
    }


def _mean_squares(ss, df, pooled: bool) -> tuple[np.ndarray, list[int]]:
    """The mean squares (..., Q) and their df of the model: `[P, O, PO, E]`, or
    `[P, O, E']` with the interaction's sum of squares pooled into E."""
    if pooled:
        dfs = [df[0], df[1], df[2] + df[3]]
        ms_e = (ss[..., 2] + ss[..., 3]) / dfs[2]
        return np.stack([ss[..., 0] / df[0], ss[..., 1] / df[1], ms_e], -1), dfs
    return ss[..., :4] / np.asarray(df[:4], float), list(df[:4])


def _components(ss, df, shape, pooled: bool, level: float) -> dict[str, tuple]:
    """`{name: (estimate, lower, upper)}` arrays of one model; estimates of single
    components clipped at 0, sums made of the clipped ones, bounds clipped at 0."""
    p, o, r = shape
    ms, dfs = _mean_squares(ss, df, pooled)
    out = {}
    for name, coef in _coefficients(p, o, r, pooled).items():
        est, lo, hi = mls_bounds(coef, ms, dfs, level)
        out[name] = [np.maximum(est, 0.0), np.maximum(lo, 0.0), np.maximum(hi, 0.0)]
    zero = np.zeros_like(out["part"][0])
    out.setdefault("part x appraiser", [zero, zero * np.nan, zero * np.nan])
    out["reproducibility"][0] = out["appraiser"][0] + out["part x appraiser"][0]
    out["gauge R&R"][0] = out["repeatability"][0] + out["reproducibility"][0]
    out["total"][0] = out["gauge R&R"][0] + out["part"][0]
    return out


@dataclass(frozen=True, eq=False)
class GrrBatch:
    """The components of many studies: `estimate[name]`, `lower[name]`, `upper[name]`
    (variances, one entry per study), the interaction's p-value and `pooled`."""

    estimate: dict[str, np.ndarray]
    lower: dict[str, np.ndarray]
    upper: dict[str, np.ndarray]
    interaction_p: np.ndarray
    pooled: np.ndarray
    level: float


def gauge_rr_batch(y, settings: MsaSettings = MsaSettings()) -> GrrBatch:
    """The variance components and their MLS intervals of each study in `y`
    (..., parts, appraisers, trials); no checks (see `gauge_rr`)."""
    y = np.asarray(y, float)
    ss, df = anova_sums(y)
    p_int = interaction_p(ss, df)
    pooled = p_int > settings.interaction_alpha
    level = settings.confidence
    full = _components(ss, df, y.shape[-3:], False, level)
    pool = _components(ss, df, y.shape[-3:], True, level)
    pick = {
        k: [np.where(pooled, a, b) for a, b in zip(pool[k], full[k], strict=True)]
        for k in COMPONENTS
    }
    return GrrBatch(
        {k: v[0] for k, v in pick.items()},
        {k: v[1] for k, v in pick.items()},
        {k: v[2] for k, v in pick.items()},
        p_int,
        pooled,
        level,
    )


@dataclass(frozen=True)
class VarianceComponent:
    """One variance component: `variance` with its interval `ci` (None for the
    interaction once pooled), and its shares: of the total variance
    (`pct_contribution`), of the total sd (`pct_study`), and its study variation
    (`multiplier` sds) of the tolerance (`pct_tolerance`, None without one)."""

    name: str
    variance: float
    ci: Interval | None
    pct_contribution: float
    pct_study: float
    pct_tolerance: float | None
    multiplier: float

    @property
    def sd(self) -> float:
        return math.sqrt(self.variance)

    @property
    def sd_ci(self) -> Interval | None:
        return None if self.ci is None else self.ci.sqrt()

    @property
    def study_variation(self) -> float:
        return self.multiplier * self.sd

    def as_dict(self) -> dict:
        sd_ci = self.sd_ci
        return {
            "component": self.name,
            "variance": self.variance,
            "sd": self.sd,
            "variance_ci": None if self.ci is None else self.ci.as_dict(),
            "sd_ci": None if sd_ci is None else sd_ci.as_dict(),
            "study_variation": self.study_variation,
            "pct_contribution": self.pct_contribution,
            "pct_study": self.pct_study,
            "pct_tolerance": self.pct_tolerance,
        }


@dataclass(frozen=True, eq=False)
class GrrResult:
    """A gauge R&R by ANOVA; see the module docstring. `anova` is the table the
    components come from (pooled or with the interaction), `anova_full` the table with
    the interaction; `clipped` names the components whose estimate was negative."""

    data: np.ndarray
    parts: tuple[str, ...]
    appraisers: tuple[str, ...]
    appraiser_is: str
    tolerance: float | None
    anova_full: AnovaTable
    anova: AnovaTable
    interaction_p: float
    components: dict[str, VarianceComponent]
    clipped: tuple[str, ...]
    cross_check: RangeGrr
    settings: MsaSettings = field(repr=False)

    @property
    def pooled(self) -> bool:
        return self.anova.pooled

    @property
    def trials(self) -> int:
        return self.data.shape[2]

    @property
    def ndc(self) -> int:
        """floor(1.41 sigma_part / sigma_GRR) (AIAG)."""
        c = self.components
        return math.floor(NDC_FACTOR * c["part"].sd / c["gauge R&R"].sd)

    @property
    def pct_grr_study(self) -> float:
        return self.components["gauge R&R"].pct_study

    @property
    def pct_grr_tolerance(self) -> float | None:
        return self.components["gauge R&R"].pct_tolerance

    @property
    def pct_grr_tolerance_ci(self) -> Interval | None:
        """6 sigma_GRR / T at the bounds of sigma_GRR's interval (%)."""
        g = self.components["gauge R&R"]
        return (
            None if self.tolerance is None else g.sd_ci.scaled(100 * g.multiplier / self.tolerance)
        )

    @property
    def pct_grr(self) -> float:
        """%GRR on the basis of the verdict (`settings.grr_basis`)."""
        tol = self.settings.grr_basis == "tolerance"
        return self.pct_grr_tolerance if tol else self.pct_grr_study

    @property
    def verdict(self) -> str:
        """`"acceptable"` below `grr_acceptable`, `"conditional"` up to `grr_conditional`,
        `"not acceptable"` above (AIAG bands, on `settings.grr_basis`)."""
        return self._band(self.pct_grr)

    def _band(self, pct: float) -> str:
        share = pct / 100.0
        if share < self.settings.grr_acceptable:
            return VERDICTS[0]
        return VERDICTS[1] if share <= self.settings.grr_conditional else VERDICTS[2]

    @property
    def ndc_ok(self) -> bool:
        return self.ndc >= self.settings.ndc_min

    @property
    def notes(self) -> tuple[str, ...]:
        """What the numbers rest on: the interaction's fate, clipped components, the
        charts' findings, the verdict on the other basis."""
        st, out = self.settings, []
        how = "pooled into repeatability" if self.pooled else "kept"
        out.append(
            f"part x {self.appraiser_is} interaction p = {self.interaction_p:.3g} "
            f"(alpha {st.interaction_alpha:g}): {how}"
        )
        out += [f"{n} variance estimate negative: set to 0" for n in self.clipped]
        if self.tolerance is not None:
            on_tol = st.grr_basis == "tolerance"
            other = "the study variation" if on_tol else "the tolerance"
            pct = self.pct_grr_study if on_tol else self.pct_grr_tolerance
            if self._band(pct) != self.verdict:
                out.append(
                    f"on %GRR of {other} ({pct:.1f} %) the verdict would be {self._band(pct)!r}"
                )
        if not self.ndc_ok:
            out.append(f"ndc {self.ndc} < {st.ndc_min}: the gauge cannot tell the parts apart")
        rc = self.cross_check
        for i, j in rc.ranges_above:
            out.append(
                f"range of part {self.parts[i]!r}, {self.appraiser_is} "
                f"{self.appraisers[j]!r} above the R chart's UCL: re-measure it"
            )
        if rc.outside_share < 0.5:
            out.append(
                f"only {rc.outside_share:.0%} of the part averages lie outside the X̄ "
                "chart's limits (AIAG: at least half): parts too alike for this gauge"
            )
        return tuple(out)

    def table(self) -> list[dict]:
        return [self.components[k].as_dict() for k in COMPONENTS if k in self.components]

    def __repr__(self) -> str:
        p, o, r = self.data.shape
        tol = "" if self.tolerance is None else f"{self.pct_grr_tolerance:.1f} % of T, "
        return (
            f"GrrResult({p} parts x {o} {self.appraiser_is}s x {r} trials, "
            f"interaction {'pooled' if self.pooled else 'kept'} (p={self.interaction_p:.3g}), "
            f"GRR {tol}{self.pct_grr_study:.1f} % of study variation, ndc={self.ndc}: "
            f"{self.verdict})"
        )


def gauge_rr(
    y,
    *,
    tolerance: float | None = None,
    parts=None,
    appraisers=None,
    appraiser_is: str = "appraiser",
    settings: MsaSettings = MsaSettings(),
) -> GrrResult:
    """The ANOVA gauge R&R of `y` (parts, appraisers, trials).

    **Arguments:** `y` the readings, NaN for a missing one (refused, named);
    `tolerance` T = USL - LSL (needed by `grr_basis="tolerance"`); `parts`,
    `appraisers` their names (default 1, 2, ...); `appraiser_is` what an appraiser is.

    **Returns:** a [`GrrResult`][]. **Raises:** `InputError` (module docstring).
    """
    y = np.asarray(y, float)
    names = _names(y, parts, appraisers)
    _check(y, *names, appraiser_is)
    tolerance = _tolerance(tolerance, settings)
    batch = gauge_rr_batch(y, settings)
    ss, df = anova_sums(y)
    pooled = bool(batch.pooled)
    ms = _mean_squares(ss, df, pooled)[0]
    single = ("appraiser", "part x appraiser", "part")
    raw = {k: float(np.dot(c, ms)) for k, c in _coefficients(*y.shape, pooled).items()}
    return GrrResult(
        data=y, parts=names[0], appraisers=names[1], appraiser_is=appraiser_is,
        tolerance=tolerance, anova_full=anova_table(ss, df, pooled=False),
        anova=anova_table(ss, df, pooled=pooled), interaction_p=float(batch.interaction_p),
        components=_table(batch, tolerance, settings),
        clipped=tuple(k for k in single if raw.get(k, 0.0) < 0),
        cross_check=range_method(y, tolerance=tolerance, multiplier=settings.study_multiplier),
        settings=settings,
    )  # fmt: skip


def _table(batch: GrrBatch, tolerance, st: MsaSettings) -> dict[str, VarianceComponent]:
    total = float(batch.estimate["total"])
    out = {}
    for k in COMPONENTS:
        if k == "part x appraiser" and bool(batch.pooled):
            continue
        v = float(batch.estimate[k])
        ci = Interval(float(batch.lower[k]), float(batch.upper[k]), batch.level)
        tol = None if tolerance is None else 100.0 * st.study_multiplier * math.sqrt(v) / tolerance
        out[k] = VarianceComponent(
            k, v, ci, 100.0 * v / total, 100.0 * math.sqrt(v / total), tol, st.study_multiplier
        )
    return out


def _names(y, parts, appraisers) -> tuple[tuple[str, ...], tuple[str, ...]]:
    if y.ndim != 3:
        raise InputError(
            f"a gauge R&R needs readings (parts, appraisers, trials), got shape {y.shape}"
        )
    out = []
    for given, m, what in ((parts, y.shape[0], "parts"), (appraisers, y.shape[1], "appraisers")):
        names = tuple(str(i + 1) for i in range(m)) if given is None else tuple(map(str, given))
        if len(names) != m:
            raise InputError(f"{len(names)} {what} names for {m} {what}")
        out.append(names)
    return out[0], out[1]


def _check(y, parts, appraisers, appraiser_is: str) -> None:
    p, o, r = y.shape
    for m, what in ((p, "parts"), (o, f"{appraiser_is}s"), (r, "trials")):
        if m < 2:
            raise InputError(f"a gauge R&R needs at least 2 {what}, got {m}", value=m)
    bad = np.argwhere(~np.isfinite(y))
    if len(bad):
        i, j, k = bad[0]
        raise InputError(
            f"part {parts[i]!r}, {appraiser_is} {appraisers[j]!r}, trial {k + 1}: "
            "reading missing or not finite (the design must be balanced)"
        )
    if np.all(np.ptp(y, axis=2) == 0.0):
        raise InputError(
            f"every part reads the same in all {r} trials of each {appraiser_is}: repeatability "
            "is not measured (no variation; a finer resolution is needed), no %GRR or ndc "
            "can be computed"
        )


def _tolerance(tolerance, st: MsaSettings):
    if tolerance is None:
        if st.grr_basis == "tolerance":
            raise InputError("grr_basis 'tolerance' needs the tolerance T (or grr_basis = 'study')")
        return None
    t = float(tolerance)
    if not 0 < t < math.inf:
        raise InputError(
            f"tolerance must be a finite number > 0, got {tolerance!r}", value=tolerance
        )
    return t
