r"""Is compensation justified? A per-feature decision from the posterior of the deviation.

[`decide`][] takes the tolerance and the posterior of one feature's deviation $\delta$
(fitted minus nominal, mm: `mean` and `sd` with their degrees of freedom `dof`, or
`samples`) and returns a [`Decision`][]: the verdict (`compensate` with the Bayes gain,
`do not compensate`, or `measure more` with the number of extra probe points that would
decide), the gain and correction (what the finish cut adds: $c = -g\,\hat\delta$), every
candidate action's expected loss, the significance, the conformance before and after
(ISO 14253-1, with guard bands) and the reasons. With finite `dof` the deviation is
$y + u\,t_\nu$. `coordinate` and `scale` only state the result as drawn (reasons,
`drawn_*`), never change the verdict. Losses and actions are in `_actions`, conformance
in `_conformance`, the verdict and its reasons in `_verdict`, the settings in
`_settings`.

The decision rule: docs/models/decision.md.
"""

from __future__ import annotations

import functools
import math
import numbers
from dataclasses import dataclass

import numpy as np

from .. import _config
from ..errors import InputError
from ._actions import ActionLoss, evaluate_actions
from ._conformance import Conformance
from ._risk import ConformityRisk, GuardBand, conformity_risk
from ._settings import DecisionSettings
from ._verdict import Verdict, VerdictWords, clear_verdict, conclude

special = _config.LazyModule("scipy.special")


@dataclass(frozen=True)
class Decision:
    """The verdict for one feature with every number behind it (see module docstring).

    `gain` and `correction` (mm, $c = -g\\hat\\delta$) are zero unless the verdict is
    `"compensate"`; `u_correction` $= g\\,u$ propagates the estimate's standard
    uncertainty. `estimate`, `u_estimate` are what was handed in; `posterior_*` include
    the prior when one is set. `actions` lists every candidate with its expected loss
    (the last is `bayes`); `best_action` is the one with the lowest loss (the
    first listed among those equal to rounding, 1e-9 relative);
    `more_points` is the extra probe points a "measure more" verdict asks for.
    `reasons` end with the conclusion, which starts with the verdict. `coordinate` and
    `scale` give the drawn deviation (`scale` × normal deviation, e.g. on the diameter):
    `drawn_estimate`, `drawn_expanded`, `drawn_tolerance`, `drawn_null_band`,
    `drawn_correction`.
    """

    feature: str | None
    verdict: Verdict
    gain: float
    correction: float
    u_correction: float
    estimate: float
    u_estimate: float
    posterior_mean: float
    posterior_sd: float
    null_band: float
    p_exceed: float
    significant: bool
    best_action: str
    actions: tuple[ActionLoss, ...]
    conformance_before: Conformance
    conformance_after: Conformance
    tolerance: tuple[float, float]
    blocked: bool
    n_points: int | None
    more_points: int | None
    reasons: tuple[str, ...]
    dof: float = math.inf
    coordinate: str = "normal"
    scale: float = 1.0

    def risk(self, when: str = "before") -> ConformityRisk:
        """The conformity decision on the feature as measured (`"before"`) or as
        predicted after the correction (`"after"`), with its specific risks (JCGM 106,
        `decide.conformity_risk`): accepted inside this decision's acceptance zone
        (ISO 14253-1, the tolerance less the guard band), the consumer's risk is
        P(out of tolerance | data); rejected, the producer's risk is P(in tolerance | data)."""
        c = self.conformance_before if when == "before" else self.conformance_after
        lo, hi = c.tolerance
        width = max(c.acceptance[0] - lo, hi - c.acceptance[1])
        band = GuardBand("fixed", width=width, max_width=max(width, 0.5 * (hi - lo)))
        return conformity_risk(c.tolerance, value=c.value, u=c.u, dof=self.dof, guard_band=band)

    @property
    def drawn_estimate(self) -> float:
        return self.scale * self.estimate

    @property
    def drawn_expanded(self) -> float:
        """Expanded uncertainty U of the deviation as measured, as drawn."""
        return abs(self.scale) * self.conformance_before.expanded

    @property
    def drawn_tolerance(self) -> tuple[float, float]:
        lo, hi = sorted((self.scale * self.tolerance[0], self.scale * self.tolerance[1]))
        return lo, hi

    @property
    def drawn_null_band(self) -> float:
        return abs(self.scale) * self.null_band

    @property
    def drawn_correction(self) -> float:
        return self.scale * self.correction

    def as_row(self) -> dict:
        """A flat dict for a verdict table (JSON/CSV): the drawn values first."""
        row = {
            "feature": self.feature,
            "verdict": self.verdict,
            "gain": self.gain,
            "coordinate": self.coordinate,
            "deviation_drawn_mm": self.drawn_estimate,
            "U_drawn_mm": self.drawn_expanded,
            "tolerance_drawn_lower_mm": self.drawn_tolerance[0],
            "tolerance_drawn_upper_mm": self.drawn_tolerance[1],
            "null_band_drawn_mm": self.drawn_null_band,
            "correction_drawn_mm": self.drawn_correction,
            "correction_mm": self.correction,
            "u_correction_mm": self.u_correction,
            "estimate_mm": self.estimate,
            "u_estimate_mm": self.u_estimate,
            "dof": self.dof if math.isfinite(self.dof) else None,
            "null_band_mm": self.null_band,
            "p_exceed_null_band": self.p_exceed,
            "p_conform_before": self.conformance_before.p_conform,
            "conformance_before": self.conformance_before.state,
            "p_conform_after": self.conformance_after.p_conform,
            "conformance_after": self.conformance_after.state,
            **_risk_columns(self.risk("before"), "before"),
            **_risk_columns(self.risk("after"), "after"),
            "best_action": self.best_action,
            "blocked": self.blocked,
            "n_points": self.n_points,
            "more_points": self.more_points,
        }
        for a in self.actions:
            row[f"loss_{a.name}"] = a.expected_loss
        row["reasons"] = "; ".join(self.reasons)
        return row

    def __repr__(self) -> str:
        head = f"Decision({self.feature!r}: {self.verdict.upper()}"
        if self.verdict == "compensate":
            head += (
                f", gain {self.gain:.3f}, correction {self.drawn_correction * 1e3:+.2f}"
                f" ± {abs(self.scale) * self.u_correction * 1e3:.2f} µm {self.coordinate}"
            )
        if self.verdict == "measure more" and self.more_points is not None:
            head += f", {self.more_points} more probe points"
        lines = [head + ")"]
        lines += [f"  - {r}" for r in self.reasons]
        lines += [f"  * {a!r}" for a in self.actions]
        return "\n".join(lines)


