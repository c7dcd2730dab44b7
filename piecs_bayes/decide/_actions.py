r"""Candidate actions of the compensation decision and their expected losses.

For the posterior of a feature's deviation $\delta$ (fitted minus nominal, mm; normal
from mean and sd, or weighted samples) and a correction $c$ that the finish cut adds,
the expected loss is quadratic off-target loss plus a cost per out-of-tolerance part
over the parts the decision affects, plus a cost when the program is changed. Each
candidate action (`none`, `full`, `fraction`, `grubbs`, `grubbs_prior`, `bayes`: the
correction that minimises the loss) is evaluated into an [`ActionLoss`][], with the
significance $P(|\delta| > b)$ for the null band $b$; `_evaluate` gathers what
`_verdict.conclude` needs. With finite degrees of freedom the posterior is given as
deterministic quantile draws of $y + u\,t_\nu$ (see `decide`).

The loss and the actions: docs/models/decision.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import _config
from ._conformance import Conformance, conformance
from ._settings import DecisionSettings

optimize = _config.LazyModule("scipy.optimize")
special = _config.LazyModule("scipy.special")


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


# --------------------------------------------------------------------------- core


@dataclass(frozen=True)
class _Post:
    """Posterior used for losses: normal (m, s) or weighted samples (with the weights'
    first two moments about zero, and the samples sorted with their cumulative
    weights: what `_loss` reads for many corrections at once)."""

    m: float
    s: float
    samples: np.ndarray | None = None
    weights: np.ndarray | None = None
    moments: tuple[float, float, float] = (1.0, 0.0, 0.0)  # sum w, sum w x, sum w x^2
    ordered: np.ndarray | None = None  # the samples, sorted
    cumulative: np.ndarray | None = None  # 0, then the cumulative weights in that order


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
    order = np.argsort(samples, kind="stable")
    moments = (float(np.sum(wts)), float(wts @ samples), float(wts @ (samples * samples)))
    cumulative = np.concatenate([[0.0], np.cumsum(wts[order])])
    return _Post(m, s, samples, wts, moments, samples[order], cumulative)


def p_out(d, tau, lo, hi):
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
        pout = p_out(mean, tau, lo, hi)
    else:
        w0, w1, w2 = post.moments  # E[(x + c)^2] without a (corrections x samples) array
        var = sa2 + st.process_sd**2
        ed2 = w2 + 2.0 * c * w1 + c * c * w0 + var
        pout = _p_out_samples(post, c, np.sqrt(var), lo, hi)
    return n * (k * ed2 + st.out_of_tolerance_cost * pout) + st.adjustment_cost * adjust


def _count(ordered: np.ndarray, c: np.ndarray, bound: float, strict: bool) -> np.ndarray:
    """Per correction `c`: how many of the sorted samples have `x + c < bound` (`strict`)
    or `x + c <= bound`, as floating point rounds `x + c`. `x + c` rises with `x`, so
    they are the first ones: a binary search for `bound - c` (which rounds too), then
    moved across the few values where the two roundings disagree, a value (and all its
    repeats) at a time."""
    n = ordered.size

    def below(i):
        v = ordered[np.clip(i, 0, n - 1)] + c
        return (v < bound) if strict else (v <= bound)

    j = np.searchsorted(ordered, bound - c, side="left" if strict else "right")
    while True:
        back = (j > 0) & ~below(j - 1)  # the sample before is not below: step back
        j = np.where(back, np.searchsorted(ordered, ordered[np.maximum(j - 1, 0)]), j)
        ahead = (j < n) & below(j)  # the sample at j is below: step over its value
        j = np.where(ahead, np.searchsorted(ordered, ordered[np.minimum(j, n - 1)], "right"), j)
        if not (back.any() or ahead.any()):
            return j


def _p_out_samples(post: _Post, c: np.ndarray, tau: np.ndarray, lo: float, hi: float):
    """`sum_i w_i p_out(x_i + c, tau)` per correction. Without scatter (`tau` 0): the
    weights of the samples below `lo - c` and above `hi - c`, from the sorted samples'
    cumulative weights; with it: a normal cdf per (correction, sample), summed by a
    matrix-vector product."""
    if np.all(tau == 0):
        cum = post.cumulative
        below = cum[_count(post.ordered, c, lo, True)]
        return below + (cum[-1] - cum[_count(post.ordered, c, hi, False)])
    if np.all(tau > 0):
        z = np.subtract.outer(lo - c, post.samples)
        z /= tau[:, None]
        pout = special.ndtr(z, out=z) @ post.weights
        z = np.add.outer(c - hi, post.samples)
        z /= tau[:, None]
        return pout + special.ndtr(z, out=z) @ post.weights
    d = post.samples[None, :] + c[:, None]
    return np.sum(post.weights * p_out(d, tau[:, None], lo, hi), axis=1)


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
class CoreVerdict:
    post: _Post
    p_exceed: float
    actions: tuple[ActionLoss, ...]
    bayes: ActionLoss
    before: Conformance
    after: Conformance
    significant: bool
    justified: bool


def evaluate_actions(
    m0, s0, samples, tol, st: DecisionSettings, k, band, max_corr, t, dof
) -> CoreVerdict:
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
    return CoreVerdict(post, p_ex, tuple(actions), bayes, before, after, significant, justified)
