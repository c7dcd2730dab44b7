"""The numerical core of part-to-part tracking: a collapsed mixture Kalman filter, batched.

The model and the notation are those of `_tracking` (which documents them); this module
holds the arithmetic, vectorised with NumPy over any number of independent series (runs
of parts times hyper-parameter grid points), so that 1,000 simulated runs on a grid of
hyper-parameters filter in one pass.

**State.** $x_k = (\\ell_k, d_k)$, level and drift of part $k$. Each part has an
indicator $s_k \\in \\{0, 1, 2\\}$: 0 regular, 1 odd part (observation variance
$+\\,\\sigma_o^2$), 2 undeclared step (level variance $+\\,\\sigma_s^2$). A declared tool
change adds $\\sigma_s^2$ whatever $s_k$. Prior $\\pi = (1 - p_o - p_s, p_o, p_s)$, at a
declared change $(1 - p_o, p_o, 0)$.

**Filter (GPB2).** After part $k$ the posterior is kept as three Gaussians, one per value
of $s_k$, with weights $w_{s}$. Part $k+1$ expands them into $3\\times 3$ Kalman updates
(one per pair $(s_k, s_{k+1})$), weighs each by $w_{s_k}\\,\\pi_{s_{k+1}}\\,
N(y_{k+1}; \\hat y, S)$ and merges, by moment matching, the three that share $s_{k+1}$.
The log predictive density of $y_{k+1}$ is the log of the sum of the nine weights. The
merged weights over $s_k$ are $p(s_k \\mid y_{0:k+1})$: the indicator of a part is
judged with one part of hindsight, which is what tells an odd part (the next part is
back) from a step (the next part stays).

**Diffuse start.** With `level0_sd = None` the level of part 0 is diffuse: part 0 sets
the level ($\\ell_0 \\mid y_0 \\sim N(y_0, R_0)$, $R_0$ its observation variance) and
contributes no likelihood (the diffuse likelihood of Durbin & Koopman, 2012, §5.7).
"""

from __future__ import annotations

import numpy as np

from .. import _config

special = _config.LazyModule("scipy.special")

__all__: list[str] = []

_TINY = 1e-300
_LOG2PI = float(np.log(2.0 * np.pi))


def _log_prior(p_odd, p_step, declared):
    """`(..., n, 3)` log prior of the indicators (zero probabilities floored at 1e-300)."""
    p_odd = np.asarray(p_odd)[..., None]
    p_step = np.where(declared, 0.0, np.asarray(p_step)[..., None])
    pri = np.stack(np.broadcast_arrays(1.0 - p_odd - p_step, p_odd + 0.0 * p_step, p_step), -1)
    return np.log(np.maximum(pri, _TINY))