@dataclass(frozen=True)
class DrawnFeature:
    """The feature a decision is for, as its drawing states it.

    - `id`: carried into the result and error messages.
    - `coordinate`, `scale`: the coordinate the tolerance is drawn on and the drawn
      deviation per unit of normal deviation (`geometry.drawn_scale`: 2 on a
      diameter); they change only how the result is stated (reasons, `drawn_*`),
      never the verdict.
    """

    id: str | None = None
    coordinate: str = "normal"
    scale: float = 1.0

    def __post_init__(self):
        s = self.scale
        if isinstance(s, bool) or not isinstance(s, numbers.Real) or not math.isfinite(s):
            raise InputError(f"scale must be a finite number, got {s!r}", feature=self.id, value=s)
        object.__setattr__(self, "scale", float(s))


# --------------------------------------------------------------------------- more points


def _grown_dof(dof: float, sd: float, u_sys: float, n: int, n_new: int) -> float:
    """The effective dof of an estimate of `sd` from `n` points (`dof`, of which `u_sys`
    is systematic, Type B) when it rests on `n_new` points: the random part's dof
    $\\nu_A = \\nu\\,(u_A/u)^4$ (Welch-Satterthwaite read backwards) grows by the
    added points, each a residual dof of the pooled sigma ($n - p$ grows as $n$), and
    $\\nu' = \\nu_A'\\,(u'/u_A')^4$ with $u_A'^2 = u_A^2\\,n/n'$."""
    rand2 = max(sd**2 - u_sys**2, 0.0)
    if not math.isfinite(dof) or rand2 <= 0.0:
        return dof
    nu_a = dof * (rand2 / sd**2) ** 2 + (n_new - n)
    rand2_new = rand2 * n / n_new
    return nu_a * ((rand2_new + u_sys**2) / rand2_new) ** 2


def _scaled(m0, s0, samples, u_sys, n, n_new, dof):
    """`(sd, samples, dof)` of the estimate from `n_new` points: the random part of the
    sd shrinks as 1/sqrt(n) and its dof grows (`_grown_dof`); the t draws of a finite dof
    are drawn again at the new dof."""
    rand2 = max(s0**2 - u_sys**2, 0.0)
    s_new = math.sqrt(rand2 * n / n_new + u_sys**2)
    dof_new = _grown_dof(dof, s0, u_sys, n, n_new)
    if math.isfinite(dof):  # the samples are t quantiles (`_checked_inputs`)
        return s_new, m0 + s_new * _T_QUANTILES(dof_new), dof_new
    if samples is None:
        return s_new, None, dof_new
    return s_new, m0 + (samples - m0) * (s_new / s0 if s0 > 0 else 1.0), dof_new


