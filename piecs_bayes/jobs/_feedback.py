"""Feedback over a production run: track every feature from part to part, replay the
feedback policies, and recommend the next part's correction.

Per part (production order: the order of the study's probe files and of the `part`
column within a file) and feature the value is the characteristic, the normal
deviation $\\delta$ at a fixed nominal point with its fit uncertainty, the same
values as the capability study (`capability_values`, batch fits). The arithmetic is
on $\\delta$ (mm, + outside the material) against the tolerance on $\\delta$;
the drawn coordinate (`geometry.drawn_scale`: $2\\delta$ on a diameter, ...) only
states the numbers (`*_drawn_mm`).

Per feature:

1. the tracking model (`compensate` tracking: local linear trend, steps at tool
   changes, odd parts; hyper-parameters averaged over their grid) gives the one-step
   ahead predictive of every part, the level, the probabilities that a part is odd or
   starts a step, and the steps (declared in `[feedback] tool_changes`, or found);
2. every policy (`none`, `full`, `fixed_gain`, `mean_value`, `ewma`, `dewma`,
   `bayes`) is replayed on the counterfactual that a correction adds to the following
   parts' deviations; the anchors are tuned over their grids on the same data (their
   best setting is reported), `bayes` runs with fixed settings;
3. the coverage of the 95 % one-step-ahead predictive intervals;
4. the `bayes` correction for the next part, with its standard uncertainty.

**Post-process loop.** With finished-part measurements (`[feedback] finish_files`,
`io.read_finish_files`), the transfer coefficient $\\beta$ of each feature
(`fit_transfer`: finish $= \\beta\\times$ semifinish) is fitted from the parts
measured both ways; the replay then runs on the finish deviations the parts would
show, $\\beta\\,\\delta_k$ (with $u_\\beta$ in the `bayes` predictive), the next-part
correction acts on $\\beta$ times the level, and the predicted finish bounds are
checked against the measurements: before the part was cut (the one-step predictive
times $\\beta$) and from the part's own semifinish measurement ($\\beta\\,y_k$).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from ..compensate import POLICIES, fit_transfer, next_part, predictive_coverage, replay, track, tune
from ..errors import InputError
from ..geometry import drawn_scale
from ..io import rows_to_dataframe
from ._batch import capability_values
from ._fit import load_probe_data
from ._options import source_sds

__all__ = ["FeatureFeedback", "FeedbackResult", "feedback_from_values", "feedback_study"]

#: the level of the predictive intervals checked
COVERAGE_LEVEL = 0.95
_Z95 = 1.959963984540054


@dataclass(frozen=True, eq=False)
class FeatureFeedback:
    """Feedback over a run for one feature (normal deviations δ in mm; see the module doc).

    - `parts`, `values`, `u`: the parts with a value, in production order, δ and u_fit.
    - `tolerance`: limits of δ; `coordinate`, `scale`: the drawn coordinate and the drawn
      deviation per unit of δ; `u_systematic`: the systematic uncertainty common to
      every part (not in `u`).
    - `tool_changes`: indices (into `parts`) of the declared tool changes.
    - `track`: the tracking of the values; `coverage`, `n_covered`: the share of parts
      inside their 95 % one-step-ahead predictive interval, and how many were counted.
    - `policies`: the replayed policies by name ([`PolicyResult`]s).
    - `next_part`: the `bayes` correction for the next part (`correction`, `u`,
      `adjustment`, `mean`, `sd`, `verdict`).
    - `transfer`: `(beta, u_beta)` from finished parts, `None` without them;
      `finish`: the finished-part check (see [`FeedbackResult.finish_rows`][]).
    """

    feature: str
    coordinate: str
    scale: float
    tolerance: tuple[float, float]
    parts: tuple[str, ...]
    values: np.ndarray
    u: np.ndarray
    u_systematic: float
    tool_changes: tuple[int, ...]
    track: object
    coverage: float
    n_covered: int
    policies: Mapping
    next_part: Mapping
    transfer: tuple[float, float] | None = None
    finish: Mapping | None = None

    @property
    def steps(self) -> list[dict]:
        """The steps: `{part, index, p_step, declared}` (declared or found, p_step > 0.5)."""
        tr = self.track
        return [
            {"part": self.parts[i], "index": int(i), "p_step": float(tr.p_step[i]),
             "declared": int(i) in self.tool_changes}
            for i in tr.steps
        ]  # fmt: skip

    @property
    def odd_parts(self) -> tuple[str, ...]:
        """Parts more likely odd than not (p_outlier > 0.5)."""
        return tuple(self.parts[i] for i in np.flatnonzero(self.track.p_outlier > 0.5))

    @property
    def best_anchor(self) -> str:
        """The anchor policy (not `none`, not `bayes`) with the lowest RMS deviation."""
        anchors = [p for p in self.policies.values() if p.name not in ("none", "bayes")]
        return min(anchors, key=lambda p: p.rmsd_mm).name if anchors else ""

    def __repr__(self) -> str:
        b = self.policies.get("bayes")
        best = self.best_anchor
        tail = ""
        if b is not None and best:
            tail = (f", RMS bayes {b.rmsd_mm * 1e3:.2f} µm vs {best} "
                    f"{self.policies[best].rmsd_mm * 1e3:.2f} µm")  # fmt: skip
        return (
            f"FeatureFeedback({self.feature!r}: {len(self.parts)} parts, steps at "
            f"{', '.join(s['part'] for s in self.steps) or 'none'}, coverage "
            f"{self.coverage:.0%}{tail})"
        )


@dataclass(frozen=True, eq=False)
class FeedbackResult:
    """Feedback over a run of parts for every feature (see [`feedback_study`][])."""

    study: str
    parts: tuple[str, ...]
    method: str
    characteristic: str
    features: Mapping[str, FeatureFeedback]
    policies: tuple[str, ...]
    tool_changes: tuple[str, ...]
    replayed_on: str = "measured"
    finish_files: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    def __getitem__(self, feature: str) -> FeatureFeedback:
        return self.features[feature]

    @property
    def steps(self) -> dict[str, tuple[str, ...]]:
        """Steps found or declared: `{first part after the step: features}`."""
        out: dict[str, list] = {}
        for f in self.features.values():
            for s in f.steps:
                out.setdefault(s["part"], []).append(f.feature)
        return {p: tuple(v) for p, v in out.items()}

    def overall(self, policy: str) -> dict:
        """A policy over every feature and part: RMS and largest |realised δ| (mm),
        parts out of tolerance and adjustments (summed), and its settings by feature."""
        res = [f.policies[policy] for f in self.features.values() if policy in f.policies]
        real = np.concatenate([np.asarray(r.realised) for r in res]) if res else np.array([])
        return {
            "name": policy,
            "settings": {f.feature: dict(f.policies[policy].settings)
                         for f in self.features.values() if policy in f.policies},
            "rmsd_mm": float(np.sqrt(np.mean(real**2))) if real.size else math.nan,
            "max_abs_mm": float(np.max(np.abs(real))) if real.size else math.nan,
            "out_of_tolerance": int(sum(r.out_of_tolerance for r in res)),
            "adjustments": int(sum(r.adjustments for r in res)),
        }  # fmt: skip

    def coverage(self) -> dict:
        """The 95 % one-step-ahead predictive coverage: pooled over the features
        (`overall`, `n` parts counted) and by feature."""
        n = sum(f.n_covered for f in self.features.values())
        inside = sum(f.coverage * f.n_covered for f in self.features.values() if f.n_covered)
        return {
            "level": COVERAGE_LEVEL,
            "overall": inside / n if n else math.nan,
            "n": n,
            "features": {f.feature: f.coverage for f in self.features.values()},
        }

    def policy_rows(self) -> list[dict]:
        """One row per feature and policy (and per policy with feature `"all"`): RMS,
        largest |δ| (mm and as drawn), out of tolerance, adjustments, settings."""
        out = []
        for f in self.features.values():
            k = abs(f.scale)
            for p in f.policies.values():
                out.append({
                    "feature": f.feature, "policy": p.name, "coordinate": f.coordinate,
                    "rmsd_mm": p.rmsd_mm, "max_abs_mm": p.max_abs_mm,
                    "rmsd_drawn_mm": p.rmsd_mm * k, "max_abs_drawn_mm": p.max_abs_mm * k,
                    "out_of_tolerance": p.out_of_tolerance, "adjustments": p.adjustments,
                    "settings": _settings_text(p.settings),
                })  # fmt: skip
        for name in self.policies:
            o = self.overall(name)
            out.append({
                "feature": "all", "policy": name, "coordinate": "normal",
                "rmsd_mm": o["rmsd_mm"], "max_abs_mm": o["max_abs_mm"],
                "rmsd_drawn_mm": math.nan, "max_abs_drawn_mm": math.nan,
                "out_of_tolerance": o["out_of_tolerance"], "adjustments": o["adjustments"],
                "settings": "",
            })  # fmt: skip
        return out

    def next_part_rows(self) -> list[dict]:
        """One row per feature: the recommended correction for the next part and its u
        (mm of δ, then as drawn), the level it acts on, the verdict."""
        out = []
        for f in self.features.values():
            n = f.next_part
            k = f.scale
            u_all = math.hypot(n["u"], (f.transfer or (1.0, 0))[0] * f.u_systematic)
            out.append({
                "feature": f.feature, "coordinate": f.coordinate,
                "correction_mm": n["correction"], "u_mm": n["u"],
                "u_with_systematic_mm": u_all,
                "correction_drawn_mm": k * n["correction"], "u_drawn_mm": abs(k) * n["u"],
                "level_mm": n["mean"], "level_sd_mm": n["sd"], "verdict": n["verdict"],
                "transfer": (f.transfer or (1.0, 0.0))[0],
                "u_transfer": (f.transfer or (1.0, 0.0))[1],
            })  # fmt: skip
        return out

    def part_rows(self) -> list[dict]:
        """One row per part and feature (long format, lengths in `unit`, δ in mm): the
        value and u, the one-step-ahead predictive (mean, sd, 95 % interval), the
        filtered and smoothed level, p_outlier, p_step, declared tool change and step
        (0/1), the finished-part measurement, and each policy's realised deviation."""
        out = []
        for f in self.features.values():
            tr = f.track
            steps = set(tr.steps)
            fin = (f.finish or {}).get("by_part", {})
            for i, p in enumerate(f.parts):
                fv, fu = fin.get(p, (math.nan, math.nan))
                row = {
                    "part": p, "index": i + 1, "feature": f.feature, "unit": "mm",
                    "coordinate": f.coordinate, "drawn_scale": f.scale,
                    "value": float(f.values[i]), "u": float(f.u[i]),
                    "pred_mean": float(tr.pred_mean[i]), "pred_sd": float(tr.pred_sd[i]),
                    "pred_lower": float(tr.pred_lo[i]), "pred_upper": float(tr.pred_hi[i]),
                    "level": float(tr.level[i]), "level_sd": float(tr.level_sd[i]),
                    "smooth_level": float(tr.smooth_level[i]),
                    "smooth_level_sd": float(tr.smooth_level_sd[i]),
                    "p_outlier": float(tr.p_outlier[i]), "p_step": float(tr.p_step[i]),
                    "tool_change": int(i in f.tool_changes), "step": int(i in steps),
                    "finish_value": float(fv), "finish_u": float(fu),
                }  # fmt: skip
                for name, pol in f.policies.items():
                    row[f"realised_{name}"] = float(pol.realised[i])
                out.append(row)
        return out

    def finish_rows(self) -> list[dict]:
        """One row per feature with finished parts: the transfer coefficient and the
        coverage of the predicted finish bounds (one step ahead; from the semifinish)."""
        out = []
        for f in self.features.values():
            if f.finish is None:
                continue
            fi = f.finish
            out.append({
                "feature": f.feature, "n_finished": fi["n"], "transfer": f.transfer[0],
                "u_transfer": f.transfer[1], "residual_sd_mm": fi["residual_sd"],
                "coverage_one_step": fi["coverage_one_step"], "n_one_step": fi["n_one_step"],
                "coverage_from_semifinish": fi["coverage_semifinish"],
            })  # fmt: skip
        return out

    def to_dataframe(self, table: str = "parts"):
        """A `pandas.DataFrame` of `table`: "parts" (`part_rows()`, feedback_parts.csv),
        "policies" (`policy_rows()`, feedback_policies.csv), "next_part"
        (`next_part_rows()`) or "finish" (`finish_rows()`)."""
        tables = {"parts": self.part_rows, "policies": self.policy_rows,
                  "next_part": self.next_part_rows, "finish": self.finish_rows}  # fmt: skip
        if table not in tables:
            raise ValueError(f"unknown table {table!r}; expected one of {', '.join(tables)}")
        return rows_to_dataframe(tables[table]())

    def __repr__(self) -> str:
        steps = "; ".join(f"{p}: {len(v)} features" for p, v in self.steps.items()) or "none"
        return (
            f"FeedbackResult({self.study!r}: {len(self.parts)} parts, "
            f"{len(self.features)} features, steps {steps}, coverage "
            f"{self.coverage()['overall']:.1%})"
        )


