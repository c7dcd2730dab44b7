"""Feedback over a production run: the policies and the counterfactual replay.

**Counterfactual.** `deviation[k]` is the measured deviation of part $k$ as it would
have been cut without any feedback correction (mm, normal deviation, + = material
left). A policy sets the correction $c_k$ of part $k$ from what it has seen of the
parts before ($k' < k$) only; the correction adds to the part:
$r_k = \\delta_k + c_k$ is the realised deviation, and $r_k$ (its measurement) is all
the policy sees of part $k$. Part 0 is cut with $c_0 = 0$. The replay assumes that a
correction acts one-for-one and at once, and that it does not change the part's
scatter (true for a wear-offset or a path correction of the finish cut).

**Policies** (`POLICIES`):

- `none`: $c_k = 0$.
- `full`: PIECS mirroring of the last part, $c_{k+1} = c_k - r_k$.
- `fixed_gain` (Renishaw Inspection Plus style): feedback percentage $g$, null band
  $b$, upper limit $L$: $c_{k+1} = c_k - g\\,r_k$ when $b \\le |r_k| \\le L$; inside
  the null band nothing changes; beyond the upper limit nothing changes and the part
  is flagged (`flags`). $b$ and $L$ are given as fractions of the tolerance half-width.
- `mean_value` (Siemens measuring cycles): $c_{k+1} = -\\frac1K\\sum_{i=k-K+1}^{k}
  (r_i - c_i)$, the mean of the last $K$ uncompensated estimates.
- `ewma` (Ingolfsson & Sachs 1993): $a_k = \\lambda(r_k - c_k) + (1-\\lambda)a_{k-1}$,
  $a_0 = r_0 - c_0$, $c_{k+1} = -a_k$.
- `dewma` (double EWMA, Butler & Stefani 1994): $a_k = \\lambda_1 e_k +
  (1-\\lambda_1)a_{k-1}$, $D_k = \\lambda_2(e_k - a_{k-1}) + (1-\\lambda_2)D_{k-1}$ with
  $e_k = r_k - c_k$, $a_0 = e_0$, $D_0 = 0$; $c_{k+1} = -(a_k + D_k)$ (a drift $d$ per
  part is followed without lag).
- `bayes`: the tracking model (`_tracking`, hyper-parameters averaged over its grid
  with weights from the parts before $k$ only) predicts the level of part $k$,
  $N(m_k, v_k)$; the one-part decision (`decide`) is handed the deviation part $k$
  would have with the current correction, `mean` $= \\beta m_k + c_{k-1}$,
  `sd` $= \\sqrt{\\beta^2 v_k}$, with `process_sd` at least the model's scatter; its
  `correction` is the adjustment, $c_k = c_{k-1} + $ correction. With one part and no
  process noise this is the one-part decision itself. The decision's `max_correction`
  (default: the tolerance width; "investigate first") withholds an adjustment larger
  than it, unless the adjustment brings the total correction closer to zero: undoing
  a correction is never blocked (else a large correction, e.g. after two odd parts
  taken for a step, would be locked in: undoing it is an adjustment as large).

The memory of `mean_value`, `ewma` and `dewma` restarts at a declared tool change
(as a controller's cycle is reset with a new tool); `bayes` knows the change as a
level step of unknown size and that the new edge starts unworn (the wear accumulated
since the previous change goes with the old edge: `TrackModel.wear_reset`).

**Tuning.** The anchors are tuned fairly: `tune` replays every setting of
`TUNING_GRIDS[policy]` on the same data and keeps the lowest RMS deviation (a
hindsight advantage `bayes` does not get: its settings are fixed).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ._decision import decide
from ._settings import DecisionSettings
from ._tracking import (
    GRID_LOG_PRIOR,
    HYPER_GRID,
    Track,
    TrackModel,
    _checked,
    _transfer,
    grid_weights,
    level_average,
    run_grid,
    track,
)
from ._tracking_decide import corrections

__all__ = [
    "BAYES_DECISION",
    "POLICIES",
    "TUNING_GRIDS",
    "PolicyResult",
    "next_part",
    "predictive_coverage",
    "replay",
    "replay_runs",
    "tune",
]

POLICIES = ("none", "full", "fixed_gain", "mean_value", "ewma", "dewma", "bayes")

BAYES_DECISION = DecisionSettings(
    adjustment_cost=0.0, require_significance=False, guard_band_factor=0.0
)
"""Decision settings of the `bayes` policy unless given: an automatic offset change
costs nothing, the expected loss alone decides (no significance demand: the
predictive already weighs the noise), conformance without a guard band."""

TUNING_GRIDS: dict[str, list[dict]] = {
    "none": [{}],
    "full": [{}],
    "fixed_gain": [
        {"gain": g, "null_band": b, "upper_limit": u}
        for g, b, u in itertools.product(
            (0.1, 0.2, 0.3, 0.5, 0.75, 1.0), (0.0, 0.1, 0.2, 0.3), (1.0, 2.0, math.inf)
        )
    ],
    "mean_value": [{"k": k} for k in (1, 2, 3, 5, 8, 12, 20)],
    "ewma": [{"lam": lam} for lam in (0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.7, 1.0)],
    "dewma": [
        {"lam1": a, "lam2": b}
        for a, b in itertools.product((0.1, 0.2, 0.3, 0.5, 0.7), (0.02, 0.05, 0.1, 0.2, 0.3))
    ],
    "bayes": [{}],
}
"""Settings tried by `tune` per policy: `fixed_gain` gain $g$, null band and upper limit
as fractions of the tolerance half-width; `mean_value` window $K$ (parts); `ewma`
weight $\\lambda$; `dewma` level and drift weights $\\lambda_1, \\lambda_2$."""


@dataclass(frozen=True)
class PolicyResult:
    """One policy replayed over a run (see the module doc).

    - `name`, `settings`: the policy and its settings (`fixed_gain`'s bands also in mm).
    - `corrections`, `realised`: `(n,)` $c_k$ and $r_k = \\delta_k + c_k$ (mm).
    - `rmsd_mm`, `max_abs_mm`: RMS and largest $|r_k|$.
    - `out_of_tolerance`: parts with $r_k$ outside the tolerance.
    - `adjustments`: parts whose correction differs from the previous part's.
    - `flags`: parts beyond `fixed_gain`'s upper limit (0 for the others).
    """

    name: str
    settings: dict
    corrections: np.ndarray
    realised: np.ndarray
    rmsd_mm: float
    max_abs_mm: float
    out_of_tolerance: int
    adjustments: int
    flags: int = 0

    def as_row(self) -> dict:
        """`{name, settings, rmsd_mm, max_abs_mm, out_of_tolerance, adjustments, flags}`."""
        return {
            "name": self.name,
            "settings": dict(self.settings),
            "rmsd_mm": self.rmsd_mm,
            "max_abs_mm": self.max_abs_mm,
            "out_of_tolerance": self.out_of_tolerance,
            "adjustments": self.adjustments,
            "flags": self.flags,
        }

    def __repr__(self) -> str:
        return (
            f"PolicyResult({self.name} {self.settings}: RMS {self.rmsd_mm * 1e3:.2f} µm, "
            f"max {self.max_abs_mm * 1e3:.2f} µm, {self.out_of_tolerance} out of tolerance, "
            f"{self.adjustments} adjustments)"
        )


# --------------------------------------------------------------------------- anchors


def _anchor(dev, policy, st, half, declared):
    """Corrections `(R, n)` and flags `(R,)` of an anchor policy on runs `dev` `(R, n)`."""
    r_, n = dev.shape
    c = np.zeros((r_, n))
    flags = np.zeros(r_, dtype=int)
    if policy == "none":
        return c, flags
    a = np.zeros(r_)
    dd = np.zeros(r_)
    window: list[np.ndarray] = []
    for k in range(n - 1):
        real = dev[:, k] + c[:, k]
        e = dev[:, k]  # = real - c: the uncompensated estimate the policy can form
        reset = k == 0 or declared[k]
        if policy == "full":
            c[:, k + 1] = c[:, k] - real
        elif policy == "fixed_gain":
            band, limit = st["null_band"] * half, st["upper_limit"] * half
            big = np.abs(real) > limit
            act = (np.abs(real) >= band) & ~big
            c[:, k + 1] = c[:, k] - np.where(act, st["gain"] * real, 0.0)
        elif policy == "mean_value":
            window = [e] if reset else (window + [e])[-int(st["k"]) :]
            c[:, k + 1] = -np.mean(window, axis=0)
        elif policy == "ewma":
            a = e if reset else st["lam"] * e + (1.0 - st["lam"]) * a
            c[:, k + 1] = -a
        elif policy == "dewma":
            if reset:
                a, dd = e, np.zeros(r_)
            else:
                a, dd = (
                    st["lam1"] * e + (1.0 - st["lam1"]) * a,
                    st["lam2"] * (e - a) + (1.0 - st["lam2"]) * dd,
                )
            c[:, k + 1] = -(a + dd)
        else:
            raise InputError(f"unknown policy {policy!r}; expected one of {POLICIES}")
    if policy == "fixed_gain":  # every part beyond the upper limit, the last one too
        flags = np.sum(np.abs(dev + c) > st["upper_limit"] * half, axis=1)
    return c, flags


def _check_settings(policy, settings) -> dict:
    if policy not in POLICIES:
        raise InputError(f"unknown policy {policy!r}; expected one of {POLICIES}", value=policy)
    st = dict(settings or {})
    need = set(TUNING_GRIDS[policy][0]) if policy != "bayes" else set()
    if policy == "bayes":
        unknown = set(st) - {"model", "transfer"}
    else:
        unknown = set(st) - need
    missing = need - set(st)
    if unknown or missing:
        raise InputError(
            f"policy {policy!r}: settings must have exactly {sorted(need)}, got {sorted(st)}",
            value=st,
        )
    return st


# --------------------------------------------------------------------------- bayes


_CHUNK = 64  # runs filtered at once on the whole grid (memory: about 60 MB)
_NO_LIMIT = 1e3  # mm: the decision's own limit, applied by the loop instead (`_held`)


def _loop_settings(ds: DecisionSettings, tolerance) -> tuple[DecisionSettings, float]:
    """The decision's settings in the loop (its own limit off) and the limit on one
    adjustment (`max_correction`, default the tolerance width)."""
    limit = tolerance[1] - tolerance[0] if ds.max_correction is None else ds.max_correction
    return replace(ds, max_correction=_NO_LIMIT), float(limit)


def _held(c_prev, adjustment, limit):
    """True where an adjustment is larger than `limit` and does not bring the total
    correction closer to zero (withheld: investigate first)."""
    c_prev = np.asarray(c_prev)
    return (np.abs(adjustment) > limit) & (np.abs(c_prev + adjustment) >= np.abs(c_prev))


def _bayes_predictive(dev, u, declared, model, transfer):
    """Level predictives `(R, n + 1)` mean and sd (column k: given parts < k, scaled by
    the transfer), the scatter variance `(R, n + 1)` expected under the grid weights
    and the PIT `(R, n)` of the one-step-ahead predictive of each part."""
    models = HYPER_GRID if model is None else (model,)
    scat2 = np.array([m.scatter_sd**2 for m in models])[None, :, None]
    beta, u_beta = transfer
    parts = []
    for i in range(0, dev.shape[0], _CHUNK):
        out = run_grid(dev[i : i + _CHUNK], u[i : i + _CHUNK], declared, models)
        wts = grid_weights(out["loglik"], None if model is not None else GRID_LOG_PRIOR)
        m, v = level_average(out, wts)
        pit = np.sum(wts[:, :, :-1] * out["pit"], 1)
        sd = np.sqrt(beta**2 * v + u_beta**2 * m**2)
        parts.append((beta * m, sd, np.sum(wts * scat2, 1) * beta**2, pit))
    return tuple(np.concatenate(p) for p in zip(*parts, strict=True))


def _bayes(dev, u, declared, tolerance, ds, model, transfer):
    """Corrections `(R, n)` of the `bayes` policy on runs `dev` `(R, n)`: part by part,
    the decision's correction (vectorised over runs, `_tracking_decide`); and the PIT
    `(R, n)` of the one-step-ahead predictives."""
    r_, n = dev.shape
    m, sd, sc2, pit = _bayes_predictive(dev, u, declared, model, transfer)
    ds, limit = _loop_settings(ds, tolerance)
    c = np.zeros((r_, n))
    for k in range(1, n):
        p_sd = np.maximum(ds.process_sd, np.sqrt(sc2[:, k]))
        adj = corrections(m[:, k] + c[:, k - 1], sd[:, k], p_sd, tolerance, ds)
        c[:, k] = c[:, k - 1] + np.where(_held(c[:, k - 1], adj, limit), 0.0, adj)
    return c, pit


# --------------------------------------------------------------------------- public


def _tol(tolerance) -> tuple[float, float]:
    try:
        lo, hi = (float(t) for t in tolerance)
    except (TypeError, ValueError):
        raise InputError(f"tolerance must be (lower, upper), got {tolerance!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise InputError(f"tolerance must be finite with lower < upper, got {tolerance!r}")
    return lo, hi


def _result(name, st, c, dev, tol, flags, half) -> PolicyResult:
    real = dev + c
    lo, hi = tol
    shown = dict(st)
    if name == "fixed_gain":
        shown["null_band_mm"] = st["null_band"] * half
        shown["upper_limit_mm"] = st["upper_limit"] * half
    if name == "bayes" and isinstance(shown.get("model"), TrackModel):
        shown["model"] = shown["model"].as_dict()
    c.flags.writeable = False
    real.flags.writeable = False
    return PolicyResult(
        name=name,
        settings=shown,
        corrections=c,
        realised=real,
        rmsd_mm=float(np.sqrt(np.mean(real**2))),
        max_abs_mm=float(np.max(np.abs(real))),
        out_of_tolerance=int(np.sum((real < lo) | (real > hi))),
        adjustments=int(np.sum(np.diff(c) != 0.0)) if c.size > 1 else 0,
        flags=int(flags),
    )


def replay(
    deviation,
    u,
    *,
    policy: str,
    settings: dict | None,
    tolerance: tuple[float, float],
    tool_changes=(),
    decision_settings: DecisionSettings | None = None,
) -> PolicyResult:
    """Replay one policy over a run on the counterfactual of the module doc.

    **Arguments:**

    - `deviation`: `(n,)` deviations of the parts as cut without feedback (mm).
    - `u`: `(n,)` (or one number) their standard uncertainties (mm), > 0.
    - `policy`: one of `POLICIES`.
    - `settings`: the policy's settings, keys as in `TUNING_GRIDS[policy]`; for `bayes`
      optionally `model` (a [`TrackModel`][]; default: the grid average) and
      `transfer` ($\\beta$ or $(\\beta, u_\\beta)$).
    - `tolerance`: `(lower, upper)` limits of the deviation (mm).
    - `tool_changes`: indices of the parts cut with a new tool.
    - `decision_settings`: the one-part decision's settings for `bayes`
      (default `BAYES_DECISION`).

    **Returns:** a [`PolicyResult`][].
    """
    dev, uu, declared = _checked(deviation, u, tool_changes)
    tol = _tol(tolerance)
    st = _check_settings(policy, settings)
    half = 0.5 * (tol[1] - tol[0])
    if policy == "bayes":
        ds = decision_settings if decision_settings is not None else BAYES_DECISION
        c = _bayes(
            dev[None], uu[None], declared, tol, ds, st.get("model"),
            _transfer(st.get("transfer", 1.0)),
        )[0][0]  # fmt: skip
        flags = 0
    else:
        c, flags = _anchor(dev[None], policy, st, half, declared)
        c, flags = c[0], flags[0]
    return _result(policy, st, c, dev, tol, flags, half)


def replay_runs(
    deviations,
    u,
    *,
    policy: str,
    settings: dict | None,
    tolerance: tuple[float, float],
    tool_changes=(),
    decision_settings: DecisionSettings | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """[`replay`][] of one policy over many runs at once (for benchmarks).

    **Arguments:** as for [`replay`][], with `deviations` and `u` shaped `(R, n)`
    (`u` broadcast) and the same declared tool changes for every run.

    **Returns:** `(corrections, flags, pit)`: `(R, n)` corrections (mm), `(R,)` counts
    of parts beyond `fixed_gain`'s upper limit, and for `bayes` the `(R, n)` predictive
    cdf of each part's uncompensated deviation given the parts before (NaN for part 0;
    `None` for the anchors): the share within $[0.025, 0.975]$ is the coverage of the
    95 % one-step-ahead predictive intervals.
    """
    dev = np.asarray(deviations, dtype=float)
    if dev.ndim != 2 or dev.shape[1] < 1 or not np.all(np.isfinite(dev)):
        raise InputError(f"deviations must be a finite (runs, parts) array, got {dev.shape}")
    uu = np.broadcast_to(np.asarray(u, dtype=float), dev.shape)
    _, _, declared = _checked(dev[0], uu[0], tool_changes)
    if not (np.all(np.isfinite(uu)) and np.all(uu > 0)):
        raise InputError("u must be finite numbers > 0 (mm)")
    tol = _tol(tolerance)
    st = _check_settings(policy, settings)
    if policy == "bayes":
        ds = decision_settings if decision_settings is not None else BAYES_DECISION
        c, pit = _bayes(dev, uu, declared, tol, ds, st.get("model"),
                        _transfer(st.get("transfer", 1.0)))  # fmt: skip
        return c, np.zeros(dev.shape[0], dtype=int), pit
    c, flags = _anchor(dev, policy, st, 0.5 * (tol[1] - tol[0]), declared)
    return c, flags, None


def tune(deviation, u, *, policy: str, tolerance, tool_changes=()) -> PolicyResult:
    """The best setting of `TUNING_GRIDS[policy]` on this run (lowest RMS deviation).

    **Arguments:** as for [`replay`][] (`bayes` is replayed with its fixed settings).

    **Returns:** the [`PolicyResult`][] of the best setting (ties: the first).
    """
    best = None
    for st in TUNING_GRIDS.get(policy, [{}]):
        res = replay(deviation, u, policy=policy, settings=st, tolerance=tolerance,
                     tool_changes=tool_changes)  # fmt: skip
        if best is None or res.rmsd_mm < best.rmsd_mm:
            best = res
    return best


def predictive_coverage(track_: Track, values, p: float = 0.95) -> float:
    """Share of parts inside their central `p` one-step-ahead predictive interval.

    **Arguments:**

    - `track_`: a [`Track`][] of the run.
    - `values`: `(n,)` the values it was made from (mm).
    - `p`: the interval's probability, in (0, 1).

    **Returns:** the share (parts without a predictive, part 0 of a diffuse start, are
    not counted); NaN when no part has one.
    """
    if not 0 < p < 1:
        raise InputError(f"p must be in (0, 1), got {p!r}", value=p)
    pit = track_.pit(values)
    ok = np.isfinite(pit)
    if not np.any(ok):
        return math.nan
    inside = (pit[ok] >= (1 - p) / 2) & (pit[ok] <= (1 + p) / 2)
    return float(np.mean(inside))


def next_part(
    values,
    u,
    *,
    tolerance,
    tool_changes=(),
    decision_settings: DecisionSettings | None = None,
    model: TrackModel | None = None,
    applied=None,
    transfer=1.0,
) -> dict:
    """The `bayes` correction for the next part of a run.

    **Arguments:**

    - `values`: `(n,)` measured deviations of the parts in production order (mm).
    - `u`: `(n,)` (or one number) their standard uncertainties (mm), > 0.
    - `tolerance`: `(lower, upper)` limits (mm).
    - `tool_changes`: indices of the parts cut with a new tool.
    - `decision_settings`: the decision's settings (default `BAYES_DECISION`).
    - `model`: fixed hyper-parameters (default: the grid average).
    - `applied`: `(n,)` corrections the parts were cut with (default 0): the model
      tracks `values - applied`.
    - `transfer`: $\\beta$ or $(\\beta, u_\\beta)$ (see `track`).

    **Returns:** a dict: `correction` (mm, the total correction for the next part),
    `adjustment` (its change from the last part's), `u` (its standard uncertainty, the
    sd of the level it corrects), `mean`, `sd` (the next part's level as handed to the
    decision, with the last correction applied), `model` (the [`TrackModel`][] used or
    the grid's best), `decision` (the [`Decision`][]) and `track` (the [`Track`][]).
    """
    y, uu, declared = _checked(values, u, tool_changes)
    tol = _tol(tolerance)
    c_prev = np.zeros(y.size) if applied is None else np.asarray(applied, dtype=float)
    if c_prev.shape != y.shape or not np.all(np.isfinite(c_prev)):
        raise InputError("applied must be finite corrections, one per part")
    tr = track(y - c_prev, uu, model=model, tool_changes=tool_changes, transfer=transfer)
    ds = decision_settings if decision_settings is not None else BAYES_DECISION
    scatter = tr.model.scatter_sd if tr.weights is None else math.sqrt(
        float(np.sum(tr.weights * np.array([m.scatter_sd**2 for m in HYPER_GRID])))
    )  # fmt: skip
    last = float(c_prev[-1])
    mean = tr.next_mean + last
    st, limit = _loop_settings(ds, tol)
    st = replace(st, process_sd=max(ds.process_sd, tr.transfer[0] * scatter))
    d = decide(tolerance=tol, mean=mean, sd=tr.next_sd, settings=st)
    if _held(last, d.correction, limit):
        d = replace(
            d, verdict="do not compensate", gain=0.0, correction=0.0, u_correction=0.0,
            blocked=True,
            reasons=(f"do not compensate: the adjustment {d.correction * 1e3:+.2f} µm exceeds "
                     f"max_correction {limit * 1e3:.2f} µm and does not bring the correction "
                     f"({last * 1e3:+.2f} µm) back: investigate first",),
        )  # fmt: skip
    return {
        "correction": last + d.correction,
        "adjustment": d.correction,
        "u": tr.next_sd,
        "mean": mean,
        "sd": tr.next_sd,
        "model": tr.model,
        "decision": d,
        "track": tr,
    }
