"""The results of feedback over a production run (`jobs._feedback`): per feature and
for the run, with the tables the writers read."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..feedback import COMPARISONS, SHOP_SETTINGS
from ..io import rows_to_dataframe

#: the level of the predictive intervals checked
COVERAGE_LEVEL = 0.95


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
    inspect_every: int = 1
    delay: int = 0

    def __getitem__(self, feature: str) -> FeatureFeedback:
        return self.features[feature]

    @staticmethod
    def policy_label(name: str) -> str:
        """A policy's name with its comparison, as the tables head it (see
        [`feedback_policy_label`][])."""
        return feedback_policy_label(name)

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
                    "feature": f.feature, "policy": p.name,
                    "comparison": feedback_comparison(p.name), "coordinate": f.coordinate,
                    "rmsd_mm": p.rmsd_mm, "max_abs_mm": p.max_abs_mm,
                    "rmsd_drawn_mm": p.rmsd_mm * k, "max_abs_drawn_mm": p.max_abs_mm * k,
                    "out_of_tolerance": p.out_of_tolerance, "adjustments": p.adjustments,
                    "settings": _settings_text(p.settings),
                })  # fmt: skip
        for name in self.policies:
            o = self.overall(name)
            out.append({
                "feature": "all", "policy": name, "comparison": feedback_comparison(name),
                "coordinate": "normal",
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
                    row[f"realised_{name.replace(' (a)', '_a')}"] = float(pol.realised[i])
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


def feedback_comparison(name: str) -> str:
    """Which comparison a policy's row is (`COMPARISONS`): a shop's one setting for the
    machine (`"<anchor> (a)"`), tuned on this run (an anchor's plain name), or `""`."""
    if name.endswith(" (a)"):
        return COMPARISONS["a"]
    return COMPARISONS["b"] if name in SHOP_SETTINGS else ""


def feedback_policy_label(name: str) -> str:
    """The policy's name with its comparison: `ewma (a)`, `ewma (b)`, `bayes`."""
    return f"{name} (b)" if name in SHOP_SETTINGS else name