def _settings_text(settings: Mapping) -> str:
    out = []
    for k, v in settings.items():
        if isinstance(v, float):
            out.append(f"{k}={v:g}")
        elif not isinstance(v, Mapping):
            out.append(f"{k}={v}")
    return " ".join(out)


def _progress_fn(progress) -> Callable[[str], None]:
    if callable(progress):
        return progress
    if not progress:
        return lambda msg: None
    t0 = time.perf_counter()
    return lambda msg: print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", flush=True)


def _finish_check(y, u, tr, transfer, meas, resid_sd) -> dict:
    """The finished-part check of one feature: `meas` is `{index: (value, u)}`."""
    beta, u_beta = transfer
    inside1, n1, inside2 = [], 0, []
    for i, (fv, fu) in meas.items():
        lo, hi = tr.pred_lo[i], tr.pred_hi[i]
        if np.isfinite(lo) and np.isfinite(hi):
            c = 0.5 * beta * (lo + hi)
            extra = _Z95 * math.hypot(fu, u_beta * tr.pred_mean[i])
            h = math.hypot(0.5 * abs(beta) * (hi - lo), extra)
            inside1.append(abs(fv - c) <= h)
            n1 += 1
        s = math.sqrt((beta * u[i]) ** 2 + (u_beta * y[i]) ** 2 + fu**2 + resid_sd**2)
        inside2.append(abs(fv - beta * y[i]) <= _Z95 * s)
    return {
        "n": len(meas),
        "coverage_one_step": float(np.mean(inside1)) if inside1 else math.nan,
        "n_one_step": n1,
        "coverage_semifinish": float(np.mean(inside2)) if inside2 else math.nan,
        "residual_sd": resid_sd,
    }


