"""Is compensation justified? A per-feature decision from the posterior of the deviation.

The *deviation* $\\delta$ of a feature is fitted minus nominal (mm); a *correction* $c$ is
what the finish cut adds, so the finish-cut deviation becomes $\\delta + c$; a *gain*
$g$ means $c = -g\\,\\hat\\delta$ with $\\hat\\delta$ the estimate handed in (posterior mean).

**Loss.** Per part, quadratic off-target loss plus a cost per out-of-tolerance part;
per decision, a cost $C_A$ when the program is changed:

$$L(c) = N\\,\\big(k\\,E[(\\delta + c + \\varepsilon_A)^2]
 + C_\\text{out}\\,P(\\text{part outside } [T_L, T_U])\\big) + C_A\\,[c \\ne 0],$$

with $\\varepsilon_A \\sim N(0, s_A^2)$ the error of the realised adjustment (only when
adjusting), the part value $\\delta + c + \\varepsilon_A + N(0, \\sigma_p^2)$ and $N$ the
parts the decision affects. Expectations are over the posterior of $\\delta$ (normal from
mean and sd, or weighted samples). With normal posterior $N(m, s^2)$:
$E[(\\delta+c)^2] = (m+c)^2 + s^2$; adjusting fully beats doing nothing iff
$m^2 > s_A^2 + C_A/(kN)$ when out-of-tolerance costs are negligible.

**Candidate actions** (all relative to the estimate $\\hat\\delta$ handed in):

- `none`: $c = 0$;
- `full`: PIECS mirroring, $c = -\\hat\\delta$;
- `fraction`: controller feedback percentage, $c = -\\lambda\\hat\\delta$;
- `grubbs`: Grubbs' harmonic rule for the $t$-th setup adjustment, $c = -\\hat\\delta/t$;
- `grubbs_prior`: its prior-shrunk form $c = -\\hat\\delta/(t + u^2/s_d^2)$ with $u$ the
  estimate's standard uncertainty and $s_d$ the prior sd of deviations (`prior_sd`);
- `bayes`: $c^* = \\arg\\min_c L(c)$ under the posterior (including the prior when
  `prior_sd` is given), or none when not adjusting is cheaper.

**Significance**: $p_\\text{exceed} = P(|\\delta| > b)$ for the null band $b$.
**Conformance** (ISO 14253-1): with $U = k_\\text{cov}\\,u$ the acceptance zone is
$[T_L + rU, T_U - rU]$; a value inside *conforms*, one outside
$[T_L - rU, T_U + rU]$ *does not conform*, otherwise it is *ambiguous*; the conformance
probability is $p_c = \\Phi((T_U - y)/u) - \\Phi((T_L - y)/u)$.

**Degrees of freedom.** When $u$ comes with finite (effective) degrees of freedom
$\\nu$ (an estimated probe sigma, Welch-Satterthwaite over the sources), the
deviation's distribution is $y + u\\,t_\\nu$: the losses and $p_\\text{exceed}$ are
taken over it (deterministic quantile draws), $p_c$ uses the $t_\\nu$ cdf and the
coverage factor is $t_\\nu$ at the probability $k_\\text{cov}$ has under the normal
(95.45 % for $k = 2$, JCGM 100 G.6).

**Verdict**:

1. `compensate` (with the Bayes gain) when the Bayes action adjusts (and, when
   `require_significance`, $p_\\text{exceed} \\ge$ `p_significant`), its correction is
   within `max_correction`, and the compensated feature is predicted to conform with
   the guard band;
2. `do not compensate` when the deviation is not significant (or adjusting does not
   pay) and the uncompensated feature conforms, or when the correction is blocked by
   `max_correction` (a blocked correction means: investigate first);
3. `measure more` otherwise: the uncertainty is too large against the tolerance to
   demonstrate conformance or significance. The number of extra probe points that
   would decide it assumes the random part of $u$ shrinks as $1/\\sqrt n$ (a
   systematic part `u_systematic` does not); when no number of points decides, the
   Bayes action is taken and the reason says so.
"""

from __future__ import annotations

import functools
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Literal

import numpy as np
from scipy import optimize, special

from ..errors import InputError

