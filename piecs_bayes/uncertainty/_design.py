r"""Where to probe a feature: a design for the uncertainty of the characteristic.

Probe points at fractions $t_i$ of a feature give, linearised at the nominal, the
characteristic's $u_\text{fit}(q)$ at its nominal points $q$ (with the declared probe
repeatability and the robust loss's variance factor); the systematic sources add
$u_\text{sys}(q)$, which no design reduces. [`predict_feature`][] gives the prediction
([`FeaturePrediction`][]: $u$, dof, $U$, the tolerance-to-U ratio).
[`design_fractions`][] places `n` points in the feature's usable window: a share
(`inside_share`) spread evenly inside, the others by coordinate exchange to minimise the
largest $u_\text{fit}$ over the characteristic's points (G-optimal), never worse than
[`uniform_fractions`][]; [`augment_fractions`][] adds points beside existing ones;
[`points_for_ratio`][] finds the least count that reaches a ratio. The settings are a
[`DesignSettings`][].

The criterion and the design: docs/uncertainty.md, section 8.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..fit import coverage_factor, effective_dof
from ._characteristic import at_fractions, deviation_and_jacobian, u_systematic

_CANDIDATES = 201
_SWEEPS = 8


@dataclass(frozen=True)
class DesignSettings:
    """How a feature's points are designed and judged.

    - `sigma`: the probe repeatability (mm); `kappa`: the loss's variance factor.
    - `at`: the decision's characteristic (`"worst"`, `"mid"`, `"start"`, `"end"`).
    - `sources`: standard deviations of the systematic sources (as `u_systematic`).
    - `dof`: degrees of freedom of the probe sigma (`inf`: known).
    - `coverage_factor`: the decision's k (2: 95.45 %), made Student-t at the dof.
    - `inside_share`, `spacing`: the spread share and the least spacing (mm).
    """

    sigma: float
    kappa: float = 1.0
    at: str = "worst"
    sources: tuple[tuple[str, float], ...] = ()
    dof: float = math.inf
    coverage_factor: float = 2.0
    inside_share: float = 0.2
    spacing: float = 0.1


@dataclass(frozen=True)
class FeaturePrediction:
    """The predicted uncertainty of a feature's characteristic for a set of points:
    `u_fit`, `u_systematic`, `u` (mm) at the fraction `t` where `u` is largest,
    `dof` (Welch-Satterthwaite), `expanded` ($U$) and `ratio` (tolerance span / 2U)."""

    n: int
    t: float
    u_fit: float
    u_systematic: float
    dof: float
    expanded: float
    ratio: float

    @property
    def u(self) -> float:
        return math.hypot(self.u_fit, self.u_systematic)


def _free_columns(feature, fixed) -> np.ndarray:
    return np.array([name not in fixed for name in feature.param_names], dtype=bool)


def _jacobian(feature, ts, free):
    zero = np.zeros(feature.nparams)
    return deviation_and_jacobian(feature, zero, np.asarray(ts, dtype=float))[1][:, free]


def _criterion(jac_pts, jac_at) -> np.ndarray:
    """Largest $g^\\top (J^\\top J)^{-1} g$ over the characteristic points (inf when
    singular); `jac_pts` `(..., n, p)`."""
    m = np.einsum("...ni,...nj->...ij", jac_pts, jac_pts)
    p = m.shape[-1]
    cond_ok = np.linalg.matrix_rank(m, tol=1e-10 * np.trace(m, axis1=-2, axis2=-1)) == p
    safe = np.where(cond_ok[..., None, None], m, np.eye(p))
    inv = np.linalg.inv(safe)
    v = np.einsum("ki,...ij,kj->...k", jac_at, inv, jac_at)
    return np.where(cond_ok, v.max(axis=-1), np.inf)


def uniform_fractions(n: int, window) -> np.ndarray:
    """`n` fractions evenly spaced over the window (its mid-point for one)."""
    t0, t1 = window
    return np.array([(t0 + t1) / 2.0]) if n == 1 else np.linspace(t0, t1, n)


def _nearest_free(cand, inside, targets, min_gap) -> np.ndarray:
    """For each target in turn, the nearest candidate that keeps `min_gap` from the
    points already placed (the spread share first)."""
    taken, idx = list(inside), []
    for target in targets:
        if taken:
            gaps = np.abs(cand[:, None] - np.asarray(taken)[None, :])
            ok = np.all(gaps >= min_gap - 1e-12, axis=1)
            ok = ok if ok.any() else np.ones(cand.size, dtype=bool)  # a full window
        else:
            ok = np.ones(cand.size, dtype=bool)
        j = int(np.argmin(np.where(ok, np.abs(cand - target), np.inf)))
        idx.append(j)
        taken.append(cand[j])
    return np.asarray(idx, dtype=int)


def _even_start(cand, inside, n_out, min_gap) -> np.ndarray:
    """Candidate indices for `n_out` points spread evenly over the window."""
    return _nearest_free(cand, inside, np.linspace(cand[0], cand[-1], n_out), min_gap)


def _end_start(cand, inside, n_out, min_gap) -> np.ndarray:
    """Candidate indices for `n_out` points clustered at both ends of the window
    (alternately, `min_gap` apart; the middle one when the count is odd)."""
    ends = [cand[0] + (k // 2) * min_gap if k % 2 == 0 else cand[-1] - (k // 2) * min_gap
            for k in range(n_out - n_out % 2)]  # fmt: skip
    targets = ends + ([0.5 * (cand[0] + cand[-1])] if n_out % 2 else [])
    return _nearest_free(cand, inside, targets, min_gap)


def _exchange(idx, cand, inside, jac_c, jac_in, jac_at, min_gap):
    """Coordinate exchange from the start `idx`: each outer point moved in turn to the
    allowed candidate that lowers the criterion most, until no move helps."""
    idx = np.array(idx)
    n_out = idx.size
    best = float(_criterion(np.concatenate([jac_in, jac_c[idx]]), jac_at))
    for _ in range(_SWEEPS):
        improved = False
        for k in range(n_out):
            others = np.delete(idx, k)
            taken = np.concatenate([inside, cand[others]])
            gaps = np.abs(cand[:, None] - taken[None, :])
            allowed = np.all(gaps >= min_gap - 1e-12, axis=1)
            trial = np.broadcast_to(jac_c[others], (cand.size, *jac_c[others].shape))
            pts = np.concatenate(
                [np.broadcast_to(jac_in, (cand.size, *jac_in.shape)), trial, jac_c[:, None, :]],
                axis=1,
            )
            crit = np.where(allowed, _criterion(pts, jac_at), np.inf)
            j = int(np.argmin(crit))
            if crit[j] < best * (1.0 - 1e-9):
                idx[k], best, improved = j, float(crit[j]), True
        if not improved:
            break
    return best, idx


def design_fractions(feature, n: int, window, settings: DesignSettings, *, fixed=()):
    """The designed fractions (sorted) of `n` points in `window` and which of them
    are the spread share (`(t, inside)`); see the module docstring."""
    free = _free_columns(feature, fixed)
    t0, t1 = window
    uniform = uniform_fractions(n, window)
    if n < 2 or (t1 - t0) * feature.length < (n - 1) * settings.spacing:
        return uniform, np.zeros(n, dtype=bool)  # no room for a design at the spacing
    share = settings.inside_share
    n_in = (max(1, int(share * n)) if share > 0 else 0) if n >= 5 else 0
    n_in = min(n_in, n - 1)
    inside = t0 + (t1 - t0) * np.arange(1, n_in + 1) / (n_in + 1)
    cand = np.linspace(t0, t1, _CANDIDATES)
    jac_c = _jacobian(feature, cand, free)
    jac_in = _jacobian(feature, inside, free) if n_in else np.zeros((0, int(free.sum())))
    jac_at = _jacobian(feature, at_fractions(feature, settings.at), free)
    min_gap = min(settings.spacing, (t1 - t0) * feature.length / max(n - 1, 1)) / feature.length
    n_out = n - n_in
    # two starts (the outer points spread evenly; clustered at both ends), each
    # improved by coordinate exchange; the better one is kept
    best, idx = np.inf, None
    for start in (
        _even_start(cand, inside, n_out, min_gap),
        _end_start(cand, inside, n_out, min_gap),
    ):
        crit, found = _exchange(start, cand, inside, jac_c, jac_in, jac_at, min_gap)
        if crit < best:
            best, idx = crit, found
    jac_u = _jacobian(feature, uniform, free)
    if _criterion(jac_u, jac_at) <= best:
        return uniform, np.zeros(n, dtype=bool)
    ts = np.concatenate([inside, cand[idx]])
    flags = np.concatenate([np.ones(n_in, dtype=bool), np.zeros(n_out, dtype=bool)])
    order = np.argsort(ts, kind="stable")
    return ts[order], flags[order]


def augment_fractions(feature, existing, n_add: int, window, settings: DesignSettings, *, fixed=()):
    """`n_add` new fractions in `window` that, with the points already probed at
    fractions `existing`, minimise the criterion (the same exchange, the probed
    points held fixed): the plan of a "measure more" verdict."""
    free = _free_columns(feature, fixed)
    t0, t1 = window
    if n_add <= 0:
        return np.zeros(0)
    have = np.asarray(existing, dtype=float)
    cand = np.linspace(t0, t1, _CANDIDATES)
    jac_c = _jacobian(feature, cand, free)
    jac_have = _jacobian(feature, have, free) if have.size else np.zeros((0, int(free.sum())))
    jac_at = _jacobian(feature, at_fractions(feature, settings.at), free)
    total = have.size + n_add
    min_gap = min(settings.spacing, (t1 - t0) * feature.length / max(total - 1, 1)) / feature.length
    best, idx = np.inf, None
    for start in (_even_start(cand, have, n_add, min_gap), _end_start(cand, have, n_add, min_gap)):
        crit, found = _exchange(start, cand, have, jac_c, jac_have, jac_at, min_gap)
        if crit < best:
            best, idx = crit, found
    return np.sort(cand[idx])


def predict_feature(feature, ts, settings: DesignSettings, *, fixed=()) -> FeaturePrediction:
    """The predicted uncertainty of the characteristic from points at fractions `ts`."""
    free = _free_columns(feature, fixed)
    ats = at_fractions(feature, settings.at)
    jac_pts = _jacobian(feature, ts, free)
    jac_at = _jacobian(feature, ats, free)
    m = jac_pts.T @ jac_pts
    if np.linalg.matrix_rank(m, tol=1e-10 * np.trace(m)) < m.shape[0]:
        var = np.full(ats.size, np.inf)
    else:
        var = np.einsum("ki,ij,kj->k", jac_at, np.linalg.inv(m), jac_at)
    u_fit = settings.sigma * np.sqrt(settings.kappa * np.maximum(var, 0.0))
    u_sys = u_systematic(feature, ats, dict(settings.sources))
    u = np.hypot(u_fit, u_sys)
    i = int(np.argmax(u))
    dof = float(effective_dof(u[i], u_fit[i], settings.dof)) if np.isfinite(u[i]) else 0.0
    p_cov = math.erf(settings.coverage_factor / math.sqrt(2.0))
    k = float(coverage_factor(dof, p_cov)) if dof > 0 else math.inf
    big_u = k * float(u[i])
    lo, hi = feature.tolerance
    ratio = (hi - lo) / (2.0 * big_u) if big_u > 0 else math.inf
    return FeaturePrediction(
        n=len(ts), t=float(ats[i]), u_fit=float(u_fit[i]), u_systematic=float(u_sys[i]),
        dof=dof, expanded=big_u, ratio=float(ratio),
    )  # fmt: skip


def points_for_ratio(
    feature, window, settings: DesignSettings, ratio: float, *, n_min: int, n_max: int, fixed=()
):
    """The least count in `[n_min, n_max]` whose designed points reach `ratio`, with
    its fractions, spread flags and prediction; `n_max` when none does (the
    prediction says how far it falls short). The predicted ratio grows with the count,
    so the count is found by doubling, then bisection (a few designs, not one per
    count)."""
    memo = {}

    def at(n):
        if n not in memo:
            ts, inside = design_fractions(feature, n, window, settings, fixed=fixed)
            memo[n] = (ts, inside, predict_feature(feature, ts, settings, fixed=fixed))
        return memo[n]

    if at(n_min)[2].ratio >= ratio:
        return at(n_min)
    lo, step = n_min, 1  # at(lo) falls short
    while True:
        hi = min(lo + step, n_max)
        if at(hi)[2].ratio >= ratio:
            break
        if hi == n_max:
            return at(n_max)
        lo, step = hi, 2 * step
    while hi - lo > 1:  # at(lo) short, at(hi) reaches
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if at(mid)[2].ratio >= ratio else (mid, hi)
    return at(hi)
