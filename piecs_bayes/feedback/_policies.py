"""Feedback over a production run: the policies and the counterfactual replay.

`deviation[k]`: part $k$'s deviation as cut without any feedback correction (mm,
normal, + = material left). A policy sets part $k$'s correction from the parts before
it only; the correction adds to the part, the realised deviation is all it sees.
[`replay`][] (one run) and [`replay_runs`][] (many) return a [`PolicyResult`][] per
policy of `POLICIES`: the anchors (`none`, `full`, `fixed_gain`, `mean_value`, `ewma`,
`dewma`, the controllers' rules `siemens`, `renishaw`, `heidenhain`) and `bayes` (the
model's predictive handed to the one-part decision, `BAYES_DECISION`). [`tune`][]
replays every setting of `TUNING_GRIDS[policy]` and keeps the lowest RMS deviation (a
hindsight advantage `bayes` does not get); `SHOP_SETTINGS` is the one setting per
anchor. [`next_part`][] is the `bayes` correction for the next part,
[`predictive_coverage`][] the share of parts inside their predictive interval.

The policies and the counterfactual: docs/feedback.md, "The policies".
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np

from ..decide import DecisionSettings, decide
from ..errors import InputError
from ._controllers import CONTROLLERS, check_controller_settings
from ._replay import anchor_loop, bayes_loop, expand_sampled, held, loop_settings, schedule, window
from ._tracking import (
    GRID_LOG_PRIOR,
    HYPER_GRID,
    Track,
    TrackModel,
    checked_values,
    grid_weights,
    run_grid,
    track,
    transfer_of,
)

POLICIES = ("none", "full", "fixed_gain", "mean_value", "ewma", "dewma") + CONTROLLERS + ("bayes",)

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
    "siemens": [
        {"_K": k, "_TZL": z, "_TMV": math.inf, "_TDIF": math.inf, "_TSA": math.inf}
        for k, z in itertools.product((1, 2, 3, 5, 8), (0.0, 0.002, 0.005, 0.01))
    ],
    "renishaw": [
        {"F": f, "V": v, "U": u}
        for f, v, u in itertools.product(
            (0.25, 0.5, 0.75, 1.0), (0.0, 0.002, 0.005, 0.01), (0.05, 0.1, math.inf)
        )
    ],
    "heidenhain": [{"RBREAK": b} for b in (0.0, 0.02, 0.05, 0.1, 0.2)],
    "bayes": [{}],
}
"""Settings tried by `tune` per policy: `fixed_gain` gain $g$, null band and upper limit
as fractions of the tolerance half-width; `mean_value` window $K$ (parts); `ewma`
weight $\\lambda$; `dewma` level and drift weights $\\lambda_1, \\lambda_2$. The
controllers' rules take what a shop types into the control, in mm: `siemens`
weighting factor `_K` (1, 2, 3, 5, 8) and zero-offset range `_TZL` (0, 2, 5, 10 µm),
the outer bands `_TMV`, `_TDIF`, `_TSA` not programmed (inf: a shop sets them per
feature, from its tolerance, and inside the tolerance only `_TMV` acts); `renishaw`
feedback `F` (F.25 ... F1: 25 % ... 100 %), null band `V` (0, 2, 5, 10 µm), upper
tolerance limit `U` (0.05, 0.1 mm, not programmed); `heidenhain` breakage tolerance
`RBREAK` (0: not monitored, 0.02 ... 0.2 mm)."""

SHOP_SETTINGS: dict[str, dict] = {
    "fixed_gain": {"gain": 0.5, "null_band": 0.0, "upper_limit": 2.0},
    "mean_value": {"k": 3},
    "ewma": {"lam": 0.4},
    "dewma": {"lam1": 0.3, "lam2": 0.05},
    "siemens": {"_K": 3, "_TZL": 0.002, "_TMV": math.inf, "_TDIF": math.inf, "_TSA": math.inf},
    "renishaw": {"F": 1.0, "V": 0.0, "U": math.inf},
    "heidenhain": {"RBREAK": 0.0},
}
"""One setting per anchor for every run, as a shop tunes a machine once (comparison
(a) of `benchmarks/bench_feedback.py`): the setting of `TUNING_GRIDS` with the lowest
mean log RMS over the benchmark's twelve scenarios on its training runs (200 runs per
scenario, seed 17; other seeds than its test runs). The controllers' rules are not tuned
there: `renishaw` and `heidenhain` take the controls' defaults (Inspection Plus: `F`
100 %, `V` and `U` not given: no null band, no upper limit; TNC tool table: `RBREAK`
0, not monitored), `siemens` (no default published for `_K`, `_TZL`) the worked
example's $k = 3$ and a 2 µm zero-offset range, the outer bands not programmed."""