__all__ = [
    "ActionLoss",
    "Conformance",
    "Decision",
    "DecisionSettings",
    "conformance",
    "decide",
    "settings_from_spec",
]

Verdict = Literal["compensate", "do not compensate", "measure more"]


@dataclass(frozen=True)
class DecisionSettings:
    """Thresholds and costs of the compensation decision (mm and cost units).

    Defaults (documented for the study file's `[decision]` table):

    - `null_band` = `None`: 10 % of the tolerance width. Deviations inside it are
      not worth correcting (controller "null band").
    - `feedback_gain` = 0.5: the fixed fraction of the `fraction` policy.
    - `loss_k` = `None`: Taguchi's $k = C_\\text{out}/((T_U - T_L)/2)^2$, i.e. a part at
      a tolerance limit loses as much as a scrapped one (cost per mm$^2$ per part;
      with $C_\\text{out} = 0$ the unit cost 1 is used).
    - `adjustment_cost` = 0.05: cost of changing the program once ($C_A$).
    - `out_of_tolerance_cost` = 1.0: cost per out-of-tolerance part ($C_\\text{out}$,
      the cost unit).
    - `adjustment_sd` = 0.0: sd of the realised correction ($s_A$, mm).
    - `process_sd` = 0.0: part-to-part scatter around the systematic deviation (mm).
    - `prior_sd` = `None`: sd of true deviations between setups ($s_d$, mm); `None` is a
      flat prior (no shrinkage, `grubbs_prior` equals `grubbs`).
    - `max_correction` = `None`: the tolerance width. A larger correction is blocked.
    - `p_significant` = 0.95: $P(|\\delta| > b)$ needed to call a deviation significant.
    - `coverage_factor` = 2.0: $k$ of the expanded uncertainty $U = k u$.
    - `guard_band_factor` = 1.0: $r$ of the acceptance limits $T_L + rU$, $T_U - rU$.
    - `parts_per_decision` = 1: parts the decision affects ($N$).
    - `max_points_factor` = 16.0: "measure more" looks for up to this many times the
      current number of probe points.
    - `require_significance` = `None`: compensate only when $P(|\\delta| > b) \\ge$
      `p_significant`. `None` means *yes without a prior, no with one*: with a flat prior
      the posterior mean is the raw estimate and the loss rule alone would chase noise;
      a prior (`prior_sd`) already shrinks noise away, and demanding significance on top
      would forgo corrections that lower the expected loss.
    """

    null_band: float | None = None
    feedback_gain: float = 0.5
    loss_k: float | None = None
    adjustment_cost: float = 0.05
    out_of_tolerance_cost: float = 1.0
    adjustment_sd: float = 0.0
    process_sd: float = 0.0
    prior_sd: float | None = None
    max_correction: float | None = None
    p_significant: float = 0.95
    coverage_factor: float = 2.0
    guard_band_factor: float = 1.0
    parts_per_decision: int = 1
    max_points_factor: float = 16.0
    require_significance: bool | None = None

    def __post_init__(self):
        def check(name, ok, expected):
            v = getattr(self, name)
            if v is None and name in _OPTIONAL:
                return
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InputError(
                    f"decision setting {name!r}: expected {expected}, got {v!r}", value=v
                )
            if not ok(v):
                raise InputError(
                    f"decision setting {name!r}: expected {expected}, got {v!r}", value=v
                )

        check("null_band", lambda v: v >= 0, "a number >= 0 (mm)")
        check("feedback_gain", lambda v: 0 < v <= 1, "a number in (0, 1]")
        check("loss_k", lambda v: v > 0, "a number > 0 (cost per mm^2)")
        check("adjustment_cost", lambda v: v >= 0, "a number >= 0")
        check("out_of_tolerance_cost", lambda v: v >= 0, "a number >= 0")
        check("adjustment_sd", lambda v: v >= 0, "a number >= 0 (mm)")
        check("process_sd", lambda v: v >= 0, "a number >= 0 (mm)")
        check("prior_sd", lambda v: v > 0, "a number > 0 (mm)")
        check("max_correction", lambda v: v > 0, "a number > 0 (mm)")
        check("p_significant", lambda v: 0.5 < v < 1, "a probability in (0.5, 1)")
        check("coverage_factor", lambda v: v > 0, "a number > 0")
        check("guard_band_factor", lambda v: v >= 0, "a number >= 0")
        check("max_points_factor", lambda v: v >= 1, "a number >= 1")
        if not (self.require_significance is None or isinstance(self.require_significance, bool)):
            raise InputError(
                "decision setting 'require_significance': expected true or false, got "
                f"{self.require_significance!r}",
                value=self.require_significance,
            )
        v = self.parts_per_decision
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise InputError(
                f"decision setting 'parts_per_decision': expected an integer >= 1, got {v!r}",
                value=v,
            )