def _transfer_fit(fid, parts, y, u, finish, notes):
    """`(beta, u_beta), {index: (value, u)}, residual sd` of one feature, or Nones."""
    if finish is None:
        return None, {}, 0.0
    by_part = finish.for_feature(fid)
    idx = {p: i for i, p in enumerate(parts)}
    meas = {idx[p]: (v, uu) for p, (v, uu, _) in by_part.items() if p in idx}
    if len(meas) < 2:
        if by_part:
            notes.append(f"{fid}: {len(meas)} finished part(s) with a semifinish value; "
                         "a transfer coefficient needs 2: replayed as measured")  # fmt: skip
        return None, {}, 0.0
    ii = np.array(sorted(meas))
    fv = np.array([meas[i][0] for i in ii])
    fu = np.array([meas[i][1] for i in ii])
    beta, u_beta = fit_transfer(y[ii], fv, u[ii], fu)
    extra = (fv - beta * y[ii]) ** 2 - fu**2 - (beta * u[ii]) ** 2
    resid_sd = math.sqrt(max(0.0, float(np.mean(extra))))
    return (float(beta), float(u_beta)), meas, resid_sd


def _one_feature(fid, feat, parts, y, u, usys, declared, policies, finish, notes, say):
    tol = tuple(float(t) for t in feat.tolerance)
    changes = tuple(sorted({i for i, p in enumerate(parts) if p in declared}))
    for p in sorted(declared - set(parts)):
        notes.append(f"{fid}: tool change {p} has no value (its fit was left out): not declared")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN predictive of part 1
        tr = track(y, u, tool_changes=changes)
    cov = predictive_coverage(tr, y, COVERAGE_LEVEL)
    n_cov = int(np.sum(np.isfinite(tr.pit(y))))
    transfer, meas, resid_sd = _transfer_fit(fid, parts, y, u, finish, notes)
    beta, u_beta = transfer if transfer is not None else (1.0, 0.0)
    dev, ud = beta * y, abs(beta) * u
    res = {}
    for name in policies:
        if name == "bayes":
            st = {} if transfer is None else {"transfer": (1.0, u_beta / max(abs(beta), 1e-12))}
            res[name] = replay(dev, ud, policy="bayes", settings=st, tolerance=tol,
                               tool_changes=changes)  # fmt: skip
        else:
            res[name] = tune(dev, ud, policy=name, tolerance=tol, tool_changes=changes)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        nxt = next_part(y, u, tolerance=tol, tool_changes=changes, transfer=(beta, u_beta))
    d = nxt["decision"]
    finish_info = None
    if transfer is not None:
        finish_info = _finish_check(y, u, tr, transfer, meas, resid_sd)
        finish_info["by_part"] = MappingProxyType({parts[i]: v for i, v in meas.items()})
    say(f"{fid}: {len(parts)} parts tracked, {len(res)} policies replayed")
    return FeatureFeedback(
        feature=fid,
        coordinate=feat.tolerance_on,
        scale=float(drawn_scale(feat)),
        tolerance=tol,
        parts=tuple(parts),
        values=_ro(y),
        u=_ro(u),
        u_systematic=float(usys),
        tool_changes=changes,
        track=tr,
        coverage=float(cov),
        n_covered=n_cov,
        policies=MappingProxyType(res),
        next_part=MappingProxyType(
            {
                "correction": float(nxt["correction"]),
                "u": float(nxt["u"]),
                "adjustment": float(nxt["adjustment"]),
                "mean": float(nxt["mean"]),
                "sd": float(nxt["sd"]),
                "verdict": str(d.verdict),
                "reasons": tuple(d.reasons),
            }
        ),  # fmt: skip
        transfer=transfer,
        finish=None if finish_info is None else MappingProxyType(finish_info),
    )


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