COMPARISONS = {
    "a": "a: one setting for the machine (SHOP_SETTINGS)",
    "b": "b: tuned on this run (hindsight)",
}
"""The two comparisons a replay of the anchors is read in (see `SHOP_SETTINGS`)."""


@dataclass(frozen=True)
class PolicyResult:
    """One policy replayed over a run (see the module doc).

    - `name`, `settings`: the policy and its settings (`fixed_gain`'s bands also in mm).
    - `corrections`, `realised`: `(n,)` $c_k$ and $r_k = \\delta_k + c_k$ (mm).
    - `rmsd_mm`, `max_abs_mm`: RMS and largest $|r_k|$.
    - `out_of_tolerance`: parts with $r_k$ outside the tolerance.
    - `adjustments`: parts whose correction differs from the previous part's.
    - `flags`: measured parts beyond `fixed_gain`'s upper limit, or on which a
      controller's rule raises an alarm (`siemens`, `renishaw`, `heidenhain`; 0 for
      the others).
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
    if policy in CONTROLLERS:
        check_controller_settings(policy, st)
    return st


# --------------------------------------------------------------------------- public


def _tol(tolerance) -> tuple[float, float]:
    try:
        lo, hi = (float(t) for t in tolerance)
    except (TypeError, ValueError):
        raise InputError(f"tolerance must be (lower, upper), got {tolerance!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise InputError(f"tolerance must be finite with lower < upper, got {tolerance!r}")
    return lo, hi


def _result(name, st, c, dev, tol, flags, half, gain=1.0) -> PolicyResult:
    real = dev + gain * c
    lo, hi = tol
    shown = dict(st)
    if name == "fixed_gain":
        shown["null_band_mm"] = st["null_band"] * half
        shown["upper_limit_mm"] = st["upper_limit"] * half
    if name == "bayes" and isinstance(shown.get("model"), TrackModel):
        shown["model"] = shown["model"].as_dict()
    c.flags.writeable = False
    real.flags.writeable = False
    fin = real[np.isfinite(real)]  # a part not measured whose deviation is not known
    return PolicyResult(
        name=name,
        settings=shown,
        corrections=c,
        realised=real,
        rmsd_mm=float(np.sqrt(np.mean(fin**2))),
        max_abs_mm=float(np.max(np.abs(fin))),
        out_of_tolerance=int(np.sum((fin < lo) | (fin > hi))),
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
    inspect_every: int = 1,
    delay: int = 0,
    gain: float = 1.0,
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
    - `inspect_every`, `delay`, `gain`: the loop as the shop runs it (`_feedback_loop`):
      every `inspect_every`-th part measured (from part 0), results `delay` parts
      late, the correction acting at `gain` times its size (the policies assume 1).

    **Returns:** a [`PolicyResult`][] (`realised` $= \\delta_k + \\gamma c_k$).
    """
    dev, uu, declared = checked_values(deviation, u, tool_changes, missing=True)
    c, flags, _ = replay_runs(
        dev[None], uu[None], policy=policy, settings=settings, tolerance=tolerance,
        tool_changes=tool_changes, decision_settings=decision_settings,
        inspect_every=inspect_every, delay=delay, gain=gain,
    )  # fmt: skip
    tol = _tol(tolerance)
    st = _check_settings(policy, settings)
    half = 0.5 * (tol[1] - tol[0])
    return _result(policy, st, c[0], dev, tol, flags[0], half, gain)


