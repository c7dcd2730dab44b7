"""The settings of a capability study as one object: [`CapabilityOptions`][].

One default per setting, shared by `capability`, `predict_capability` and the
capability job (`piecs_bayes.jobs.capability_from_values`, `capability_study`,
whose study file's `[capability]` table names the same fields). A value out of
its range is refused when the object is made, naming the setting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real

from ..errors import InputError
from ._sigma import CONVENTIONS, SIGMA_METHODS
from ._stability import RUN_LENGTH, TREND_LENGTH

#: the nominal points whose deviation a capability study follows from part to part
CHARACTERISTICS = ("mid", "start", "end")


@dataclass(frozen=True)
class CapabilityOptions:
    """How capability, stability and the predicted capability are computed.

    - `characteristic`: the nominal point of each feature followed over the parts
      (`"mid"`, `"start"`, `"end"`; the capability job's values).
    - `confidence`: level of the two-sided confidence and credible intervals.
    - `threshold`: the Bayesian summaries report $P(C_{pk} >$ `threshold`$)$.
    - `sigma_method`: the within sigma (`sigma_within`'s methods; the capability job
      reads `"auto"` as `"mr"`, individuals); `convention`: `"piecs"` or `"qcc"`.
    - `subtract_gauge`: the job subtracts the mean measurement variance from the
      variances (`capability` takes the gauge sd itself as an argument).
    - `gain`: fraction of the mean offset the predicted compensation removes.
    - `bayes`: also posterior medians and credible intervals, from `n_draws` draws
      seeded by `seed` (the predictions draw as many with the same seed).
    - `run_length`, `trend_length`: the stability rules (`stability_check`).
    - `q_mp_limit`: the largest capability ratio of the measuring process,
      $Q_{MP} = 2 U_{MP} / T$, at which a process may be called capable (VDA 5 /
      ISO 22514-7: 30 %); `coverage_factor`: $k$ in $U_{MP} = k\\,u_{MP}$ (2).
    """

    characteristic: str = "mid"
    confidence: float = 0.95
    threshold: float = 1.33
    sigma_method: str = "auto"
    convention: str = "piecs"
    subtract_gauge: bool = False
    gain: float = 1.0
    bayes: bool = True
    n_draws: int = 100_000
    seed: int = 0
    run_length: int = RUN_LENGTH
    trend_length: int = TREND_LENGTH
    q_mp_limit: float = 0.30
    coverage_factor: float = 2.0

    def __post_init__(self):
        _choice(self, "characteristic", CHARACTERISTICS, "characteristic")
        _choice(self, "sigma_method", SIGMA_METHODS, "sigma method")
        _choice(self, "convention", CONVENTIONS, "convention")
        _number(self, "confidence", lambda v: 0.0 < v < 1.0, "a number in (0, 1)")
        _number(self, "threshold", lambda v: True, "a finite number")
        _number(self, "gain", lambda v: v >= 0.0, "a finite number >= 0")
        _number(self, "q_mp_limit", lambda v: 0.0 < v <= 1.0, "a number in (0, 1]")
        _number(self, "coverage_factor", lambda v: v > 0.0, "a finite number > 0")
        for name in ("subtract_gauge", "bayes"):
            if not isinstance(getattr(self, name), bool):
                _refuse(name, "true or false", getattr(self, name))
        for name, least in (("n_draws", 1), ("seed", 0), ("run_length", 2), ("trend_length", 3)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, Integral) or v < least:
                _refuse(name, f"an integer >= {least}", v)


def _refuse(name: str, expected: str, value) -> None:
    raise InputError(f"capability option {name!r}: expected {expected}, got {value!r}", value=value)


def _choice(opts, name: str, allowed: tuple, what: str) -> None:
    v = getattr(opts, name)
    if v not in allowed:
        raise InputError(
            f"capability option {name!r}: unknown {what} {v!r}; expected one of "
            f"{', '.join(map(repr, allowed))}",
            value=v,
        )


def _number(opts, name: str, ok, expected: str) -> None:
    v = getattr(opts, name)
    if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v) or not ok(v):
        _refuse(name, expected, v)
