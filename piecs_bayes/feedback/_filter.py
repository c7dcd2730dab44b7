"""The numerical core of part-to-part tracking: a collapsed mixture Kalman filter, batched.

The model and its notation are those of `_tracking` (docs/feedback.md); this module holds
the arithmetic, vectorised with NumPy over any number of independent series (runs of
parts times hyper-parameter grid points), so that 1,000 simulated runs on the grid filter
in one pass. [`mixture_filter`][] keeps the posterior over the parts' indicators
(regular, odd, undeclared step) as one Gaussian per recent event (`STEP_MEMORY`
components for steps), and returns per part and series the log predictive density, the
predicted and filtered level and drift, the indicators' probabilities with hindsight
and, with `ahead`, predictions further ahead; [`smoother`][] gives the smoothed level.
A declared tool change restarts the wear ([`wear_factor`][]); with a diffuse first
level, part 0 sets the level and contributes no likelihood.

The filter's arithmetic: docs/feedback.md, "The filter".
"""

from __future__ import annotations

import numpy as np

from .. import _config
from ._mixture import logsumexp

special = _config.LazyModule("scipy.special")


_TINY = 1e-300
_LOG2PI = float(np.log(2.0 * np.pi))

STEP_MEMORY = 6
"""Parts an undeclared step's hypothesis is kept apart (with hindsight) before merging."""


def _prior_k(p_odd, p_step, declared):
    """`(B, 3)` prior of part k's indicator (regular, odd, undeclared step); no
    undeclared step at a declared change."""
    p_step = np.where(declared, 0.0, np.asarray(p_step))
    return np.stack([1.0 - p_odd - p_step, p_odd + 0.0 * p_step, p_step], -1)


def _merge(logw, *moments):
    """Moment-match Gaussians `(B, M)` (log weights, then `a, d, p11, p12, p22`) over
    axis 1: `(log total weight, a, d, p11, p12, p22)`, each `(B,)`."""
    lt = logsumexp(logw, axis=1)
    g = np.exp(logw - lt[:, None])
    a, d, p11, p12, p22 = moments
    ma, md = np.sum(g * a, 1), np.sum(g * d, 1)
    da, dd = a - ma[:, None], d - md[:, None]
    return (lt, ma, md, np.sum(g * (p11 + da * da), 1), np.sum(g * (p12 + da * dd), 1),
            np.sum(g * (p22 + dd * dd), 1))  # fmt: skip


def wear_factor(declared, wear_reset) -> np.ndarray:
    """`(B, n)` the drift's coefficient in the level's transition to part k:
    $1 - \\rho\\,m$ at a declared change ($m$ parts since the previous one or the
    first part), 1 elsewhere (see the module doc)."""
    declared = np.asarray(declared, dtype=bool)
    b, n = declared.shape
    since = np.zeros((b, n))
    last = np.zeros(b)
    for k in range(n):
        since[:, k] = k - last
        last = np.where(declared[:, k], k, last)
    rho = np.asarray(wear_reset, dtype=float)[:, None]
    return np.where(declared, 1.0 - rho * since, 1.0)


def _ahead(w, a, d, p11, p12, p22, par, fwear, declared, hazard, k, horizon):
    """`(B, horizon)` mean and variance of the level of parts k + 1 .. k + horizon given
    the components after part k (as `lm`, `lv`: the regular components and declared
    steps; an undeclared step at a part in between that carries the hazard, a measured
    one, adds its prior share of variance): the prediction through parts without a
    measurement."""
    b, n = declared.shape
    phi = par.get("drift_decay", np.ones(b))[:, None]
    am = np.full((b, horizon), np.nan)
    av = np.full((b, horizon), np.nan)
    step = np.zeros(b)
    for h in range(1, horizon + 1):
        j = k + h
        f = fwear[:, j : j + 1] if j < n else 1.0
        a, d, p11, p12, p22 = _transition(a, d, p11, p12, p22, f, phi, par)
        dec = declared[:, j] if j < n else np.zeros(b, dtype=bool)
        m = np.sum(w * a, 1)
        am[:, h - 1] = m
        av[:, h - 1] = (
            np.sum(w * (p11 + (a - m[:, None]) ** 2), 1) + step + np.where(dec, par["step2"], 0.0)
        )
        # a part passed may have had an undeclared step (where it carries the hazard)
        haz = hazard[:, j] if j < n else np.ones(b, dtype=bool)
        step = step + np.where(dec, par["step2"], np.where(haz, par["p_step"], 0.0) * par["step2"])
    return am, av