def mixture_filter(y, r, par, declared):
    """Run the collapsed mixture filter on a batch of series.

    **Arguments:**

    - `y`: `(B, n)` observed values (mm).
    - `r`: `(B, n)` measurement variances $u_k^2$ (mm$^2$), all > 0.
    - `par`: dict of `(B,)` arrays: `scatter2`, `q_level`, `q_drift`, `drift0`,
      `step2`, `p_step`, `p_odd`, `odd2` (variances in mm$^2$) and `level0` (prior
      variance of the level of part 0, `inf` for diffuse).
    - `declared`: `(B, n)` or `(n,)` booleans, True at a declared tool change.

    **Returns:** a dict of arrays: `loglik` `(B, n)` (log predictive density of each part;
    0 for a diffuse part 0), `pw`, `pm`, `ps` `(B, n, 9)` (weights, means and sds of the
    one-step-ahead predictive mixture of $y_k$; NaN for a diffuse part 0), `pit`
    `(B, n)` (that mixture's cdf at $y_k$), `lm`, `lv`
    `(B, n)` (predictive mean and variance of the level of part $k$ given parts $< k$,
    the regular component plus a declared step; the collapsed mixture), `fm`, `fv`
    `(B, n)` (filtered level mean and variance), `fd`, `fdv` (filtered drift),
    `p_filt` `(B, n, 3)` ($p(s_k \\mid y_{0:k})$), `p_lag` `(B, n, 3)`
    ($p(s_k \\mid y_{0:k+1})$; the last part: filtered), `next_m`, `next_v` `(B,)`
    (level predictive for part n).
    """
    y = np.asarray(y, dtype=float)
    r = np.asarray(r, dtype=float)
    b, n = y.shape
    declared = np.broadcast_to(np.asarray(declared, dtype=bool), (b, n))
    scatter2 = par["scatter2"][:, None]
    q_level = par["q_level"][:, None]
    q_drift = par["q_drift"][:, None]
    step2 = par["step2"][:, None]
    odd2 = par["odd2"][:, None]
    level0 = par["level0"]
    diffuse = ~np.isfinite(level0)
    logpri = _log_prior(par["p_odd"], par["p_step"], declared)  # (B, n, 3)
    s_odd = np.array([0.0, 1.0, 0.0])
    s_step = np.array([0.0, 0.0, 1.0])

    out = {
        k: np.full((b, n), np.nan) for k in ("loglik", "lm", "lv", "fm", "fv", "fd", "fdv", "pit")
    }
    for k in ("pw", "pm", "ps"):
        out[k] = np.full((b, n, 9), np.nan)
    out["p_filt"] = np.full((b, n, 3), np.nan)
    out["p_lag"] = np.full((b, n, 3), np.nan)

    # carried components, indexed by s_{k-1}: weights (B, 3), moments (B, 3)
    w = np.tile([1.0, 0.0, 0.0], (b, 1))
    a = np.zeros((b, 3))
    d = np.zeros((b, 3))
    p11 = np.tile(np.where(diffuse, 0.0, level0)[:, None], (1, 3))
    p12 = np.zeros((b, 3))
    p22 = np.tile(par["drift0"][:, None], (1, 3))
    for k in range(n):
        qadd = np.where(declared[:, k : k + 1], 1.0, s_step[None, :]) * step2  # (B, 3) by s_k
        rk = r[:, k : k + 1] + scatter2 + s_odd[None, :] * odd2  # (B, 3) by s_k
        if k == 0:
            pa, pd, pp11, pp12, pp22 = a, d, p11, p12, p22
        else:
            pa, pd = a + d, d
            pp11 = p11 + 2.0 * p12 + p22 + q_level
            pp12, pp22 = p12 + p22, p22 + q_drift
        # level predictive for part k (before its indicator): declared step included
        dec = np.where(declared[:, k], step2[:, 0], 0.0)
        lm = np.sum(w * pa, 1)
        lv = np.sum(w * (pp11 + (pa - lm[:, None]) ** 2), 1) + dec
        first = diffuse & (k == 0)
        out["lm"][:, k] = np.where(first, np.nan, lm)
        out["lv"][:, k] = np.where(first, np.nan, lv)
        # expand: (B, j=s_{k-1}, s=s_k)
        e11 = pp11[:, :, None] + qadd[:, None, :]
        e12 = np.broadcast_to(pp12[:, :, None], e11.shape)
        e22 = np.broadcast_to(pp22[:, :, None], e11.shape)
        ea = np.broadcast_to(pa[:, :, None], e11.shape)
        ed = np.broadcast_to(pd[:, :, None], e11.shape)
        rr = np.broadcast_to(rk[:, None, :], e11.shape)
        yk = y[:, k][:, None, None]
        with np.errstate(divide="ignore"):
            logw_prev = np.log(np.maximum(w, _TINY))
        first_diffuse = diffuse & (k == 0)
        s = e11 + rr
        innov = yk - ea
        logn = -0.5 * (_LOG2PI + np.log(s) + innov**2 / s)
        logn = np.where(first_diffuse[:, None, None], 0.0, logn)
        logj = logw_prev[:, :, None] + logpri[:, k][:, None, :] + logn  # (B, 3, 3)
        if k == 0:
            logj[:, 1:, :] = np.log(_TINY) + logj[:, 1:, :]  # one prior component at part 0
        tot = special.logsumexp(logj.reshape(b, 9), axis=1)
        out["loglik"][:, k] = np.where(first_diffuse, 0.0, tot)
        # predictive mixture of y_k: prior weights, no data
        logp = logw_prev[:, :, None] + logpri[:, k][:, None, :]
        if k == 0:
            logp = logp + np.array([0.0, np.log(_TINY), np.log(_TINY)])[None, :, None]
        pw = np.exp(logp - special.logsumexp(logp.reshape(b, 9), 1)[:, None, None])
        out["pw"][:, k] = pw.reshape(b, 9)
        out["pm"][:, k] = np.where(first_diffuse[:, None], np.nan, ea.reshape(b, 9))
        out["ps"][:, k] = np.where(first_diffuse[:, None], np.nan, np.sqrt(s).reshape(b, 9))
        pit = np.sum(pw * special.ndtr(innov / np.sqrt(s)), axis=(1, 2))
        out["pit"][:, k] = np.where(first_diffuse, np.nan, pit)
        # update every pair
        k1, k2 = e11 / s, e12 / s
        ua = np.where(first_diffuse[:, None, None], yk, ea + k1 * innov)
        ud = np.where(first_diffuse[:, None, None], ed, ed + k2 * innov)
        u11 = np.where(first_diffuse[:, None, None], rr, e11 * rr / s)
        u12 = np.where(first_diffuse[:, None, None], 0.0, e12 * rr / s)
        u22 = np.where(first_diffuse[:, None, None], e22, e22 - e12 * e12 / s)
        post = np.exp(logj - tot[:, None, None])  # (B, j, s)
        ws = post.sum(1)  # (B, s)
        out["p_filt"][:, k] = ws
        if k > 0:
            out["p_lag"][:, k - 1] = post.sum(2)
        # merge over j for each s (within-group weights from logs: no 0/0)
        g = np.exp(logj - special.logsumexp(logj, axis=1)[:, None, :])  # (B, j, s)
        a = np.sum(g * ua, 1)
        d = np.sum(g * ud, 1)
        da, dd = ua - a[:, None, :], ud - d[:, None, :]
        p11 = np.sum(g * (u11 + da * da), 1)
        p12 = np.sum(g * (u12 + da * dd), 1)
        p22 = np.sum(g * (u22 + dd * dd), 1)
        w = ws
        fm = np.sum(w * a, 1)
        fd = np.sum(w * d, 1)
        out["fm"][:, k] = fm
        out["fv"][:, k] = np.sum(w * (p11 + (a - fm[:, None]) ** 2), 1)
        out["fd"][:, k] = fd
        out["fdv"][:, k] = np.sum(w * (p22 + (d - fd[:, None]) ** 2), 1)
    out["p_lag"][:, n - 1] = out["p_filt"][:, n - 1]
    na = a + d
    nm = np.sum(w * na, 1)
    n11 = p11 + 2.0 * p12 + p22 + q_level
    out["next_m"] = nm
    out["next_v"] = np.sum(w * (n11 + (na - nm[:, None]) ** 2), 1)
    return out