def _more_points(m0, s0, samples, u_sys, n, tol, st, k, band, max_corr, t, dof) -> int | None:
    n_max = max(int(math.ceil(st.max_points_factor * n)), n + 1)
    cands = sorted({min(n_max, int(math.ceil(n * 1.08**j))) for j in range(1, 200)} - {n})
    prev = n
    for n_new in cands:
        s_new, smp, d_new = _scaled(m0, s0, samples, u_sys, n, n_new, dof)
        if clear_verdict(evaluate_actions(m0, s_new, smp, tol, st, k, band, max_corr, t, d_new)):
            for n_try in range(prev + 1, n_new):  # the smallest decisive count
                s_try, smp, d_try = _scaled(m0, s0, samples, u_sys, n, n_try, dof)
                core = evaluate_actions(m0, s_try, smp, tol, st, k, band, max_corr, t, d_try)
                if clear_verdict(core) is not None:
                    return n_try - n
            return n_new - n
        prev = n_new
        if n_new >= n_max:
            break
    return None


def decide(
    *,
    tolerance: tuple[float, float],
    mean: float | None = None,
    sd: float | None = None,
    samples=None,
    settings: DecisionSettings | None = None,
    n_points: int | None = None,
    u_systematic: float = 0.0,
    run_index: int = 1,
    dof: float = math.inf,
    feature: DrawnFeature | None = None,
) -> Decision:
    """Decide whether to compensate one feature.

    **Arguments:**

    - `tolerance`: `(lower, upper)` limits of the deviation (mm), e.g. `(-0.01, 0.01)`.
    - `mean`, `sd`: posterior mean and standard deviation of the deviation (mm), or
    - `samples`: posterior draws of the deviation (1-D).
    - `settings`: thresholds and costs, see [`DecisionSettings`][].
    - `n_points`: probe points behind the estimate (needed for "how many more").
    - `u_systematic`: part of `sd` that more points do not reduce (mm).
    - `run_index`: $t$ of Grubbs' harmonic rule (1 for a first setup adjustment).
    - `dof`: (effective) degrees of freedom of `sd` (`inf`: normal). Finite: the
      deviation is `mean + sd * t_dof` (see the module doc); not with `samples`.
    - `feature`: its id and how its tolerance is drawn (a [`DrawnFeature`][]; default:
      no id, the normal deviation as drawn).

    **Returns:** a [`Decision`][] with the verdict, the gain and correction, every
    action's expected loss, significance, conformance before and after, and reasons.
    """
    st = settings if settings is not None else DecisionSettings()
    drawn = feature if feature is not None else DrawnFeature()
    feature, coordinate, scale = drawn.id, drawn.coordinate, drawn.scale
    lo, hi = _tolerance(tolerance, feature)
    m0, s0, smp, dof = _checked_inputs(
        mean, sd, samples, u_systematic, dof, run_index, n_points, feature
    )
    band, k, max_corr = feature_scales(st, hi - lo)
    core = evaluate_actions(m0, s0, smp, (lo, hi), st, k, band, max_corr, run_index, dof)
    more = None
    if clear_verdict(core) is None and n_points is not None:
        more = _more_points(
            m0, s0, smp, u_systematic, n_points, (lo, hi), st, k, band, max_corr, run_index,
            dof,
        )  # fmt: skip
    words = VerdictWords(coordinate, float(scale))
    out = conclude(
        core, band=band, max_corr=max_corr, st=st, n_points=n_points, more=more, w=words, dof=dof
    )
    return Decision(
        feature=feature,
        verdict=out.verdict,
        gain=float(out.gain),
        correction=float(out.correction),
        u_correction=float(abs(out.gain) * s0),
        estimate=m0,
        u_estimate=s0,
        posterior_mean=core.post.m,
        posterior_sd=core.post.s,
        null_band=float(band),
        p_exceed=core.p_exceed,
        significant=core.significant,
        best_action=_best_action(core.actions),
        actions=core.actions,
        conformance_before=core.before,
        conformance_after=core.after,
        tolerance=(lo, hi),
        blocked=out.blocked,
        n_points=n_points,
        more_points=more,
        reasons=out.reasons,
        dof=dof,
        coordinate=coordinate,
        scale=float(scale),
    )


