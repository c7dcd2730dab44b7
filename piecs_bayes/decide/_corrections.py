"""The one-part decision's correction, vectorised: `decide(...).correction` for many parts.

A replay of the `bayes` feedback policy asks the one-part decision tens of thousands of
times; `decide` builds a full [`Decision`][] each time. For a normal posterior
(`samples` and `dof` not used) and no `n_points`, its correction is a short chain of
closed forms, which [`corrections`][] computes for arrays of `mean`, `sd` and
`process_sd` (mm) with the same rules as `decide` (`_actions._evaluate`,
`_verdict.conclude`): the Bayes correction, none when adjusting does not lower the
loss, and 0 unless the verdict would be "compensate". It returns the corrections (mm)
shaped like the broadcast inputs. `tests/compensate/test_feedback.py` checks it against `decide`
on random cases.

The closed forms: docs/models/decision.md, "Many parts at once".
"""

from __future__ import annotations

import math

import numpy as np

from .. import _config
from ._actions import p_out
from ._decision import feature_scales
from ._settings import DecisionSettings

special = _config.LazyModule("scipy.special")


_GOLD = 0.5 * (math.sqrt(5.0) - 1.0)


def _f(x, tau, lo, hi, k, c_out):
    """$k x^2 + C_\\text{out}P_\\text{out}(x)$ (the $x$-dependent part of the loss)."""
    return k * x * x + c_out * p_out(x, tau, lo, hi)


def corrections(mean, sd, process_sd, tolerance, st: DecisionSettings) -> np.ndarray:
    """`decide(tolerance=..., mean=m, sd=s, settings=replace(st, process_sd=p)).correction`
    for arrays of `m`, `s`, `p` (broadcast; mm).

    **Arguments:**

    - `mean`, `sd`: the deviation's posterior mean and sd (mm), `sd` > 0.
    - `process_sd`: the part-to-part scatter per element (replaces `st.process_sd`).
    - `tolerance`: `(lower, upper)` (mm).
    - `st`: the decision settings (all but `process_sd` used as given).

    **Returns:** the corrections (mm), shaped like the broadcast inputs.
    """
    m0, s0, sp = np.broadcast_arrays(
        np.asarray(mean, dtype=float), np.asarray(sd, dtype=float),
        np.asarray(process_sd, dtype=float),
    )  # fmt: skip
    lo, hi = (float(t) for t in tolerance)
    width = hi - lo
    band, k, max_corr = feature_scales(st, width)
    if st.prior_sd is None:
        m, s = m0, s0
    else:
        w = st.prior_sd**2 / (st.prior_sd**2 + s0**2)
        m, s = m0 * w, s0 * np.sqrt(w)
    n = st.parts_per_decision
    sa2 = st.adjustment_sd**2
    tau_adj = np.sqrt(s**2 + sa2 + sp**2)
    tau_0 = np.sqrt(s**2 + sp**2)
    c_out = st.out_of_tolerance_cost
    # x* on the grid, then golden-section search in its bracket
    span = np.maximum(np.maximum(width, 6.0 * s), 1e-9)
    t = np.linspace(-1.0, 1.0, 401)
    grid = span[..., None] * t
    fg = _f(grid, tau_adj[..., None], lo, hi, k, c_out)
    j = np.argmin(fg, axis=-1)
    xj = np.take_along_axis(grid, j[..., None], -1)[..., 0]
    fj = np.take_along_axis(fg, j[..., None], -1)[..., 0]
    a = np.take_along_axis(grid, np.maximum(j - 1, 0)[..., None], -1)[..., 0]
    b = np.take_along_axis(grid, np.minimum(j + 1, 400)[..., None], -1)[..., 0]
    x1, x2 = b - _GOLD * (b - a), a + _GOLD * (b - a)
    f1, f2 = _f(x1, tau_adj, lo, hi, k, c_out), _f(x2, tau_adj, lo, hi, k, c_out)
    for _ in range(80):
        left = f1 < f2
        b = np.where(left, x2, b)
        a = np.where(left, a, x1)
        x1n, x2n = b - _GOLD * (b - a), a + _GOLD * (b - a)
        x1, x2 = np.where(left, x1n, x2), np.where(left, x1, x2n)
        f1, f2 = (
            np.where(left, _f(x1n, tau_adj, lo, hi, k, c_out), f2),
            np.where(left, f1, _f(x2n, tau_adj, lo, hi, k, c_out)),
        )
    xs = 0.5 * (a + b)
    fs = _f(xs, tau_adj, lo, hi, k, c_out)
    xs = np.where(fs <= fj, xs, xj)
    c_b = xs - m
    # grid values are in c-space in decide (-m + grid): the same points
    common = n * k * (s**2 + sp**2)
    loss_b = n * _f(xs, tau_adj, lo, hi, k, c_out) + common + n * k * sa2 + st.adjustment_cost
    loss_0 = n * _f(m, tau_0, lo, hi, k, c_out) + common
    c_b = np.where(loss_b >= loss_0, 0.0, c_b)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where((c_b != 0.0) & (m0 != 0.0), -c_b / m0, 0.0)
    clip = (g < 0.0) | (g > 1.0)
    c_b = np.where(clip, -np.clip(g, 0.0, 1.0) * m0, c_b)
    # significance, justification, block, conformance after
    p_ex = np.where(
        s > 0,
        special.ndtr((-band - m) / np.where(s > 0, s, 1.0))
        + special.ndtr((m - band) / np.where(s > 0, s, 1.0)),
        (np.abs(m) > band).astype(float),
    )
    require = st.require_significance
    if require is None:
        require = st.prior_sd is None
    justified = (c_b != 0.0) & ((p_ex >= st.p_significant) | (not require))
    blocked = np.abs(c_b) > max_corr
    s_after = np.sqrt(s**2 + np.where(c_b != 0.0, sa2, 0.0))
    guard = st.guard_band_factor * st.coverage_factor * s_after
    value = m + c_b
    conforms = (lo + guard <= value) & (value <= hi - guard)
    return np.where(justified & ~blocked & conforms, c_b, 0.0)
