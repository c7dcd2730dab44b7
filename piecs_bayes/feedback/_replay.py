"""The closed loop of a production run as a shop runs it: sampled inspection, late
results, a correction that acts with an unknown gain.

`_policies` states the counterfactual (`deviation[k]`: part $k$ as cut without any
correction). Here the loop is run part by part with three facts of the shop floor:
only every `inspect_every`-th part is measured (every part's deviation counts), the
result of a part arrives `delay` parts late, and a correction $c$ moves the part by
`gain` times $c$ (the policies assume 1). A policy decides when a result arrives and
holds its correction until the next; `bayes` treats a part not measured as a prediction
step of the filter. `anchor_loop` and `bayes_loop` run the loop; [`expand_sampled`][]
places the measured parts' values in production order (NaN between). With
`inspect_every=1`, `delay=0`, `gain=1` this is the plain replay exactly (a test).

The loop: docs/feedback.md, "The loop as shops run it".
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .. import _config
from ..decide import DecisionSettings, corrections
from ..errors import InputError
from ._controllers import (
    CONTROLLERS,
    controller_alarms,
    heidenhain_step,
    renishaw_step,
    siemens_step,
)
from ._filter import mixture_filter
from ._mixture import logsumexp
from ._tracking import GRID_LOG_PRIOR, HYPER_GRID, grid_weights, model_params

special = _config.LazyModule("scipy.special")


_CHUNK = 64  # runs filtered at once on the whole grid
_NO_LIMIT = 1e3  # mm: the decision's own limit, applied by the loop instead (`held`)
ANCHORS = ("none", "full", "fixed_gain", "mean_value", "ewma", "dewma") + CONTROLLERS


def loop_settings(ds: DecisionSettings, tolerance) -> tuple[DecisionSettings, float]:
    """The decision's settings in the loop (its own limit off) and the limit on one
    adjustment (`max_correction`, default the tolerance width)."""
    limit = tolerance[1] - tolerance[0] if ds.max_correction is None else ds.max_correction
    return replace(ds, max_correction=_NO_LIMIT), float(limit)


def held(c_prev, adjustment, limit):
    """True where an adjustment is larger than `limit` and does not bring the total
    correction closer to zero (withheld: investigate first)."""
    c_prev = np.asarray(c_prev)
    return (np.abs(adjustment) > limit) & (np.abs(c_prev + adjustment) >= np.abs(c_prev))


def schedule(n: int, inspect_every: int, delay: int) -> tuple[np.ndarray, np.ndarray]:
    """`(inspected, source)`: `(n,)` True for a measured part; `(n,)` the part whose
    result arrives before part k is cut (-1: none), $k - 1 - D$ when measured."""
    if isinstance(inspect_every, bool) or not isinstance(inspect_every, int | np.integer):
        raise InputError(f"inspect_every must be an integer >= 1, got {inspect_every!r}")
    if isinstance(delay, bool) or not isinstance(delay, int | np.integer):
        raise InputError(f"delay must be an integer >= 0, got {delay!r}")
    if inspect_every < 1 or delay < 0:
        raise InputError(f"inspect_every >= 1 and delay >= 0, got {inspect_every}, {delay}")
    k = np.arange(n)
    inspected = k % int(inspect_every) == 0
    j = k - 1 - int(delay)
    source = np.where((j >= 0) & inspected[np.maximum(j, 0)], j, -1)
    return inspected, source


def expand_sampled(values, inspect_every: int, extra: int = 0) -> np.ndarray:
    """The values of every `inspect_every`-th part (parts 0, E, 2E, ...) in production
    order: NaN at the parts between, and `extra` NaN parts after the last."""
    v = np.asarray(values, dtype=float)
    e = int(inspect_every)
    out = np.full((v.size - 1) * e + 1 + int(extra), np.nan)
    out[: (v.size - 1) * e + 1 : e] = v
    return out


def _gain(gain, r_) -> np.ndarray:
    g = np.broadcast_to(np.asarray(gain, dtype=float), (r_,)).copy()
    if not np.all(np.isfinite(g)):
        raise InputError(f"gain must be finite, got {gain!r}")
    return g


def anchor_loop(dev, policy, st, half, declared, inspected, source, gain, mid=0.0):
    """Corrections `(R, n)` and flags `(R,)` of an anchor policy in the loop (`half`,
    `mid`: the tolerance's half-width and middle; the controllers' alarms as flags)."""
    r_, n = dev.shape
    g = _gain(gain, r_)
    c = np.zeros((r_, n))
    flags = np.zeros(r_, dtype=int)
    if policy not in ANCHORS:
        raise InputError(f"unknown policy {policy!r}; expected one of {ANCHORS + ('bayes',)}")
    if policy == "none":
        return c, flags
    a = np.zeros(r_)
    dd = np.zeros(r_)
    state = np.zeros(r_)  # siemens: the mean M; heidenhain: the tool locked
    window: list[np.ndarray] = []
    last = -1
    for k in range(1, n):
        j = int(source[k])
        if j < 0:
            c[:, k] = c[:, k - 1]
            continue
        real = dev[:, j] + g * c[:, j]
        e = real - c[:, j]  # the uncompensated estimate the policy can form
        reset = last < 0 or bool(np.any(declared[last + 1 : j + 1]))
        last = j
        if policy == "full":
            c[:, k] = -e
        elif policy == "fixed_gain":
            band, limit = st["null_band"] * half, st["upper_limit"] * half
            act = (np.abs(real) >= band) & ~(np.abs(real) > limit)
            c[:, k] = c[:, k - 1] - np.where(act, st["gain"] * real, 0.0)
        elif policy == "mean_value":
            window = [e] if reset else (window + [e])[-int(st["k"]) :]
            c[:, k] = -np.mean(window, axis=0)
        elif policy in CONTROLLERS:
            if reset:  # a new tool: the rule starts again (the mean cleared, unlocked)
                state = np.zeros(r_)
            if policy == "siemens":
                state, adj = siemens_step(state, real - mid, st, half)
            elif policy == "renishaw":
                adj = renishaw_step(real, st)
            else:
                locked, adj = heidenhain_step(state.astype(bool), real, st)
                state = locked.astype(float)
            c[:, k] = c[:, k - 1] + adj
        elif policy == "ewma":
            a = e if reset else st["lam"] * e + (1.0 - st["lam"]) * a
            c[:, k] = -a
        else:  # dewma
            if reset:
                a, dd = e, np.zeros(r_)
            else:
                a, dd = (
                    st["lam1"] * e + (1.0 - st["lam1"]) * a,
                    st["lam2"] * (e - a) + (1.0 - st["lam2"]) * dd,
                )
            c[:, k] = -(a + dd)
    if policy == "fixed_gain":  # every measured part beyond the upper limit
        real = dev + g[:, None] * c
        flags = np.sum((np.abs(real) > st["upper_limit"] * half) & inspected, axis=1)
    elif policy in CONTROLLERS:
        flags = controller_alarms(policy, st, dev + g[:, None] * c, inspected, half, mid)
    return c, flags


def bayes_loop(dev, u, declared, tolerance, ds, model, transfer, inspected, source, gain):
    """Corrections `(R, n)` of the `bayes` policy in the loop and the PIT `(R, n)` of
    the filter's one-step-ahead predictive of each measured part (NaN elsewhere)."""
    cs, pits = [], []
    for i in range(0, dev.shape[0], _CHUNK):
        sl = slice(i, i + _CHUNK)
        c, pit = _bayes_chunk(dev[sl], u[sl], declared, tolerance, ds, model, transfer,
                              inspected, source, _gain(gain, dev.shape[0])[sl])  # fmt: skip
        cs.append(c)
        pits.append(pit)
    return np.concatenate(cs), np.concatenate(pits)