def _checked_inputs(mean, sd, samples, u_systematic, dof, run_index, n_points, feature):
    """`(m0, s0, samples or None, dof)`: the estimate handed in and the options, checked.

    With finite `dof` the samples are deterministic draws of `m0 + s0 * t_dof`.
    """
    m0, s0, smp = _estimate(mean, sd, samples, feature)
    dof = _checked_options(u_systematic, s0, dof, run_index, n_points, smp is not None, feature)
    if math.isfinite(dof):
        smp = m0 + s0 * _T_QUANTILES(dof)
    return m0, s0, smp, dof


def _estimate(mean, sd, samples, feature) -> tuple[float, float, np.ndarray | None]:
    """The estimate handed in: `(mean, sd, samples or None)`, checked."""
    if samples is not None:
        if mean is not None or sd is not None:
            raise InputError("give either mean and sd or samples, not both", feature=feature)
        smp = np.asarray(samples, dtype=float).ravel()
        if smp.size < 2 or not np.all(np.isfinite(smp)):
            raise InputError(
                "samples must be at least 2 finite numbers", feature=feature, value=smp.size
            )
        return float(smp.mean()), float(smp.std(ddof=1)), smp
    if mean is None or sd is None:
        raise InputError("give the deviation's posterior mean and sd (or samples)", feature=feature)
    m0, s0 = float(mean), float(sd)
    if not math.isfinite(m0):
        raise InputError(f"mean must be finite, got {mean!r}", feature=feature, value=mean)
    if not (math.isfinite(s0) and s0 > 0):
        raise InputError(f"sd must be a finite number > 0, got {sd!r}", feature=feature, value=sd)
    return m0, s0, None


def _checked_options(u_systematic, s0, dof, run_index, n_points, has_samples, feature) -> float:
    """Check the remaining arguments of `decide`; return `dof` as a float."""
    if not (math.isfinite(u_systematic) and 0 <= u_systematic <= s0):
        raise InputError(
            f"u_systematic must be in [0, sd={s0:.3g}], got {u_systematic!r}",
            feature=feature,
            value=u_systematic,
        )
    if isinstance(dof, bool) or not isinstance(dof, numbers.Real) or not dof > 0:
        raise InputError(f"dof must be a number > 0 (or inf), got {dof!r}", feature=feature)
    dof = float(dof)
    if math.isfinite(dof) and has_samples:
        raise InputError("dof applies to mean and sd, not to samples", feature=feature)
    if isinstance(run_index, bool) or not isinstance(run_index, int) or run_index < 1:
        raise InputError(f"run_index must be an integer >= 1, got {run_index!r}", value=run_index)
    if n_points is not None and (
        isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 1
    ):
        raise InputError(f"n_points must be an integer >= 1, got {n_points!r}", value=n_points)
    return dof


def feature_scales(st: DecisionSettings, width: float) -> tuple[float, float, float]:
    """Null band, Taguchi loss constant $k$ and largest allowed correction (defaults filled)."""
    band = 0.1 * width if st.null_band is None else st.null_band
    k = st.loss_k if st.loss_k is not None else st.out_of_tolerance_cost / (width / 2) ** 2
    if k == 0.0:
        k = 1.0 / (width / 2) ** 2  # no costs given at all: fall back to unit Taguchi loss
    max_corr = width if st.max_correction is None else st.max_correction
    return band, k, max_corr


_N_T = 2000


@functools.lru_cache(maxsize=256)
def _T_QUANTILES(dof: float) -> np.ndarray:  # noqa: N802 - a cached constant table
    """Stratified standard t quantiles: deterministic draws of $t_\\nu$."""
    q = special.stdtrit(dof, (np.arange(_N_T) + 0.5) / _N_T)
    q.flags.writeable = False
    return q


def _tolerance(tolerance, feature) -> tuple[float, float]:
    try:
        lo, hi = (float(t) for t in tolerance)
    except (TypeError, ValueError):
        raise InputError(
            f"tolerance must be (lower, upper) numbers, got {tolerance!r}",
            feature=feature,
            value=tolerance,
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise InputError(
            f"tolerance must be finite with lower < upper, got ({lo}, {hi})",
            feature=feature,
            value=tolerance,
        )
    return lo, hi


def _best_action(actions) -> str:
    """The action with the lowest expected loss; among losses equal to rounding (1e-9
    relative: e.g. `bayes` at gain 1 is `full`) the first listed, so that the last
    bits of a fit never flip the choice."""
    low = min(a.expected_loss for a in actions)
    return next(a.name for a in actions if a.expected_loss <= low + 1e-9 * abs(low))


def _risk_columns(risk: ConformityRisk, when: str) -> dict:
    """The flat columns of one conformity decision's specific risks."""
    return {
        f"decision_{when}": risk.decision,
        f"consumer_risk_{when}": risk.specific_consumer_risk,
        f"producer_risk_{when}": risk.specific_producer_risk,
    }
