"""Gaussian mixtures of the tracker's predictive: distribution function and quantiles.

The grid-averaged one-step-ahead predictive of a part (`_tracking.track`) is a mixture
of normals, one per model and switching component; its 95 % interval is the mixture's
2.5 % and 97.5 % quantiles, found here to `QUANTILE_TOL`.
"""

from __future__ import annotations

import math

import numpy as np

from .. import _config

special = _config.LazyModule("scipy.special")


def logsumexp(a, axis=None, keepdims=False):
    """`scipy.special.logsumexp(a, axis, keepdims=keepdims)` of a real array, computed
    as it computes it (the largest terms apart, `log1p` of the rest: the same
    numbers), without its array-API dispatch: ~0.5 ms a call, 2 s of the 4,000 in
    a feedback study. A result that is not finite (a row of -inf, an inf, a NaN) is
    `log(sum(exp(a)))`, as there."""
    a = np.asarray(a, dtype=float)
    a_max = np.max(a, axis=axis, keepdims=True)
    top = a == a_max
    m = np.sum(top, axis=axis, keepdims=True, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        s = np.sum(np.exp(np.where(top, -np.inf, a) - a_max), axis=axis, keepdims=True)
        s = np.where(s == 0, s, s / m)
        out = np.log1p(s) + np.log(m) + a_max
        bad = ~np.isfinite(out)
        if bad.any():
            out = np.where(bad, np.log(np.sum(np.exp(a), axis=axis, keepdims=True)), out)
    if not keepdims:
        out = np.squeeze(out, axis=axis)
    return out[()] if out.ndim == 0 else out


def mixture_cdf(x, w, m, s):
    """The distribution function at `x` of Gaussian mixtures `(..., C)` of weights `w`,
    means `m` and sds `s` (NaN rows give NaN)."""
    with np.errstate(invalid="ignore"):
        c = np.sum(w * special.ndtr((np.asarray(x)[..., None] - m) / s), -1)
    return np.where(np.isnan(m[..., 0]), np.nan, c)


QUANTILE_TOL = 1e-13  # mm: the quantile's final step
#: a mixture of more than 4x this many components first finds the quantile of its
#: heaviest `COARSE_COMPONENTS` (to `COARSE_TOL`) and starts there: the grid's
#: predictive (13,824 components) then takes 6 steps of the whole mixture, not 12
COARSE_COMPONENTS = 256
COARSE_TOL = 1e-9  # mm


def mixture_quantile(p, w, m, s):
    """Quantile `p` of Gaussian mixtures `(..., C)` (NaN rows stay NaN): Newton's
    method kept inside a bisection bracket (a step that leaves the bracket, or a
    density of zero, bisects), until every step is below `QUANTILE_TOL` (at most 100
    steps). It starts from the quantile of the mixture's `COARSE_COMPONENTS` heaviest
    components (the same iteration, from the moment-matched normal's quantile) when
    it has many more. A row that has converged leaves the iteration (each row has
    the iterates it would have alone)."""
    w, m, s = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (w, m, s)))
    shape = m.shape[:-1]
    w, m, s = (v.reshape(-1, v.shape[-1]) for v in (w, m, s))
    bad = np.isnan(m[:, 0])
    x = np.full(bad.shape, np.nan)
    act = np.flatnonzero(~bad)
    w, m, s = w[act], m[act], s[act]
    tot = np.sum(w, -1)
    tot = np.where(tot > 0, tot, 1.0)
    w = w / tot[:, None]
    lo = np.min(m - 12 * s, -1)
    hi = np.max(m + 12 * s, -1)
    mean = np.sum(w * m, -1)
    sd = np.sqrt(np.sum(w * (s**2 + (m - mean[:, None]) ** 2), -1))
    start = np.clip(mean + sd * special.ndtri(p), lo, hi)
    k = COARSE_COMPONENTS
    if w.shape[1] > 4 * k:
        top = np.argpartition(-w, k, axis=1)[:, :k]
        wt, mt, st = (np.take_along_axis(v, top, 1) for v in (w, m, s))
        with np.errstate(invalid="ignore"):
            wt = wt / np.sum(wt, -1, keepdims=True)
        coarse = _bracketed_newton(p, wt, mt, st, start, lo, hi, COARSE_TOL)
        start = np.where(np.isfinite(coarse), np.clip(coarse, lo, hi), start)
    x[act] = _bracketed_newton(p, w, m, s, start, lo, hi, QUANTILE_TOL)
    return x.reshape(shape)


def _bracketed_newton(p, w, m, s, xa, lo, hi, tol):
    """`mixture_quantile`'s iteration on rows of normalised mixtures `(R, C)` from
    `xa`, inside the brackets `[lo, hi]`, until each row's step is below `tol`."""
    x = np.full(xa.shape, np.nan)
    act = np.arange(xa.shape[0])  # the rows still iterating
    norm = 1.0 / math.sqrt(2 * math.pi)
    for _ in range(100):
        z = (xa[:, None] - m) / s
        f = np.sum(w * special.ndtr(z), -1) - p
        dens = np.sum(w * np.exp(-0.5 * z * z) / s, -1) * norm
        lo, hi = np.where(f < 0, xa, lo), np.where(f < 0, hi, xa)
        with np.errstate(divide="ignore", invalid="ignore"):
            nxt = xa - f / dens
        inside = np.isfinite(nxt) & (nxt >= lo) & (nxt <= hi)
        nxt = np.where(inside, nxt, 0.5 * (lo + hi))
        done = np.abs(nxt - xa) <= tol
        x[act[done]] = nxt[done]
        keep = ~done
        if not keep.any():
            break
        act, xa, lo, hi = act[keep], nxt[keep], lo[keep], hi[keep]
        w, m, s = w[keep], m[keep], s[keep]
    else:
        x[act] = xa  # at the step limit: the last iterate
    return x