def window(am, av, w):
    """The level over the parts a correction is held for, `(R,)` each: the mean of the
    grid-averaged predictive means, the mean of their variances and the spread of the
    means about their mean (`am`, `av` `(R, G, E)`; `w` `(R, G, 1)` grid weights)."""
    m_i = np.sum(w * am, 1)
    v_i = np.sum(w * (av + (am - m_i[:, None, :]) ** 2), 1)
    m = np.mean(m_i, 1)
    return m, np.mean(v_i, 1), np.mean((m_i - m[:, None]) ** 2, 1)


def _bayes_chunk(dev, u, declared, tolerance, ds, model, transfer, inspected, source, g):
    r_, n = dev.shape
    models = HYPER_GRID if model is None else (model,)
    ng = len(models)
    log_prior = GRID_LOG_PRIOR if model is None else np.zeros(1)
    par = model_params(models, r_)
    scat2 = par["scatter2"].reshape(r_, ng)
    beta, u_beta = transfer
    ds, limit = loop_settings(ds, tolerance)
    hold = np.diff(np.append(np.flatnonzero(source >= 0), n))  # parts each arrival holds
    holds = dict(zip(np.flatnonzero(source >= 0).tolist(), hold.tolist(), strict=True))
    dly = int(max([k - 1 - s for k, s in enumerate(source) if s >= 0], default=0))
    horizon = dly + max(holds.values(), default=1)
    c = np.zeros((r_, n))
    cum = np.zeros((r_, ng, n + 1))  # log evidence of parts < k

    def feed(k, out):
        if k > 0:
            cum[:, :, k] = cum[:, :, k - 1] + out["loglik"][:, k - 1].reshape(r_, ng)
            j = int(source[k])
            c[:, k] = c[:, k - 1]
            if j >= 0:
                c[:, k] += _decide(out, cum[:, :, j + 1], j, k - 1 - j, holds[k], c[:, k - 1])
        real = dev[:, k] + g * c[:, k]
        y = real - c[:, k] if inspected[k] else np.full(r_, np.nan)
        return np.repeat(y, ng)

    def _decide(out, cum_j, j, d, e, c_prev):
        lw = cum_j + log_prior[None, :]
        w = np.exp(lw - logsumexp(lw, axis=1, keepdims=True))[:, :, None]
        m, v, spread = window(out["am"][:, j, d : d + e].reshape(r_, ng, e),
                              out["av"][:, j, d : d + e].reshape(r_, ng, e), w)  # fmt: skip
        sd = np.sqrt(beta**2 * v + u_beta**2 * m**2)
        sc2 = (np.sum(w[:, :, 0] * scat2, 1) + spread) * beta**2
        p_sd = np.maximum(ds.process_sd, np.sqrt(sc2))
        adj = corrections(beta * m + c_prev, sd, p_sd, tolerance, ds)
        return np.where(held(c_prev, adj, limit), 0.0, adj)

    out = mixture_filter(
        np.zeros((r_ * ng, n)), np.repeat(u**2, ng, axis=0), par,
        np.repeat(np.broadcast_to(np.atleast_2d(declared), (r_, n)), ng, axis=0),
        ahead=horizon, feed=feed, mixture=False, hazard=inspected,
    )  # fmt: skip
    loglik = out["loglik"].reshape(r_, ng, n)
    wts = grid_weights(loglik, log_prior)
    pit = np.sum(wts[:, :, :-1] * out["pit"].reshape(r_, ng, n), 1)
    return c, np.where(inspected[None, :], pit, np.nan)