def _transition(a, d, p11, p12, p22, f, phi, par):
    """One part's transition of components: $\\ell' = \\ell + f d$, $d' = \\phi d$
    (`drift_decay`), the level and drift walks added."""
    pa, pd = a + f * d, phi * d
    pp11 = p11 + 2.0 * f * p12 + f * f * p22 + par["q_level"][:, None]
    pp12 = phi * (p12 + f * p22)
    pp22 = phi * phi * p22 + par["q_drift"][:, None]
    return pa, pd, pp11, pp12, pp22


def _collapse(lj, mom, c_n, memory):
    """The components after a measured part: a regular part after none kept apart, the
    last part odd or the oldest step merge into `base`; a new odd part and a new step
    each start a component; a step j - 1 parts ago becomes j ago."""
    base = [0, 1, c_n - 1]
    merged = [
        _merge(lj[:, base, 0], *(v[:, base, 0] for v in mom)),
        _merge(lj[:, :, 1], *(v[:, :, 1] for v in mom)),  # a new odd part
        _merge(lj[:, :, 2], *(v[:, :, 2] for v in mom)),  # a new step
    ]
    out = [np.stack(z, 1) for z in zip(*merged, strict=True)]
    if memory > 1:  # step j - 1 parts ago, then a regular part: step j ago
        older = slice(2, c_n - 1)
        out = [out[0]] + [np.concatenate([x, v[:, older, 0]], 1)
                          for x, v in zip(out[1:], mom, strict=True)]  # fmt: skip
        out[0] = np.concatenate([out[0], lj[:, older, 0]], 1)
    return out


def _collapse_unseen(lj, mom, c_n):
    """The components after a part without a measurement: nothing is judged, so no
    hypothesis moves on (the odd one waits for the next measurement, a step keeps its
    count of measurements); a new step joins "a step since the last measurement"."""

    def pick(cs, s_):
        return [lj[:, cs, s_]] + [v[:, cs, s_] for v in mom]

    def join(*parts):
        return [np.concatenate(z, 1) for z in zip(*parts, strict=True)]

    merged = [
        _merge(*pick([0], 0)),
        _merge(*join(pick([1], 0), pick(slice(None), 1))),  # odd: weight 0 when unseen
        _merge(*join(pick([2], 0), pick(slice(None), 2))),
    ]
    out = [np.stack(z, 1) for z in zip(*merged, strict=True)]
    if c_n > 3:
        rest = pick(slice(3, c_n), 0)
        out = [np.concatenate([x, r], 1) for x, r in zip(out, rest, strict=True)]
    return out


