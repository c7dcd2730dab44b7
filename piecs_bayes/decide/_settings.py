"""Thresholds and costs of the compensation decision (the study file's `[decision]` table)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields

from ..errors import InputError


@dataclass(frozen=True)
class DecisionSettings:
    """Thresholds and costs of the compensation decision (mm and cost units).

    Defaults (documented for the study file's `[decision]` table):

    - `null_band` = `None`: 10 % of the tolerance width. Deviations inside it are
      not worth correcting (controller "null band").
    - `feedback_gain` = 0.5: the fixed fraction of the `fraction` policy.
    - `loss_k` = `None`: Taguchi's $k = C_\\text{out}/((T_U - T_L)/2)^2$, i.e. a part at
      a tolerance limit loses as much as a scrapped one (cost per mm$^2$ per part;
      with $C_\\text{out} = 0$ the unit cost 1 is used).
    - `adjustment_cost` = 0.05: cost of changing the program once ($C_A$).
    - `out_of_tolerance_cost` = 1.0: cost per out-of-tolerance part ($C_\\text{out}$,
      the cost unit).
    - `adjustment_sd` = 0.0: sd of the realised correction ($s_A$, mm).
    - `process_sd` = 0.0: part-to-part scatter around the systematic deviation (mm).
    - `prior_sd` = `None`: sd of true deviations between setups ($s_d$, mm); `None` is a
      flat prior (no shrinkage, `grubbs_prior` equals `grubbs`).
    - `max_correction` = `None`: the tolerance width. A larger correction is blocked.
    - `p_significant` = 0.95: $P(|\\delta| > b)$ needed to call a deviation significant.
    - `coverage_factor` = 2.0: $k$ of the expanded uncertainty $U = k u$.
    - `guard_band_factor` = 1.0: $r$ of the acceptance limits $T_L + rU$, $T_U - rU$.
    - `parts_per_decision` = 1: parts the decision affects ($N$).
    - `max_points_factor` = 16.0: "measure more" looks for up to this many times the
      current number of probe points.
    - `require_significance` = `None`: compensate only when $P(|\\delta| > b) \\ge$
      `p_significant`. `None` means *yes without a prior, no with one*: with a flat prior
      the posterior mean is the raw estimate and the loss rule alone would chase noise;
      a prior (`prior_sd`) already shrinks noise away, and demanding significance on top
      would forgo corrections that lower the expected loss.
    """

    null_band: float | None = None
    feedback_gain: float = 0.5
    loss_k: float | None = None
    adjustment_cost: float = 0.05
    out_of_tolerance_cost: float = 1.0
    adjustment_sd: float = 0.0
    process_sd: float = 0.0
    prior_sd: float | None = None
    max_correction: float | None = None
    p_significant: float = 0.95
    coverage_factor: float = 2.0
    guard_band_factor: float = 1.0
    parts_per_decision: int = 1
    max_points_factor: float = 16.0
    require_significance: bool | None = None

    def __post_init__(self):
        def check(name, ok, expected):
            v = getattr(self, name)
            if v is None and name in _OPTIONAL:
                return
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InputError(
                    f"decision setting {name!r}: expected {expected}, got {v!r}", value=v
                )
            if not ok(v):
                raise InputError(
                    f"decision setting {name!r}: expected {expected}, got {v!r}", value=v
                )

        check("null_band", lambda v: v >= 0, "a number >= 0 (mm)")
        check("feedback_gain", lambda v: 0 < v <= 1, "a number in (0, 1]")
        check("loss_k", lambda v: v > 0, "a number > 0 (cost per mm^2)")
        check("adjustment_cost", lambda v: v >= 0, "a number >= 0")
        check("out_of_tolerance_cost", lambda v: v >= 0, "a number >= 0")
        check("adjustment_sd", lambda v: v >= 0, "a number >= 0 (mm)")
        check("process_sd", lambda v: v >= 0, "a number >= 0 (mm)")
        check("prior_sd", lambda v: v > 0, "a number > 0 (mm)")
        check("max_correction", lambda v: v > 0, "a number > 0 (mm)")
        check("p_significant", lambda v: 0.5 < v < 1, "a probability in (0.5, 1)")
        check("coverage_factor", lambda v: v > 0, "a number > 0")
        check("guard_band_factor", lambda v: v >= 0, "a number >= 0")
        check("max_points_factor", lambda v: v >= 1, "a number >= 1")
        if not (self.require_significance is None or isinstance(self.require_significance, bool)):
            raise InputError(
                "decision setting 'require_significance': expected true or false, got "
                f"{self.require_significance!r}",
                value=self.require_significance,
            )
        v = self.parts_per_decision
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise InputError(
                f"decision setting 'parts_per_decision': expected an integer >= 1, got {v!r}",
                value=v,
            )


_OPTIONAL = ("null_band", "loss_k", "prior_sd", "max_correction")


def settings_from_spec(spec: Mapping | None, *, file: str | None = None) -> DecisionSettings:
    """Decision settings from a mapping (the study file's `[decision]` table).

    Missing keys take the defaults of [`DecisionSettings`][]; an unknown key or a bad
    value raises `InputError` naming the key and the value.
    """
    if spec is None:
        return DecisionSettings()
    if not isinstance(spec, Mapping):
        raise InputError(f"decision settings must be a table, got {type(spec).__name__}", file=file)
    known = {f.name for f in fields(DecisionSettings)}
    for key in spec:
        if key not in known:
            raise InputError(
                f"unknown decision setting {key!r} (value {spec[key]!r}); expected one of "
                f"{sorted(known)}",
                file=file,
                value=spec[key],
            )
    try:
        return DecisionSettings(**dict(spec))
    except InputError as e:
        if file is None:
            raise
        raise InputError(e.reason, file=file, value=e.value) from None