def feedback_from_values(
    values: Mapping[str, Sequence[float]],
    u: Mapping[str, Sequence[float]],
    *,
    profile,
    parts: Mapping[str, Sequence[str]],
    u_systematic: Mapping[str, float] | None = None,
    tool_changes: Sequence[str] = (),
    policies: Sequence[str] = POLICIES,
    finish=None,
    characteristic: str = "mid",
    study: str = "",
    method: str = "",
    notes: Sequence[str] = (),
    progress=False,
) -> FeedbackResult:
    """Feedback over a run from per-part values (pure; see the module doc).

    **Arguments:**

    - `values`, `u`: by feature id, the normal deviations δ and their standard
      uncertainties (mm), one per part in production order.
    - `profile`: the study's profile (tolerances and drawn coordinates).
    - `parts`: by feature id, the part ids of the values.
    - `u_systematic`: by feature, the systematic uncertainty common to every part (mm).
    - `tool_changes`: part ids cut first with a new tool (declared steps).
    - `policies`: the policies to replay (default: all).
    - `finish`: finished-part measurements (`io.FinishData`) or `None`.
    - `progress`: `True` (print), a callable `progress(message)`, or `False`.

    **Returns:** a [`FeedbackResult`][].
    """
    say = _progress_fn(progress)
    notes = list(notes)
    for p in policies:
        if p not in POLICIES:
            raise InputError(f"unknown policy {p!r}; expected some of {', '.join(POLICIES)}",
                             value=p)  # fmt: skip
    declared = set(tool_changes)
    feats = {}
    for fid in profile.ids:
        if fid not in values:
            continue
        y = np.asarray(values[fid], dtype=float)
        uu = np.asarray(u[fid], dtype=float)
        if y.size < 2:
            notes.append(f"{fid}: only {y.size} value(s); no feedback")
            continue
        feats[fid] = _one_feature(
            fid, profile[fid], list(parts[fid]), y, uu, (u_systematic or {}).get(fid, 0.0),
            declared, tuple(policies), finish, notes, say,
        )  # fmt: skip
    all_parts = tuple(dict.fromkeys(p for f in feats.values() for p in f.parts))
    replayed = "measured" if not any(f.transfer for f in feats.values()) else "finish"
    return FeedbackResult(
        study=study,
        parts=all_parts,
        method=method,
        characteristic=characteristic,
        features=MappingProxyType(feats),
        policies=tuple(policies),
        tool_changes=tuple(p for p in all_parts if p in declared),
        replayed_on=replayed,
        finish_files=() if finish is None else tuple(dict.fromkeys(finish.files.tolist())),
        notes=tuple(notes),
    )