def mixture_filter(y, r, par, declared, memory: int = STEP_MEMORY, *, ahead: int = 0,
                   feed=None, mixture: bool = True, hazard=None):  # fmt: skip
    """Run the collapsed mixture filter on a batch of series.

    A part without a measurement (`y` NaN) is a prediction step only: no likelihood, no
    update, no odd-part indicator, and no undeclared-step indicator of its own: the
    step probability `p_step` is a hazard per measurement, carried by the measured part
    that ends a gap (a step anywhere in the gap moves the level that part shows).

    **Arguments:**

    - `y`: `(B, n)` observed values (mm); NaN: the part was not measured (part 0 must
      be measured when its level is diffuse).
    - `r`: `(B, n)` measurement variances $u_k^2$ (mm$^2$), all > 0.
    - `par`: dict of `(B,)` arrays: `scatter2`, `q_level`, `q_drift`, `drift0`,
      `step2`, `p_step`, `p_odd`, `odd2` (variances in mm$^2$), `level0` (prior
      variance of the level of part 0, `inf` for diffuse), `drift0_mean` (mm/part)
      and `wear_reset`.
    - `declared`: `(B, n)` or `(n,)` booleans, True at a declared tool change.
    - `memory`: `STEP_MEMORY` (1: GPB2).
    - `ahead`: H > 0 adds `am`, `av` `(B, n, H)`: the level of parts k + 1 .. k + H
      given parts <= k (for a measurement that arrives late, and a correction held
      over several parts).
    - `feed`: `feed(k, out) -> (B,)` values of part k, called before part k is used
      (a closed loop: the value depends on the correction decided from `out` so far);
      `y` is then only the shape (and the values not fed).
    - `mixture`: False skips the predictive mixture `pw`, `pm`, `ps` (memory).
    - `hazard`: `(n,)` or `(B, n)` booleans, the parts that carry the undeclared-step
      hazard; default the measured parts (every part with `feed`).

    **Returns:** a dict of arrays: `loglik` `(B, n)` (log predictive density of each part;
    0 for a diffuse part 0), `pw`, `pm`, `ps` `(B, n, 3C)` (weights, means and sds of the
    one-step-ahead predictive mixture of $y_k$, $C$ = `memory` + 2; NaN for a diffuse
    part 0), `pit` `(B, n)` (that mixture's cdf at $y_k$), `lm`, `lv` `(B, n)`
    (predictive mean and variance of the level of part $k$ given parts $< k$, the
    regular component plus a declared step; the collapsed mixture), `fm`, `fv`
    `(B, n)` (filtered level mean and variance), `fd`, `fdv` (filtered drift),
    `p_filt` `(B, n, 3)` ($p(s_k \\mid y_{0:k})$), `p_lag` `(B, n, 3)` (the
    indicators with hindsight: odd given $y_{0:k+1}$; a step given $y_{0:k+j}$,
    $j$ = `memory` or the parts left, the share merged into a later odd part or step
    given the parts up to it; both filtered at the end of the run; regular the rest),
    `next_m`, `next_v` `(B,)` (level predictive for part n).
    """
    y = np.array(y, dtype=float)
    r = np.asarray(r, dtype=float)
    b, n = y.shape
    c_n = memory + 2
    declared = np.broadcast_to(np.asarray(declared, dtype=bool), (b, n))
    fwear = wear_factor(declared, par.get("wear_reset", np.zeros(b)))
    phi = par.get("drift_decay", np.ones(b))[:, None]
    scatter2 = par["scatter2"][:, None]
    step2 = par["step2"][:, None]
    odd2 = par["odd2"][:, None]
    level0 = par["level0"]
    diffuse = ~np.isfinite(level0)
    p_odd = np.asarray(par["p_odd"])[:, None] * np.ones(n)
    if hazard is None:
        hazard = np.ones((b, n), dtype=bool) if feed is not None else ~np.isnan(y)
    hazard = np.broadcast_to(np.asarray(hazard, dtype=bool), (b, n))
    if feed is None:
        p_odd = np.where(np.isnan(y), 0.0, p_odd)
        if np.any(diffuse & np.isnan(y[:, 0])):
            raise ValueError("part 0 must be measured when the first level is diffuse")
    s_odd = np.array([0.0, 1.0, 0.0])
    s_step = np.array([0.0, 0.0, 1.0])

    out = {
        k: np.full((b, n), np.nan) for k in ("loglik", "lm", "lv", "fm", "fv", "fd", "fdv", "pit")
    }
    for k in ("pw", "pm", "ps") if mixture else ():
        out[k] = np.full((b, n, 3 * c_n), np.nan)
    if ahead:
        out["am"] = np.full((b, n, ahead), np.nan)
        out["av"] = np.full((b, n, ahead), np.nan)
    out["p_filt"] = np.full((b, n, 3), np.nan)
    p_odd_lag = np.full((b, n), np.nan)
    p_step_lag = np.full((b, n), np.nan)
    gone = np.zeros((b, n))  # a step's probability merged away by a later odd part or step

    # carried components (B, C): weights and moments
    w = np.zeros((b, c_n))
    w[:, 0] = 1.0
    a = np.zeros((b, c_n))
    d = np.tile(par.get("drift0_mean", np.zeros(b))[:, None], (1, c_n))
    p11 = np.tile(np.where(diffuse, 0.0, level0)[:, None], (1, c_n))
    p12 = np.zeros((b, c_n))
    p22 = np.tile(par["drift0"][:, None], (1, c_n))
    for k in range(n):
        if feed is not None:
            y[:, k] = feed(k, out)
        seen = np.isfinite(y[:, k])  # (B,): part k measured
        p_step_k = np.where(hazard[:, k], par["p_step"], 0.0)
        pri_k = np.log(np.maximum(_prior_k(np.where(seen, p_odd[:, k], 0.0), p_step_k,
                                           declared[:, k]), _TINY))  # fmt: skip
        qadd = np.where(declared[:, k : k + 1], 1.0, s_step[None, :]) * step2  # (B, 3) by s_k
        rk = r[:, k : k + 1] + scatter2 + s_odd[None, :] * odd2  # (B, 3) by s_k
        if k == 0:
            pa, pd, pp11, pp12, pp22 = a, d, p11, p12, p22
        else:
            pa, pd, pp11, pp12, pp22 = _transition(a, d, p11, p12, p22, fwear[:, k : k + 1],
                                                   phi, par)  # fmt: skip
        # level predictive for part k (before its indicator): declared step included
        dec = np.where(declared[:, k], step2[:, 0], 0.0)
        lm = np.sum(w * pa, 1)
        lv = np.sum(w * (pp11 + (pa - lm[:, None]) ** 2), 1) + dec
        first = diffuse & (k == 0)
        out["lm"][:, k] = np.where(first, np.nan, lm)
        out["lv"][:, k] = np.where(first, np.nan, lv)
        # expand: (B, c, s)
        e11 = pp11[:, :, None] + qadd[:, None, :]
        e12 = np.broadcast_to(pp12[:, :, None], e11.shape)
        e22 = np.broadcast_to(pp22[:, :, None], e11.shape)
        ea = np.broadcast_to(pa[:, :, None], e11.shape)
        ed = np.broadcast_to(pd[:, :, None], e11.shape)
        rr = np.broadcast_to(rk[:, None, :], e11.shape)
        sn = seen[:, None, None]
        yk = np.where(seen, y[:, k], 0.0)[:, None, None]
        with np.errstate(divide="ignore"):
            logw_prev = np.log(np.maximum(w, _TINY))
        s = e11 + rr
        innov = np.where(sn, yk - ea, 0.0)
        logn = -0.5 * (_LOG2PI + np.log(s) + innov**2 / s)
        logn = np.where(first[:, None, None] | ~sn, 0.0, logn)
        logp = logw_prev[:, :, None] + pri_k[:, None, :]  # prior weights, no data
        logj = (logp + logn).reshape(b, 3 * c_n)
        tot = logsumexp(logj, axis=1)
        out["loglik"][:, k] = np.where(first | ~seen, 0.0, tot)
        pw = np.exp(logp - logsumexp(logp.reshape(b, -1), 1)[:, None, None])
        if mixture:
            out["pw"][:, k] = pw.reshape(b, -1)
            out["pm"][:, k] = np.where(first[:, None], np.nan, ea.reshape(b, -1))
            out["ps"][:, k] = np.where(first[:, None], np.nan, np.sqrt(s).reshape(b, -1))
        pit = np.sum(pw * special.ndtr(innov / np.sqrt(s)), axis=(1, 2))
        out["pit"][:, k] = np.where(first | ~seen, np.nan, pit)
        # update every (component, indicator) pair
        k1, k2 = np.where(sn, e11 / s, 0.0), np.where(sn, e12 / s, 0.0)
        fd_ = first[:, None, None]
        ua = np.where(fd_, yk, ea + k1 * innov).reshape(b, -1)
        ud = np.where(fd_, ed, ed + k2 * innov).reshape(b, -1)
        u11 = np.where(fd_, rr, e11 - k1 * e11).reshape(b, -1)
        u12 = np.where(fd_, 0.0, e12 - k1 * e12).reshape(b, -1)
        u22 = np.where(fd_, e22, e22 - k2 * e12).reshape(b, -1)
        post = np.exp(logj - tot[:, None]).reshape(b, c_n, 3)
        out["p_filt"][:, k] = post.sum(1)
        if k > 0:  # part k - 1 odd; a step at part k - j (carried as "step j - 1 ago")
            p_odd_lag[:, k - 1] = post[:, 1].sum(1)
            for j in range(1, min(memory, k) + 1):
                p_step_lag[:, k - j] = post[:, 1 + j].sum(1) + gone[:, k - j]
                gone[:, k - j] += post[:, 1 + j, 1:].sum(1)  # merged into a new event
        # merge into the components of part k (see the module doc)
        lj = logj.reshape(b, c_n, 3)
        mom = [v.reshape(b, c_n, 3) for v in (ua, ud, u11, u12, u22)]
        lt, a, d, p11, p12, p22 = _collapse(lj, mom, c_n, memory)
        if not np.all(seen):  # not measured: the hypotheses wait for a measurement
            alt = _collapse_unseen(lj, mom, c_n)
            lt, a, d, p11, p12, p22 = (np.where(seen[:, None], x, y_)
                                       for x, y_ in zip((lt, a, d, p11, p12, p22), alt,
                                                        strict=True))  # fmt: skip
        w = np.exp(lt - tot[:, None])
        fm = np.sum(w * a, 1)
        fd = np.sum(w * d, 1)
        out["fm"][:, k] = fm
        out["fv"][:, k] = np.sum(w * (p11 + (a - fm[:, None]) ** 2), 1)
        out["fd"][:, k] = fd
        out["fdv"][:, k] = np.sum(w * (p22 + (d - fd[:, None]) ** 2), 1)
        if ahead:
            out["am"][:, k], out["av"][:, k] = _ahead(
                w, a, d, p11, p12, p22, par, fwear, declared, hazard, k, ahead
            )
    p_odd_lag[:, n - 1] = out["p_filt"][:, n - 1, 1]
    p_step_lag[:, n - 1] = out["p_filt"][:, n - 1, 2]
    p_step_lag = np.minimum(p_step_lag, 1.0 - p_odd_lag)
    out["p_lag"] = np.stack([1.0 - p_odd_lag - p_step_lag, p_odd_lag, p_step_lag], -1)
    na, _, n11, _, _ = _transition(a, d, p11, p12, p22, 1.0, phi, par)
    nm = np.sum(w * na, 1)
    out["next_m"] = nm
    out["next_v"] = np.sum(w * (n11 + (na - nm[:, None]) ** 2), 1)
    return out