def replay_runs(
    deviations,
    u,
    *,
    policy: str,
    settings: dict | None,
    tolerance: tuple[float, float],
    tool_changes=(),
    decision_settings: DecisionSettings | None = None,
    inspect_every: int = 1,
    delay: int = 0,
    gain=1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """[`replay`][] of one policy over many runs at once (for benchmarks).

    **Arguments:** as for [`replay`][], with `deviations` and `u` shaped `(R, n)`
    (`u` broadcast), the same declared tool changes for every run and `gain` one
    number or `(R,)`, one per run.

    **Returns:** `(corrections, flags, pit)`: `(R, n)` corrections (mm), `(R,)` counts
    of parts beyond `fixed_gain`'s upper limit or with a controller's alarm, and for
    `bayes` the `(R, n)` predictive cdf of each measured part's uncompensated
    deviation given the parts before (NaN for part 0 and parts not measured; `None`
    for the anchors): the share within $[0.025, 0.975]$ is the coverage of the 95 %
    one-step-ahead predictive intervals.
    """
    dev = np.asarray(deviations, dtype=float)
    if dev.ndim != 2 or dev.shape[1] < 1:
        raise InputError(f"deviations must be a (runs, parts) array, got {dev.shape}")
    inspected, source = schedule(dev.shape[1], inspect_every, delay)
    if not np.all(np.isfinite(dev[:, inspected])):
        raise InputError("deviations must be finite at the measured parts (NaN only at "
                         "parts not measured)")  # fmt: skip
    uu = np.broadcast_to(np.asarray(u, dtype=float), dev.shape)
    _, _, declared = checked_values(dev[0], uu[0], tool_changes, missing=True)
    if not (np.all(np.isfinite(uu[:, inspected])) and np.all(uu[:, inspected] > 0)):
        raise InputError("u must be finite numbers > 0 (mm)")
    uu = np.where(inspected, uu, np.nanmax(uu[:, inspected]))  # not used: not measured
    tol = _tol(tolerance)
    st = _check_settings(policy, settings)
    if policy == "bayes":
        ds = decision_settings if decision_settings is not None else BAYES_DECISION
        tr = transfer_of(st.get("transfer", 1.0))
        c, pit = bayes_loop(dev, uu, declared, tol, ds, st.get("model"), tr, inspected,
                            source, gain)  # fmt: skip
        return c, np.zeros(dev.shape[0], dtype=int), pit
    c, flags = anchor_loop(dev, policy, st, 0.5 * (tol[1] - tol[0]), declared, inspected,
                           source, gain, mid=0.5 * (tol[0] + tol[1]))  # fmt: skip
    return c, flags, None


def tune(deviation, u, *, policy: str, tolerance, tool_changes=(), inspect_every: int = 1,
         delay: int = 0) -> PolicyResult:  # fmt: skip
    """The best setting of `TUNING_GRIDS[policy]` on this run (lowest RMS deviation).

    **Arguments:** as for [`replay`][] (`bayes` is replayed with its fixed settings).

    **Returns:** the [`PolicyResult`][] of the best setting (ties: the first).
    """
    best = None
    for st in TUNING_GRIDS.get(policy, [{}]):
        res = replay(deviation, u, policy=policy, settings=st, tolerance=tolerance,
                     tool_changes=tool_changes, inspect_every=inspect_every,
                     delay=delay)  # fmt: skip
        if best is None or res.rmsd_mm < best.rmsd_mm:
            best = res
    return best


def at_measured(result, idx):
    """A [`Track`][] or [`PolicyResult`][] of a run in production order, at the measured
    parts `idx` only (sampled inspection): its per-part arrays indexed by `idx`; a
    track's steps and tool changes moved to the first measured part at or after them."""
    idx = np.asarray(idx, dtype=int)
    if isinstance(result, PolicyResult):
        return replace(result, corrections=_ro(result.corrections[idx]),
                       realised=_ro(result.realised[idx]))  # fmt: skip
    arrays = ("pred_mean", "pred_sd", "pred_lo", "pred_hi", "pred_weights", "pred_means",
              "pred_sds", "level", "level_sd", "smooth_level", "smooth_level_sd",
              "p_outlier", "p_step")  # fmt: skip

    def moved(ks):
        return tuple(sorted({int(np.searchsorted(idx, k)) for k in ks if k <= idx[-1]}))

    kw = {a: _ro(getattr(result, a)[idx]) for a in arrays}
    return replace(result, steps=moved(result.steps), tool_changes=moved(result.tool_changes),
                   **kw)  # fmt: skip


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


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


def _window(z, uz, changes, model, dly, e) -> tuple[float, float, float]:
    """`window` of `_feedback_loop` after the last part of `z` (production order)."""
    models = HYPER_GRID if model is None else (model,)
    ext = dly + e  # the parts ahead, not measured yet: the schedule says which will be
    z, uz = np.append(z, np.full(ext, np.nan)), np.append(uz, np.full(ext, uz[-1]))
    declared = np.zeros(z.size, dtype=bool)
    declared[list(changes)] = True
    out = run_grid(z, uz, declared, models, ahead=ext, mixture=False,
                   hazard=np.arange(z.size) % e == 0)  # fmt: skip
    lp = GRID_LOG_PRIOR if model is None else None
    j = z.size - 1 - ext
    w = grid_weights(out["loglik"][:, :, : j + 1], lp)[:, :, -1:]
    m, v, spread = window(out["am"][:, :, j, dly:], out["av"][:, :, j, dly:], w)
    return float(m[0]), float(v[0]), float(spread[0])


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
    inspect_every: int = 1,
    delay: int = 0,
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
    - `inspect_every`, `delay`: the values are every `inspect_every`-th part of the run
      (production parts $0, E, 2E, \\dots$; `tool_changes` and `applied` index them)
      and a result arrives `delay` parts late: the correction is the one for the next
      part to be cut after the last result, part $(n - 1)E + 1 + D$, held for $E$ parts
      (the level handed to the decision is the mean over those parts; their spread
      adds to the scatter), as the `bayes` replay decides it.

    **Returns:** a dict: `correction` (mm, the total correction for the next part),
    `adjustment` (its change from the last part's), `u` (its standard uncertainty, the
    sd of the level it corrects), `mean`, `sd` (the next part's level as handed to the
    decision, with the last correction applied), `model` (the [`TrackModel`][] used or
    the grid's best), `decision` (the [`Decision`][]) and `track` (the [`Track`][]).
    """
    y, uu, declared = checked_values(values, u, tool_changes)
    tol = _tol(tolerance)
    c_prev = np.zeros(y.size) if applied is None else np.asarray(applied, dtype=float)
    if c_prev.shape != y.shape or not np.all(np.isfinite(c_prev)):
        raise InputError("applied must be finite corrections, one per part")
    schedule(1, inspect_every, delay)  # checks them
    e, dly = int(inspect_every), int(delay)
    sampled = e > 1 or dly > 0
    z, uz, changes = y - c_prev, uu, tuple(tool_changes)
    if sampled:  # production order: NaN at the parts not measured
        z, uz = expand_sampled(z, e), expand_sampled(uu, e)
        changes = tuple(int(t) * e for t in np.flatnonzero(declared))
    tr = track(z, uz, model=model, tool_changes=changes, transfer=transfer)
    ds = decision_settings if decision_settings is not None else BAYES_DECISION
    scatter = tr.model.scatter_sd if tr.weights is None else math.sqrt(
        float(np.sum(tr.weights * np.array([m.scatter_sd**2 for m in HYPER_GRID])))
    )  # fmt: skip
    last = float(c_prev[-1])
    beta, u_beta = tr.transfer
    if sampled:  # the level over the parts the correction is held for, as the replay
        m_l, v_l, spread = _window(z, uz, changes, model, dly, e)
        mean_level = beta * m_l
        next_sd = math.sqrt(beta**2 * v_l + u_beta**2 * m_l**2)
        spread *= beta**2
    else:
        mean_level, spread, next_sd = tr.next_mean, 0.0, tr.next_sd
    mean = mean_level + last
    st, limit = loop_settings(ds, tol)
    p_sd = math.sqrt((beta * scatter) ** 2 + spread)
    st = replace(st, process_sd=max(ds.process_sd, p_sd))
    d = decide(tolerance=tol, mean=mean, sd=next_sd, settings=st)
    if held(last, d.correction, limit):
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
        "u": next_sd,
        "mean": mean,
        "sd": next_sd,
        "model": tr.model,
        "decision": d,
        "track": tr,
    }