def _declared(study, parts: Sequence[str], cfg) -> tuple[str, ...]:
    changes = tuple(cfg.get("tool_changes", ()))
    for p in changes:
        if p not in parts:
            shown = f"{parts[0]}..{parts[-1]}" if len(parts) > 3 else ", ".join(parts)
            raise InputError(
                f"feedback.tool_changes: unknown part {p!r}; the run has {len(parts)} parts "
                f"({shown})",
                file=str(study.path), value=p,
            )  # fmt: skip
    return changes


def _finish(study, finish, parts):
    """The finished-part measurements: `finish` (`FinishData`, or paths), else the
    study's `[feedback] finish_files`, else `None`; every part must be in the run."""
    from ..io import read_finish_files

    if finish is None:
        files = study.sections.get("feedback", {}).get("finish_files", ())
        if not files:
            return None
        finish = files
    if not hasattr(finish, "for_feature"):
        finish = read_finish_files(list(finish), profile=study.profile, units=study.units,
                                   encoding=study.encoding)  # fmt: skip
    known = set(parts)
    for i, p in enumerate(finish.part.tolist()):
        if p not in known:
            raise InputError(
                f"part {p!r} is not a part of the run ({len(parts)} parts from the probe files)",
                file=str(finish.files[i]), line=int(finish.lines[i]), column="part", value=p,
            )  # fmt: skip
    return finish