def smoother(y, r, par, declared, p_odd, p_step):
    """Kalman filter and RTS smoother with the indicators' expected effects.

    The observation precision of part $k$ is its expectation over the indicator,
    $1/R_k = (1-p_{o,k})/R + p_{o,k}/(R + \\sigma_o^2)$, and the step variance
    $p_{s,k}\\sigma_s^2$ ($\\sigma_s^2$ and the wear restart at a declared change): exact
    when the probabilities are 0 or 1 (a Gaussian model, or indicators known).

    **Arguments:** `y` (NaN: not measured), `r`, `par`, `declared` as for
    [`mixture_filter`][];
    `p_odd`, `p_step`: `(B, n)` indicator probabilities.

    **Returns:** `(mean, var)` `(B, n)` of the smoothed level.
    """
    b, n = y.shape
    declared = np.broadcast_to(np.asarray(declared, dtype=bool), (b, n))
    base = r + par["scatter2"][:, None]
    reff = 1.0 / ((1.0 - p_odd) / base + p_odd / (base + par["odd2"][:, None]))
    qadd = np.where(declared, 1.0, p_step) * par["step2"][:, None]
    diffuse = ~np.isfinite(par["level0"])
    fwear = wear_factor(declared, par.get("wear_reset", np.zeros(b)))
    fa = np.zeros((b, n, 2))
    fp = np.zeros((b, n, 2, 2))
    pa = np.zeros((b, n, 2))
    pp = np.zeros((b, n, 2, 2))
    d0 = par.get("drift0_mean", np.zeros(b))
    m = np.stack([np.zeros(b), d0], 1)
    p = np.zeros((b, 2, 2))
    p[:, 0, 0] = np.where(diffuse, 0.0, par["level0"])
    p[:, 1, 1] = par["drift0"]
    tr = np.zeros((b, n, 2, 2))  # transition into part k
    tr[:, :, 0, 0] = 1.0
    tr[:, :, 1, 1] = par.get("drift_decay", np.ones(b))[:, None]
    tr[:, :, 0, 1] = fwear
    seen = np.isfinite(y)
    y = np.where(seen, y, 0.0)
    for k in range(n):
        if k > 0:
            m = np.einsum("bij,bj->bi", tr[:, k], m)
            p = tr[:, k] @ p @ np.swapaxes(tr[:, k], 1, 2)
            p[:, 0, 0] += par["q_level"] + qadd[:, k]
            p[:, 1, 1] += par["q_drift"]
        pa[:, k], pp[:, k] = m, p
        s = p[:, 0, 0] + reff[:, k]
        gain = np.where(seen[:, k : k + 1], p[:, :, 0] / s[:, None], 0.0)  # none: predict
        m = m + gain * (y[:, k] - m[:, 0])[:, None]
        p = p - gain[:, :, None] * p[:, 0, :][:, None, :]
        if k == 0:
            m = np.where(diffuse[:, None], np.stack([y[:, 0], d0], 1), m)
            p0 = np.zeros((b, 2, 2))
            p0[:, 0, 0] = reff[:, 0]
            p0[:, 1, 1] = par["drift0"]
            p = np.where(diffuse[:, None, None], p0, p)
        p = 0.5 * (p + np.swapaxes(p, 1, 2))
        fa[:, k], fp[:, k] = m, p
    sm, sp = fa[:, -1].copy(), fp[:, -1].copy()
    mean = np.zeros((b, n))
    var = np.zeros((b, n))
    mean[:, -1], var[:, -1] = sm[:, 0], sp[:, 0, 0]
    for k in range(n - 2, -1, -1):
        ppk = pp[:, k + 1]
        cross = fp[:, k] @ np.swapaxes(tr[:, k + 1], 1, 2)  # Cov(x_k, x_{k+1} | y_{0:k})
        jmat = cross @ np.linalg.pinv(ppk, hermitian=True)
        sm = fa[:, k] + np.einsum("bij,bj->bi", jmat, sm - pa[:, k + 1])
        sp = fp[:, k] + jmat @ (sp - ppk) @ np.swapaxes(jmat, 1, 2)
        mean[:, k], var[:, k] = sm[:, 0], sp[:, 0, 0]
    return mean, np.maximum(var, 0.0)
