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


def mixture_quantile(p, w, m, s):
    """Quantile `p` of Gaussian mixtures `(..., C)` (NaN rows stay NaN): Newton's
    method kept inside a bisection bracket (a step that leaves the bracket, or a
    density of zero, bisects), from the moment-matched normal's quantile, until every
    step is below `QUANTILE_TOL` (at most 100 steps). A row that has converged leaves
    the iteration (each row has the iterates it would have alone)."""
    w, m, s = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (w, m, s)))
    shape = m.shape[:-1]
    w, m, s = (v.reshape(-1, v.shape[-1]) for v in (w, m, s))
    bad = np.isnan(m[:, 0])
    x = np.full(bad.shape, np.nan)
    act = np.flatnonzero(~bad)  # the rows still iterating
    w, m, s = w[act], m[act], s[act]
    tot = np.sum(w, -1)
    tot = np.where(tot > 0, tot, 1.0)
    w = w / tot[:, None]
    lo = np.min(m - 12 * s, -1)
    hi = np.max(m + 12 * s, -1)
    mean = np.sum(w * m, -1)
    sd = np.sqrt(np.sum(w * (s**2 + (m - mean[:, None]) ** 2), -1))
    xa = np.clip(mean + sd * special.ndtri(p), lo, hi)
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
        done = np.abs(nxt - xa) <= QUANTILE_TOL
        x[act[done]] = nxt[done]
        keep = ~done
        if not keep.any():
            break
        act, xa, lo, hi = act[keep], nxt[keep], lo[keep], hi[keep]
        w, m, s = w[keep], m[keep], s[keep]
    else:
        x[act] = xa  # at the step limit: the last iterate
    return x.reshape(shape)