def smoother(y, r, par, declared, p_odd, p_step):
    """Kalman filter and RTS smoother with the indicators' expected effects.

    The observation precision of part $k$ is its expectation over the indicator,
    $1/R_k = (1-p_{o,k})/R + p_{o,k}/(R + \\sigma_o^2)$, and the step variance
    $p_{s,k}\\sigma_s^2$ ($\\sigma_s^2$ at a declared change): exact when the
    probabilities are 0 or 1 (a Gaussian model, or indicators known).

    **Arguments:** `y`, `r`, `par`, `declared` as for [`mixture_filter`][];
    `p_odd`, `p_step`: `(B, n)` indicator probabilities.

    **Returns:** `(mean, var)` `(B, n)` of the smoothed level.
    """
    b, n = y.shape
    declared = np.broadcast_to(np.asarray(declared, dtype=bool), (b, n))
    base = r + par["scatter2"][:, None]
    reff = 1.0 / ((1.0 - p_odd) / base + p_odd / (base + par["odd2"][:, None]))
    qadd = np.where(declared, 1.0, p_step) * par["step2"][:, None]
    diffuse = ~np.isfinite(par["level0"])
    fa = np.zeros((b, n, 2))
    fp = np.zeros((b, n, 2, 2))
    pa = np.zeros((b, n, 2))
    pp = np.zeros((b, n, 2, 2))
    m = np.zeros((b, 2))
    p = np.zeros((b, 2, 2))
    p[:, 0, 0] = np.where(diffuse, 0.0, par["level0"])
    p[:, 1, 1] = par["drift0"]
    tr = np.array([[1.0, 1.0], [0.0, 1.0]])
    for k in range(n):
        if k > 0:
            m = m @ tr.T
            p = tr @ p @ tr.T
            p[:, 0, 0] += par["q_level"] + qadd[:, k]
            p[:, 1, 1] += par["q_drift"]
        pa[:, k], pp[:, k] = m, p
        s = p[:, 0, 0] + reff[:, k]
        gain = p[:, :, 0] / s[:, None]
        m = m + gain * (y[:, k] - m[:, 0])[:, None]
        p = p - gain[:, :, None] * p[:, 0, :][:, None, :]
        if k == 0:
            m = np.where(diffuse[:, None], np.stack([y[:, 0], np.zeros(b)], 1), m)
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
        cross = fp[:, k] @ tr.T  # Cov(x_k, x_{k+1} | y_{0:k})
        jmat = cross @ np.linalg.pinv(ppk, hermitian=True)
        sm = fa[:, k] + np.einsum("bij,bj->bi", jmat, sm - pa[:, k + 1])
        sp = fp[:, k] + jmat @ (sp - ppk) @ np.swapaxes(jmat, 1, 2)
        mean[:, k], var[:, k] = sm[:, 0], sp[:, 0, 0]
    return mean, np.maximum(var, 0.0)
