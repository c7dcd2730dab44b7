"""The settings of a measuring-system analysis as one object: [`MsaSettings`][].

One default per setting, from the procedures they name (VDA 5 / Bosch booklet 10 /
Minitab for the type-1 study, AIAG MSA 4th ed. for the gauge R&R, VDA 5 / ISO 22514-7
for the uncertainty budget), shared by `type1_study`, `gauge_rr`, `uncertainty_budget`
and the gauge-study job (whose file's `[settings]` table names the same fields). A value
out of its range is refused when the object is made, naming the setting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real

from ..errors import InputError

#: what %GRR is judged on: the tolerance (6 sigma_GRR / T) or the study variation
GRR_BASES = ("tolerance", "study")
#: how resolution and repeatability enter the budget: the larger of them (VDA 5,
#: ISO 22514-7) or both
RESOLUTION_RULES = ("max", "both")


@dataclass(frozen=True)
class MsaSettings:
    """How the type-1 study, the gauge R&R and the uncertainty budget are judged.

    Type-1 study: `min_readings` (n >= 25), `k_share` (K: the share of the tolerance
    the gauge may spread over, 0.20) and `l_spread` (L: that spread in repeatability
    sds, 6): Cg = K T / (L s), Cgk = (K T / 2 - |bias|) / (L s / 2); `cg_limit`,
    `cgk_limit` (1.33) and `resolution_share` (resolution <= 5 % of T).
    Gauge R&R: `interaction_alpha` (the interaction is pooled into repeatability when
    its p-value is above it, 0.25; 0: always pooled, 1: never), `study_multiplier`
    (6 sigma of study variation), `grr_basis` (the verdict on %GRR of the
    `"tolerance"` or of the `"study"` variation), `grr_acceptable` / `grr_conditional`
    (10 % / 30 %), `ndc_min` (5).
    Budget: `coverage_factor` (k = 2), `q_ms_limit` / `q_mp_limit` (15 % / 30 %),
    `resolution_rule` (`"max"`: the larger of u_RE and the repeatabilities, VDA 5;
    `"both"`: both counted). `confidence`: the level of every interval (0.95).
    """

    confidence: float = 0.95
    min_readings: int = 25
    k_share: float = 0.20
    l_spread: float = 6.0
    cg_limit: float = 1.33
    cgk_limit: float = 1.33
    resolution_share: float = 0.05
    interaction_alpha: float = 0.25
    study_multiplier: float = 6.0
    grr_basis: str = "tolerance"
    grr_acceptable: float = 0.10
    grr_conditional: float = 0.30
    ndc_min: int = 5
    coverage_factor: float = 2.0
    q_ms_limit: float = 0.15
    q_mp_limit: float = 0.30
    resolution_rule: str = "max"

    def __post_init__(self):
        unit = (lambda v: 0.0 < v < 1.0, "a number in (0, 1)")
        positive = (lambda v: v > 0.0, "a number > 0")
        for name, (ok, what) in {
            "confidence": unit,
            "k_share": unit,
            "resolution_share": unit,
            "interaction_alpha": (lambda v: 0.0 <= v <= 1.0, "a number in [0, 1]"),
            "grr_acceptable": unit,
            "q_ms_limit": unit,
            "q_mp_limit": unit,
            "l_spread": positive,
            "cg_limit": positive,
            "cgk_limit": positive,
            "study_multiplier": positive,
            "coverage_factor": positive,
            "grr_conditional": (lambda v: v > self.grr_acceptable, "a number above grr_acceptable"),
        }.items():
            _number(self, name, ok, what)
        for name, least in (("min_readings", 2), ("ndc_min", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, Integral) or v < least:
                _refuse(name, f"an integer >= {least}", v)
        _choice(self, "grr_basis", GRR_BASES)
        _choice(self, "resolution_rule", RESOLUTION_RULES)


def _refuse(name: str, expected: str, value) -> None:
    raise InputError(f"msa setting {name!r}: expected {expected}, got {value!r}", value=value)


def _number(opts, name: str, ok, expected: str) -> None:
    v = getattr(opts, name)
    if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v) or not ok(v):
        _refuse(name, expected, v)


def _choice(opts, name: str, allowed: tuple) -> None:
    v = getattr(opts, name)
    if v not in allowed:
        _refuse(name, f"one of {', '.join(map(repr, allowed))}", v)