_OPTIONAL = ("null_band", "loss_k", "prior_sd", "max_correction")


def settings_from_spec(spec: Mapping | None, *, file: str | None = None) -> DecisionSettings:
    """Decision settings from a mapping (the study file's `[decision]` table).

    Missing keys take the defaults of [`DecisionSettings`][]; an unknown key or a bad
    value raises `InputError` naming the key and the value.
    """
    if spec is None:
        return DecisionSettings()
    if not isinstance(spec, Mapping):
        raise InputError(f"decision settings must be a table, got {type(spec).__name__}", file=file)
    known = {f.name for f in fields(DecisionSettings)}
    for key in spec:
        if key not in known:
            raise InputError(
                f"unknown decision setting {key!r} (value {spec[key]!r}); expected one of "
                f"{sorted(known)}",
                file=file,
                value=spec[key],
            )
    try:
        return DecisionSettings(**dict(spec))
    except InputError as e:
        if file is None:
            raise
        raise InputError(e.reason, file=file, value=e.value) from None


@dataclass(frozen=True)
class Conformance:
    """ISO 14253-1 conformance of a value with standard uncertainty `u`.

    `state` is `"conforms"`, `"does not conform"` or `"ambiguous"`; `acceptance` is the
    guarded acceptance zone (empty, i.e. lower > upper, when $2rU$ exceeds the tolerance).
    """

    value: float
    u: float
    expanded: float
    tolerance: tuple[float, float]
    acceptance: tuple[float, float]
    p_conform: float
    state: str

    def __repr__(self) -> str:
        lo, hi = self.acceptance
        return (
            f"Conformance({self.state}, value={self.value:+.4g}, U={self.expanded:.2g}, "
            f"acceptance=[{lo:+.4g}, {hi:+.4g}], p_c={self.p_conform:.3f})"
        )


def conformance(
    value: float,
    u: float,
    tolerance: tuple[float, float],
    *,
    coverage_factor: float = 2.0,
    guard_band_factor: float = 1.0,
    dof: float = math.inf,
) -> Conformance:
    """ISO 14253-1 decision with guard bands $rU$, $U = k u$, and $p_c$ (see module doc).

    With finite `dof` the coverage factor is Student-t's at the normal coverage of
    `coverage_factor` and $p_c$ uses the $t_\\nu$ cdf."""
    lo, hi = (float(t) for t in tolerance)
    if math.isfinite(dof):
        p_cov = 2.0 * float(special.ndtr(coverage_factor)) - 1.0
        big_u = float(special.stdtrit(dof, 0.5 + p_cov / 2.0)) * u
    else:
        big_u = coverage_factor * u
    g = guard_band_factor * big_u
    acc = (lo + g, hi - g)
    if u > 0 and math.isfinite(dof):
        p_c = float(special.stdtr(dof, (hi - value) / u) - special.stdtr(dof, (lo - value) / u))
    elif u > 0:
        p_c = float(special.ndtr((hi - value) / u) - special.ndtr((lo - value) / u))
    else:
        p_c = float(lo <= value <= hi)
    if acc[0] <= value <= acc[1]:
        state = "conforms"
    elif value < lo - g or value > hi + g:
        state = "does not conform"
    else:
        state = "ambiguous"
    return Conformance(float(value), float(u), big_u, (lo, hi), acc, p_c, state)