def feedback_study(study, *, probe=None, finish=None, progress=True) -> FeedbackResult:
    """Feedback over the study's run of parts: tracking, policy replay, next part.

    **Arguments:**

    - `study`: the study; its probe files give the parts in production order; its
      `[feedback]` table the declared tool changes, the policies and the finished-part
      files; its `[capability]` (or `[feedback]`) `characteristic` the nominal point.
    - `probe`: the probe data (`ProbeData`), read from the study when not given.
    - `finish`: finished-part measurements (`io.FinishData` or file paths) instead of
      the study's `finish_files`.
    - `progress`: `True` (print a line per step), a callable `progress(message)`, or
      `False`.

    **Returns:** a [`FeedbackResult`][].

    **Raises:** `InputError` for a tool change or finished part not in the run (naming
    the file, key or line, and the value).
    """
    say = _progress_fn(progress)
    cfg = study.sections.get("feedback", {})
    probe = probe if probe is not None else load_probe_data(study)
    parts = probe.parts
    if len(parts) < 2:
        raise InputError(f"feedback needs a run of at least 2 parts, got {len(parts)} in "
                         f"{probe.file_text}")  # fmt: skip
    declared = _declared(study, parts, cfg)
    fin = _finish(study, finish, parts)
    if fin is not None:
        say(f"read {len(fin)} finished-part measurements of {len(fin.parts)} parts")
    at = cfg.get("characteristic", study.capability.get("characteristic", "mid"))
    notes = []
    used = study.fit.method
    if used == "bayes":
        used = "robust"
        notes.append("per-part values from the robust fits (the study asks for bayes)")
    if study.fit.free_transform:
        raise InputError("feedback: joint fits (fit.free_transform) are not batched; "
                         "remove fit.free_transform", file=str(study.path))  # fmt: skip

    say(f"fitting {len(parts)} parts in batches (the first call compiles)")

    def fitted(done, total, last):
        say(f"fitted {done}/{total} parts ({last})")

    values, us, pids, usys, more = capability_values(
        study, probe, method=used, at=at, sources=source_sds(study), progress=fitted
    )
    notes += more
    return feedback_from_values(
        values, us, profile=study.profile, parts=pids, u_systematic=usys,
        tool_changes=declared, policies=cfg.get("policies", POLICIES), finish=fin,
        characteristic=at, study=study.name, method=used, notes=notes, progress=say,
    )  # fmt: skip