@dataclass(frozen=True)
class ActionLoss:
    """One candidate action: its gain on the estimate, correction (mm), expected loss."""

    name: str
    gain: float
    correction: float
    expected_loss: float
    blocked: bool

    def __repr__(self) -> str:
        b = ", BLOCKED" if self.blocked else ""
        return (
            f"{self.name}: gain {self.gain:.3f}, correction {self.correction:+.4g} mm, "
            f"E[loss] {self.expected_loss:.4g}{b}"
        )


@dataclass(frozen=True)
class Decision:
    """The verdict for one feature with every number behind it (see module docstring).

    `gain` and `correction` (mm, $c = -g\\hat\\delta$) are zero unless the verdict is
    `"compensate"`; `u_correction` $= g\\,u$ propagates the estimate's standard
    uncertainty. `estimate`, `u_estimate` are what was handed in; `posterior_*` include
    the prior when one is set. `actions` lists every candidate with its expected loss
    (the last is `bayes`); `best_action` is the one with the lowest loss;
    `more_points` is the extra probe points a "measure more" verdict asks for.
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

    def as_row(self) -> dict:
        """A flat dict for a verdict table (JSON/CSV)."""
        row = {
            "feature": self.feature,
            "verdict": self.verdict,
            "gain": self.gain,
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
                f", gain {self.gain:.3f}, correction {self.correction:+.4g}"
                f" ± {self.u_correction:.2g} mm"
            )
        if self.verdict == "measure more" and self.more_points is not None:
            head += f", {self.more_points} more probe points"
        lines = [head + ")"]
        lines += [f"  - {r}" for r in self.reasons]
        lines += [f"  * {a!r}" for a in self.actions]
        return "\n".join(lines)


# --------------------------------------------------------------------------- core


@dataclass(frozen=True)
class _Post:
    """Posterior used for losses: normal (m, s) or weighted samples."""

    m: float
    s: float
    samples: np.ndarray | None = None
    weights: np.ndarray | None = None


def _posterior(m0, s0, samples, prior_sd) -> _Post:
    if samples is None:
        if prior_sd is None:
            return _Post(m0, s0)
        w = prior_sd**2 / (prior_sd**2 + s0**2)
        return _Post(m0 * w, s0 * math.sqrt(w))
    if prior_sd is None:
        wts = np.full(samples.size, 1.0 / samples.size)
    else:
        lw = -0.5 * (samples / prior_sd) ** 2
        wts = np.exp(lw - lw.max())
        wts /= wts.sum()
    m = float(np.sum(wts * samples))
    s = float(math.sqrt(max(np.sum(wts * (samples - m) ** 2), 0.0)))
    return _Post(m, s, samples, wts)


def _p_out(d, tau, lo, hi):
    if np.all(tau == 0):
        return ((d < lo) | (d > hi)).astype(float)
    with np.errstate(divide="ignore"):
        return special.ndtr((lo - d) / tau) + special.ndtr((d - hi) / tau)


def _loss(c, post: _Post, tol, st: DecisionSettings, k: float, adjust):
    """Expected loss of corrections `c` (array), `adjust` flags whether each adjusts."""
    c = np.atleast_1d(np.asarray(c, dtype=float))
    adjust = np.broadcast_to(np.asarray(adjust, dtype=bool), c.shape)
    lo, hi = tol
    sa2 = np.where(adjust, st.adjustment_sd**2, 0.0)
    n = st.parts_per_decision
    if post.samples is None:
        mean = post.m + c
        ed2 = mean**2 + post.s**2 + sa2 + st.process_sd**2
        tau = np.sqrt(post.s**2 + sa2 + st.process_sd**2)
        pout = _p_out(mean, tau, lo, hi)
    else:
        d = post.samples[None, :] + c[:, None]
        ed2 = np.sum(post.weights * d**2, axis=1) + sa2 + st.process_sd**2
        tau = np.sqrt(sa2 + st.process_sd**2)[:, None]
        pout = np.sum(post.weights * _p_out(d, tau, lo, hi), axis=1)
    return n * (k * ed2 + st.out_of_tolerance_cost * pout) + st.adjustment_cost * adjust


def _bayes_correction(post: _Post, tol, st, k) -> float:
    lo, hi = tol
    width = hi - lo
    span = max(width, 6.0 * post.s, 1e-9)
    grid = -post.m + np.linspace(-span, span, 401)
    f = _loss(grid, post, tol, st, k, True)
    j = int(np.argmin(f))
    a, b = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
    res = optimize.minimize_scalar(
        lambda c: float(_loss(c, post, tol, st, k, True)[0]),
        bounds=(a, b),
        method="bounded",
        options={"xatol": 1e-9 * max(width, 1e-6)},
    )
    return float(res.x) if res.fun <= f[j] else float(grid[j])


def _p_exceed(post: _Post, band: float) -> float:
    if post.samples is None:
        if post.s == 0:
            return float(abs(post.m) > band)
        return float(
            special.ndtr((-band - post.m) / post.s) + special.ndtr((post.m - band) / post.s)
        )
    return float(np.sum(post.weights * (np.abs(post.samples) > band)))


@dataclass(frozen=True)
class _Core:
    post: _Post
    p_exceed: float
    actions: tuple[ActionLoss, ...]
    bayes: ActionLoss
    before: Conformance
    after: Conformance
    significant: bool
    justified: bool


def _evaluate(m0, s0, samples, tol, st: DecisionSettings, k, band, max_corr, t, dof) -> _Core:
    post = _posterior(m0, s0, samples, st.prior_sd)
    lam = st.feedback_gain
    shrink = t if st.prior_sd is None else t + s0**2 / st.prior_sd**2
    named = [("none", 0.0), ("full", 1.0), ("fraction", lam), ("grubbs", 1.0 / t)]
    named.append(("grubbs_prior", 1.0 / shrink))
    actions = []
    for name, g in named:
        c = -g * m0 if g != 0.0 and m0 != 0.0 else 0.0
        adj = c != 0.0
        loss = float(_loss(c, post, tol, st, k, adj)[0])
        actions.append(ActionLoss(name, g, c, loss, abs(c) > max_corr))
    c_b = _bayes_correction(post, tol, st, k)
    loss_b = float(_loss(c_b, post, tol, st, k, True)[0])
    loss_0 = actions[0].expected_loss
    if loss_b >= loss_0:
        c_b, loss_b = 0.0, loss_0
    g_b = -c_b / m0 if c_b != 0.0 and m0 != 0.0 else 0.0
    if not 0.0 <= g_b <= 1.0:
        # PIECS gains live in [0, 1]: an optimum outside (a hair above 1 by rounding,
        # or a real overshoot) is clipped and its correction and loss recomputed.
        g_b = min(max(g_b, 0.0), 1.0)
        c_b = -g_b * m0
        loss_b = float(_loss(c_b, post, tol, st, k, c_b != 0.0)[0])
    bayes = ActionLoss("bayes", g_b, c_b, loss_b, abs(c_b) > max_corr)
    actions.append(bayes)
    kw = dict(coverage_factor=st.coverage_factor, guard_band_factor=st.guard_band_factor)
    # a t-distributed estimate (finite dof, no prior): conformance on its scale s0
    t_dist = math.isfinite(dof) and st.prior_sd is None
    u_before, dof_before = (s0, dof) if t_dist else (post.s, math.inf)
    before = conformance(post.m, u_before, tol, dof=dof_before, **kw)
    s_after = math.sqrt(u_before**2 + (st.adjustment_sd**2 if c_b != 0 else 0.0))
    dof_after = dof_before * (s_after / u_before) ** 4 if u_before > 0 else dof_before
    after = conformance(post.m + c_b, s_after, tol, dof=dof_after, **kw)
    p_ex = _p_exceed(post, band)
    significant = p_ex >= st.p_significant
    require = st.require_significance
    if require is None:
        require = st.prior_sd is None
    justified = c_b != 0.0 and (significant or not require)
    return _Core(post, p_ex, tuple(actions), bayes, before, after, significant, justified)


def _clear(core: _Core) -> str | None:
    """The verdict when the evidence is clear, else None ('measure more')."""
    b = core.bayes
    if core.justified:
        if b.blocked:
            return "do not compensate"
        return "compensate" if core.after.state == "conforms" else None
    return "do not compensate" if core.before.state == "conforms" else None


def _scaled(m0, s0, samples, u_sys, n, n_new):
    rand2 = max(s0**2 - u_sys**2, 0.0)
    s_new = math.sqrt(rand2 * n / n_new + u_sys**2)
    if samples is None:
        return s_new, None
    return s_new, m0 + (samples - m0) * (s_new / s0 if s0 > 0 else 1.0)


def _more_points(m0, s0, samples, u_sys, n, tol, st, k, band, max_corr, t, dof) -> int | None:
    n_max = max(int(math.ceil(st.max_points_factor * n)), n + 1)
    cands = sorted({min(n_max, int(math.ceil(n * 1.08**j))) for j in range(1, 200)} - {n})
    prev = n
    for n_new in cands:
        s_new, smp = _scaled(m0, s0, samples, u_sys, n, n_new)
        if _clear(_evaluate(m0, s_new, smp, tol, st, k, band, max_corr, t, dof)) is not None:
            for n_try in range(prev + 1, n_new):  # the smallest decisive count
                s_try, smp = _scaled(m0, s0, samples, u_sys, n, n_try)
                core = _evaluate(m0, s_try, smp, tol, st, k, band, max_corr, t, dof)
                if _clear(core) is not None:
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
    feature: str | None = None,
    dof: float = math.inf,
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
    - `feature`: id carried into the result and error messages.
    - `dof`: (effective) degrees of freedom of `sd` (`inf`: normal). Finite: the
      deviation is `mean + sd * t_dof` (see the module doc); not with `samples`.

    **Returns:** a [`Decision`][] with the verdict, the gain and correction, every
    action's expected loss, significance, conformance before and after, and reasons.
    """
    st = settings if settings is not None else DecisionSettings()
    lo, hi = _tolerance(tolerance, feature)
    if samples is not None:
        if mean is not None or sd is not None:
            raise InputError("give either mean and sd or samples, not both", feature=feature)
        smp = np.asarray(samples, dtype=float).ravel()
        if smp.size < 2 or not np.all(np.isfinite(smp)):
            raise InputError(
                "samples must be at least 2 finite numbers", feature=feature, value=smp.size
            )
        m0, s0 = float(smp.mean()), float(smp.std(ddof=1))
    else:
        smp = None
        if mean is None or sd is None:
            raise InputError(
                "give the deviation's posterior mean and sd (or samples)", feature=feature
            )
        m0, s0 = float(mean), float(sd)
        if not math.isfinite(m0):
            raise InputError(f"mean must be finite, got {mean!r}", feature=feature, value=mean)
        if not (math.isfinite(s0) and s0 > 0):
            raise InputError(
                f"sd must be a finite number > 0, got {sd!r}", feature=feature, value=sd
            )
    if not (math.isfinite(u_systematic) and 0 <= u_systematic <= s0):
        raise InputError(
            f"u_systematic must be in [0, sd={s0:.3g}], got {u_systematic!r}",
            feature=feature,
            value=u_systematic,
        )
    if isinstance(dof, bool) or not isinstance(dof, numbers.Real) or not dof > 0:
        raise InputError(f"dof must be a number > 0 (or inf), got {dof!r}", feature=feature)
    dof = float(dof)
    if math.isfinite(dof):
        if smp is not None:
            raise InputError("dof applies to mean and sd, not to samples", feature=feature)
        smp = m0 + s0 * _T_QUANTILES(dof)
    if isinstance(run_index, bool) or not isinstance(run_index, int) or run_index < 1:
        raise InputError(f"run_index must be an integer >= 1, got {run_index!r}", value=run_index)
    if n_points is not None and (
        isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 1
    ):
        raise InputError(f"n_points must be an integer >= 1, got {n_points!r}", value=n_points)

    width = hi - lo
    band = 0.1 * width if st.null_band is None else st.null_band
    k = st.loss_k if st.loss_k is not None else st.out_of_tolerance_cost / (width / 2) ** 2
    if k == 0.0:
        k = 1.0 / (width / 2) ** 2  # no costs given at all: fall back to unit Taguchi loss
    max_corr = width if st.max_correction is None else st.max_correction
    core = _evaluate(m0, s0, smp, (lo, hi), st, k, band, max_corr, run_index, dof)
    b = core.bayes

    reasons = [
        f"estimate {m0:+.4g} mm, u = {s0:.2g} mm"
        + (f" ({dof:.0f} effective degrees of freedom)" if math.isfinite(dof) else "")
        + (
            f" (posterior with prior sd {st.prior_sd:g}: {core.post.m:+.4g} ± {core.post.s:.2g})"
            if st.prior_sd is not None
            else ""
        ),
        f"P(|deviation| > null band {band:.3g} mm) = {core.p_exceed:.3f} "
        f"({'>=' if core.significant else '<'} {st.p_significant:g}: "
        f"{'significant' if core.significant else 'not significant'})",
    ]
    best = min(core.actions, key=lambda a: a.expected_loss)
    reasons.append(
        "expected loss: "
        + ", ".join(f"{a.name} {a.expected_loss:.4g}" for a in core.actions)
        + f" (lowest: {best.name})"
    )
    reasons.append(
        f"conformance as measured: {core.before.state}, p_c = {core.before.p_conform:.3f}"
    )

    verdict = _clear(core)
    more = None
    blocked = False
    if verdict is None:
        if n_points is not None:
            more = _more_points(
                m0, s0, smp, u_systematic, n_points, (lo, hi), st, k, band, max_corr, run_index,
                dof,
            )  # fmt: skip
        target = core.after if core.justified else core.before
        lo_a, hi_a = target.acceptance
        if n_points is None:
            verdict = "measure more"
            reasons.append(
                f"uncertainty too large against the tolerance: U = {target.expanded:.2g} mm, "
                f"acceptance zone [{lo_a:+.3g}, {hi_a:+.3g}] mm does not contain "
                f"{target.value:+.3g} mm; give n_points to estimate how many more are needed"
            )
        elif more is not None:
            verdict = "measure more"
            reasons.append(
                f"uncertainty too large against the tolerance: U = {target.expanded:.2g} mm, "
                f"acceptance zone [{lo_a:+.3g}, {hi_a:+.3g}] mm does not contain "
                f"{target.value:+.3g} mm; about {more} more probe points "
                f"({n_points} -> {n_points + more}, u ~ 1/sqrt(n)) would decide"
            )
        else:
            verdict = "compensate" if core.justified and not b.blocked else "do not compensate"
            reasons.append(
                f"even {st.max_points_factor:g}x the probe points would not decide "
                f"(the estimate sits on a threshold or u_systematic dominates): "
                f"taking the lowest-loss action ({'adjust' if core.justified else 'none'})"
            )
    if b.blocked and core.justified:
        blocked = True
        verdict = "do not compensate"
        reasons.append(
            f"blocked: correction {b.correction:+.4g} mm exceeds max_correction {max_corr:.3g} mm;"
            " investigate (wrong tool, offset or setup) before adjusting"
        )
    if verdict == "compensate":
        gain, corr = b.gain, b.correction
        if gain == 0.0:  # compensate was forced by the fallback, use full gain
            gain, corr = 1.0, -m0
        reasons.append(
            f"compensate with gain {gain:.3f}: predicted after {core.after.value:+.3g} mm, "
            f"{core.after.state}, p_c = {core.after.p_conform:.3f}"
        )
    else:
        gain, corr = 0.0, 0.0
        if verdict == "do not compensate" and not blocked:
            if b.correction == 0.0:
                reasons.append("do not compensate: adjusting does not lower the expected loss")
            elif not core.significant:
                reasons.append(
                    "do not compensate: the deviation is not significant (without a prior, "
                    "significance is required)"
                )
    return Decision(
        feature=feature,
        verdict=verdict,
        gain=float(gain),
        correction=float(corr),
        u_correction=float(abs(gain) * s0),
        estimate=m0,
        u_estimate=s0,
        posterior_mean=core.post.m,
        posterior_sd=core.post.s,
        null_band=float(band),
        p_exceed=core.p_exceed,
        significant=core.significant,
        best_action=best.name,
        actions=core.actions,
        conformance_before=core.before,
        conformance_after=core.after,
        tolerance=(lo, hi),
        blocked=blocked,
        n_points=n_points,
        more_points=more,
        reasons=tuple(reasons),
        dof=dof,
    )


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
